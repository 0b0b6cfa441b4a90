"""Native code for CasADi functions: generate C with CasADi, compile once, call through ctypes.

Calling a :class:`casadi.Function` from Python costs about 50 microseconds, which
would cap the simulator far below its speed target. The same function, written out
by CasADi's code generator, compiled with the system C compiler and called through
``ctypes`` into preallocated buffers, costs about 2 microseconds. The symbolic
definition stays the single source of truth: the compiled code is generated from it.

Compiled libraries are cached on disk under ``$WALL_INSPECTOR_CACHE`` (default
``~/.cache/wall_inspector``), keyed by a hash of the generated source, and loaded
libraries are shared inside a process. If no C compiler is available, calls fall
back to CasADi's own evaluator (slower, same numbers) with a warning.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
import warnings
from pathlib import Path

import casadi as ca
import numpy as np

__all__ = ["CompiledFunction", "cache_dir"]

_LIBRARIES: dict[str, ctypes.CDLL | None] = {}
_LOCK = threading.Lock()
_DOUBLE_P = ctypes.POINTER(ctypes.c_double)


def cache_dir() -> Path:
    """Folder that holds compiled libraries (created on demand)."""
    root = os.environ.get("WALL_INSPECTOR_CACHE") or os.path.join(
        os.path.expanduser("~"), ".cache", "wall_inspector"
    )
    path = Path(root)
    path.mkdir(parents=True, exist_ok=True)
    return path


def _generate_source(function: ca.Function) -> str:
    with tempfile.TemporaryDirectory() as tmp:
        generator = ca.CodeGenerator(f"{function.name()}.c", {"with_header": False})
        generator.add(function)
        generator.generate(tmp + os.sep)
        return Path(tmp, f"{function.name()}.c").read_text()


def _compile(source: str, target: Path) -> None:
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        raise RuntimeError("no C compiler found (set CC or install gcc)")
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        src = Path(tmp, "source.c")
        src.write_text(source)
        out = Path(tmp, target.name)
        cmd = [compiler, "-O2", "-shared", "-fPIC", "-o", str(out), str(src), "-lm"]
        subprocess.run(cmd, check=True, capture_output=True)
        os.replace(out, target)  # atomic: concurrent processes never load a half-written file


def _load(function: ca.Function) -> ctypes.CDLL | None:
    source = _generate_source(function)
    key = hashlib.sha256(source.encode()).hexdigest()[:24]
    with _LOCK:
        if key in _LIBRARIES:
            return _LIBRARIES[key]
        target = cache_dir() / f"{function.name()}_{key}.so"
        library: ctypes.CDLL | None
        try:
            if not target.exists():
                _compile(source, target)
            library = ctypes.CDLL(str(target))
        except (OSError, RuntimeError, subprocess.CalledProcessError) as exc:
            warnings.warn(
                f"could not compile CasADi function {function.name()!r} ({exc}); "
                "falling back to CasADi's evaluator, which is about 20x slower",
                RuntimeWarning,
                stacklevel=3,
            )
            library = None
        _LIBRARIES[key] = library
        return library


class CompiledFunction:
    """A dense CasADi function evaluated as native code.

    Inputs are copied into preallocated buffers (matrices in CasADi's column-major
    order) and outputs are returned as fresh 1-D NumPy arrays of ``nnz`` entries.
    Each instance owns its buffers, so instances are not shared between threads,
    but many instances share one loaded library.
    """

    def __init__(self, function: ca.Function):
        for i in range(function.n_in()):
            if not function.sparsity_in(i).is_dense():
                raise ValueError(f"input {function.name_in(i)!r} of {function.name()!r} must be dense")
        for i in range(function.n_out()):
            if not function.sparsity_out(i).is_dense():
                raise ValueError(f"output {function.name_out(i)!r} of {function.name()!r} must be dense")
        self.function = function
        self._inputs = [np.zeros(function.nnz_in(i)) for i in range(function.n_in())]
        self._outputs = [np.zeros(function.nnz_out(i)) for i in range(function.n_out())]
        library = _load(function)
        self.native = library is not None
        if library is None:
            return
        self._entry = getattr(library, function.name())
        self._entry.restype = ctypes.c_int
        self._entry.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_int]
        n_arg, n_res = function.sz_arg(), function.sz_res()
        self._argv = (_DOUBLE_P * n_arg)(
            *[b.ctypes.data_as(_DOUBLE_P) for b in self._inputs], *([None] * (n_arg - len(self._inputs)))
        )
        self._resv = (_DOUBLE_P * n_res)(
            *[b.ctypes.data_as(_DOUBLE_P) for b in self._outputs], *([None] * (n_res - len(self._outputs)))
        )
        self._iw = (ctypes.c_longlong * max(function.sz_iw(), 1))()
        self._w = (ctypes.c_double * max(function.sz_w(), 1))()

    @property
    def name(self) -> str:
        return self.function.name()

    def __call__(self, *args) -> tuple[np.ndarray, ...]:
        if len(args) != len(self._inputs):
            raise TypeError(f"{self.name} takes {len(self._inputs)} inputs, got {len(args)}")
        if not self.native:
            result = self.function(*[np.asarray(a, dtype=float).reshape(-1, order="F") for a in args])
            result = result if isinstance(result, (list, tuple)) else [result]
            return tuple(np.asarray(r, dtype=float).reshape(-1, order="F") for r in result)
        for buffer, value in zip(self._inputs, args):
            buffer[:] = np.ravel(value, order="F")
        if self._entry(self._argv, self._resv, self._iw, self._w, 0) != 0:
            raise FloatingPointError(f"native evaluation of {self.name} failed")
        return tuple(out.copy() for out in self._outputs)
