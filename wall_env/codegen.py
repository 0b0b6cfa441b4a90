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

import copy
import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import threading
import warnings
from pathlib import Path

import casadi as ca
import numpy as np

__all__ = ["CompiledFunction", "BatchedFunction", "cache_dir", "NATIVE_FLAGS"]

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


def _compile(source: str, target: Path, flags: tuple[str, ...] = ("-O2",)) -> None:
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        raise RuntimeError("no C compiler found (set CC or install gcc)")
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        src = Path(tmp, "source.c")
        src.write_text(source)
        out = Path(tmp, target.name)
        cmd = [compiler, *flags, "-shared", "-fPIC", "-o", str(out), str(src), "-lm"]
        try:
            subprocess.run(cmd, check=True, capture_output=True)
        except subprocess.CalledProcessError:
            if "-march=native" not in flags:
                raise
            # a compiler that does not know the host: portable code is slower, not wrong
            cmd.remove("-march=native")
            subprocess.run(cmd, check=True, capture_output=True)
        os.replace(out, target)  # atomic: concurrent processes never load a half-written file


def _host_signature() -> str:
    """What code compiled with ``-march=native`` depends on: the processor's model and instruction sets."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        lines = []
    wanted = [line for line in lines if line.split(":")[0].strip() in ("model name", "flags", "Features", "CPU part")]
    return platform.machine() + "\n" + "\n".join(dict.fromkeys(wanted))


def _load(function: ca.Function, extra_source: str = "", flags: tuple[str, ...] = ("-O2",)) -> ctypes.CDLL | None:
    source = _generate_source(function) + extra_source
    hashed = source if flags == ("-O2",) else source + "\n/* flags: " + " ".join(flags) + " */"
    if "-march=native" in flags:  # the library only runs on processors like this one
        hashed += "\n/* host: " + _host_signature() + " */"
    key = hashlib.sha256(hashed.encode()).hexdigest()[:24]
    with _LOCK:
        if key in _LIBRARIES:
            return _LIBRARIES[key]
        target = cache_dir() / f"{function.name()}_{key}.so"
        library: ctypes.CDLL | None
        try:
            if not target.exists():
                _compile(source, target, flags)
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


def _check_dense(function: ca.Function) -> None:
    """Compiled calls pass flat buffers, so every input and output must be dense."""
    for i in range(function.n_in()):
        if not function.sparsity_in(i).is_dense():
            raise ValueError(f"input {function.name_in(i)!r} of {function.name()!r} must be dense")
    for i in range(function.n_out()):
        if not function.sparsity_out(i).is_dense():
            raise ValueError(f"output {function.name_out(i)!r} of {function.name()!r} must be dense")


class CompiledFunction:
    """A dense CasADi function evaluated as native code.

    Inputs are copied into preallocated buffers (matrices in CasADi's column-major
    order) and outputs are returned as fresh 1-D NumPy arrays of ``nnz`` entries.
    Each instance owns its buffers, so instances are not shared between threads,
    but many instances share one loaded library.
    """

    def __init__(self, function: ca.Function):
        _check_dense(function)
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


# A loop over the rows of batched inputs, appended to the generated source of a function
# ``NAME``: row k of input i starts at ``arg[i] + k * nnz_in(i)`` (the same for outputs), so
# NumPy arrays of shape (n, nnz) in C order are passed as they are. ``arg``/``res`` hold the
# function's own work arrays past its inputs/outputs, hence the copies of size sz_arg/sz_res.
_BATCH_LOOP = """
CASADI_SYMBOL_EXPORT int {name}_batch(casadi_int n, const casadi_real** arg, casadi_real** res,
                                      casadi_int* iw, casadi_real* w) {{
  static const casadi_int nnz_in[{n_in}] = {{{nnz_in}}};
  static const casadi_int nnz_out[{n_out}] = {{{nnz_out}}};
  const casadi_real* a[{sz_arg}];
  casadi_real* r[{sz_res}];
  casadi_int i, k;
  for (k = 0; k < n; ++k) {{
    for (i = 0; i < {sz_arg}; ++i) a[i] = 0;
    for (i = 0; i < {sz_res}; ++i) r[i] = 0;
    for (i = 0; i < {n_in}; ++i) a[i] = arg[i] + k * nnz_in[i];
    for (i = 0; i < {n_out}; ++i) r[i] = res[i] + k * nnz_out[i];
    if ({name}(a, r, iw, w, 0)) return (int)(k + 1);
  }}
  return 0;
}}
"""

# compiler flags of batched functions: -fno-math-errno lets sqrt compile to one instruction
# (the results are the same; only errno is no longer set)
_BATCH_FLAGS = ("-O3", "-fno-math-errno")
# flags for code that is as fast as the host allows (the controllers' solves): the host's
# instruction sets (FMA, AVX) change the last bits of results, and the cached library is
# keyed by the host's processor so that it never runs on another kind
NATIVE_FLAGS = _BATCH_FLAGS + ("-march=native",)


class BatchedFunction:
    """A dense CasADi function evaluated as native code on ``n`` rows of inputs in one call.

    The generated C code of ``function`` is compiled with a loop over the rows (see
    ``_BATCH_LOOP``), so one call evaluates the same code for every vehicle of a batch;
    ``n = 1`` is the single environment. Inputs and outputs are NumPy arrays of shape
    ``(n, nnz)`` (each row a matrix in CasADi's column-major order). ``flags``: compiler
    flags (default ``-O3 -fno-math-errno``; :data:`NATIVE_FLAGS` adds ``-march=native``).
    """

    def __init__(self, function: ca.Function, flags: tuple[str, ...] = _BATCH_FLAGS):
        _check_dense(function)
        self.function = function
        self.nnz_in = [function.nnz_in(i) for i in range(function.n_in())]
        self.nnz_out = [function.nnz_out(i) for i in range(function.n_out())]
        extra = _BATCH_LOOP.format(
            name=function.name(), n_in=function.n_in(), n_out=function.n_out(),
            nnz_in=", ".join(map(str, self.nnz_in)) or "0", nnz_out=", ".join(map(str, self.nnz_out)) or "0",
            sz_arg=max(function.sz_arg(), 1), sz_res=max(function.sz_res(), 1),
        )
        library = _load(function, extra, tuple(flags))
        self.native = library is not None
        self._iw = (ctypes.c_longlong * max(function.sz_iw(), 1))()
        self._w = (ctypes.c_double * max(function.sz_w(), 1))()
        if library is not None:
            self._entry = getattr(library, f"{function.name()}_batch")
            self._entry.restype = ctypes.c_int
            self._entry.argtypes = [ctypes.c_longlong] + [ctypes.c_void_p] * 4
        self._argv = (_DOUBLE_P * function.n_in())()
        self._resv = (_DOUBLE_P * function.n_out())()
        self._bound: tuple[int, list[np.ndarray], list[np.ndarray]] | None = None

    @property
    def name(self) -> str:
        return self.function.name()

    def clone(self) -> BatchedFunction:
        """Another evaluator of the same loaded library with its own work arrays and bindings, so
        that two threads can evaluate different rows at once (native calls release the GIL)."""
        other = copy.copy(self)
        other._iw = (ctypes.c_longlong * len(self._iw))()
        other._w = (ctypes.c_double * len(self._w))()
        other._argv = (_DOUBLE_P * self.function.n_in())()
        other._resv = (_DOUBLE_P * self.function.n_out())()
        other._bound = None
        return other

    def outputs(self, n: int) -> list[np.ndarray]:
        """Fresh output arrays for ``n`` rows."""
        return [np.zeros((n, k)) for k in self.nnz_out]

    def bind(self, inputs: list[np.ndarray], outputs: list[np.ndarray]) -> None:
        """Fix the arrays that :meth:`__call__` reads and writes: ``inputs[i]`` and ``outputs[j]``
        are C-contiguous float64 arrays of shape ``(n, nnz)``, changed in place between calls
        (binding once saves the pointer conversions, which cost more than a vehicle's step)."""
        n = outputs[0].shape[0]
        for kind, arrays, sizes in (("input", inputs, self.nnz_in), ("output", outputs, self.nnz_out)):
            if len(arrays) != len(sizes):
                raise ValueError(f"{self.name} has {len(sizes)} {kind}s, got {len(arrays)}")
            for i, (value, size) in enumerate(zip(arrays, sizes)):
                if value.dtype != np.float64 or not value.flags.c_contiguous or value.shape != (n, size):
                    raise ValueError(f"{kind} {i} of {self.name} must be C-contiguous float64 of shape "
                                     f"{(n, size)}, got {value.dtype} {value.shape}")
        self._bound = (n, list(inputs), list(outputs))
        for i, value in enumerate(inputs):
            self._argv[i] = value.ctypes.data_as(_DOUBLE_P)
        for j, value in enumerate(outputs):
            self._resv[j] = value.ctypes.data_as(_DOUBLE_P)

    def __call__(self) -> None:
        """Evaluate every row of the bound arrays, writing the bound outputs."""
        if self._bound is None:
            raise RuntimeError(f"bind the arrays of {self.name} before calling it")
        n, inputs, outputs = self._bound
        if self.native:
            failed = self._entry(n, self._argv, self._resv, self._iw, self._w)
            if failed:
                raise FloatingPointError(f"native evaluation of {self.name} failed for row {failed - 1}")
            return
        for k in range(n):
            result = self.function(*[value[k] for value in inputs])
            result = result if isinstance(result, (list, tuple)) else [result]
            for out, r in zip(outputs, result):
                out[k] = np.asarray(r, dtype=float).reshape(-1, order="F")
