"""Build an exported controller's folder with its Makefile, and fly the library through ``ctypes``.

:func:`build` runs ``make`` in a folder written by :func:`controllers.export.export_controller`.
:class:`NativeController` loads the built ``libwi_controller.so`` and is a policy like the
Python ones (Stable-Baselines3's ``predict``), so the same evaluation flies both; it does
per step what a flight computer does around ``wi_step``: it samples the reference over the
horizon, passes the episode's parameters (walls and heading read from the env at each
episode start) and keeps one ``wi_memory`` per vehicle. The solve, the warm start, the
hover fallback and the action mapping all happen in the C library.
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from controllers.export.c_code import EXPORT_FILE, default_parameters, parameter_vector
from controllers.mpc.policy import MPC
from controllers.mpc.step import StepOptions
from controllers.policy import ControllerPolicy
from wall_env.observation import OBSERVATION_FIELDS, OBSERVATION_SIZE

__all__ = ["build", "NativeController", "LIBRARY", "BENCH_PROGRAM", "STATUS_NAMES"]

LIBRARY = "libwi_controller.so"
BENCH_PROGRAM = "wi_bench"
STATUS_NAMES = {1: "non-finite observation", 2: "solver failure (non-finite cost at the initial guess)",
                3: "non-finite MPC solution"}
_TIME = OBSERVATION_FIELDS["time"].start
_DOUBLE_P = ctypes.POINTER(ctypes.c_double)


def build(folder: str | Path) -> Path:
    """Run ``make`` in an exported controller's ``folder`` (``$CC``/``$CFLAGS`` are honoured); return the
    path of the shared library. ``FileNotFoundError`` if the folder holds no export or ``make`` is missing,
    ``RuntimeError`` with the compiler's last lines if the build fails."""
    folder = Path(folder)
    if not (folder / EXPORT_FILE).is_file() or not (folder / "Makefile").is_file():
        raise FileNotFoundError(f"{folder} holds no exported controller ({EXPORT_FILE} and Makefile)")
    make = shutil.which("make")
    if make is None:
        raise FileNotFoundError("`make` is not installed; build with the one-line command in export.json instead")
    done = subprocess.run([make, "-C", str(folder)], capture_output=True, text=True)
    if done.returncode != 0:
        tail = " | ".join((done.stderr or done.stdout).strip().splitlines()[-3:])
        raise RuntimeError(f"make in {folder} failed: {tail}")
    return folder / LIBRARY


def _load_private_copy(path: Path) -> ctypes.CDLL:
    """Load a copy of the library under a fresh name: the dynamic loader hands out the library it already
    loaded for a path, so a folder exported and built again in the same process would otherwise run old code."""
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp, path.name)
        shutil.copyfile(path, copy)
        return ctypes.CDLL(str(copy))  # the loaded library outlives its file


class NativeController(ControllerPolicy):
    """An exported MPC or SC-MPC, built in ``folder``, flown through ``ctypes`` with SB3's ``predict``.

    ``policy``: the Python controller it was exported from (or one built the same way): it
    gives the reference sampler and, at each episode start, the parameters for that
    episode's walls and heading (:func:`controllers.export.c_code.parameter_vector`), as a
    flight computer would set them. Nothing of its solver runs. A library of other sizes
    than ``policy`` (another horizon, model structure or scene structure) raises
    ``ValueError``. Failures (status != 0) are counted in :attr:`failures` and
    :attr:`failure_log` with a ``RuntimeWarning``, as the Python controllers do; the
    command then is the library's hover fallback.

    :attr:`statuses` lists the status of every step of every vehicle.
    """

    def __init__(self, folder: str | Path, policy: MPC):
        if not isinstance(policy, MPC):
            raise ValueError(f"policy must be a controllers.MPC or SCMPC, got {type(policy).__name__}")
        super().__init__(policy.description)
        self.policy = policy
        self.name = f"{policy.name} (exported C)"
        path = Path(folder) / LIBRARY
        if not path.is_file():
            raise FileNotFoundError(f"{path} does not exist; build the folder first (controllers.export.build)")
        self.library = _load_private_copy(path)
        sizes = (ctypes.c_longlong * 8)()
        self.library.wi_sizes(sizes)
        parameters = default_parameters(policy)
        expected = [OBSERVATION_SIZE, 9 * (policy.problem.horizon + 1), policy.problem.global_size,
                    policy.attitude_problem.global_size, StepOptions.size, policy.problem.horizon,
                    8 * len(parameters)]
        if list(sizes)[:7] != expected:
            raise ValueError(f"{path} was built for another controller: sizes {list(sizes)[:7]}, {policy.name} "
                             f"needs {expected} (observation, samples, global, attitude global, options, horizon, "
                             "parameter bytes)")
        self._parameter_size = len(parameters)
        self._memory_doubles = (int(sizes[7]) + 7) // 8
        self._step = self.library.wi_step
        self._step.restype = ctypes.c_int
        self._step.argtypes = [_DOUBLE_P, _DOUBLE_P, _DOUBLE_P, ctypes.c_void_p, _DOUBLE_P, _DOUBLE_P]
        self.library.wi_memory_init.argtypes = [ctypes.c_void_p]
        self.library.wi_default_parameters.argtypes = [_DOUBLE_P]
        self._observation = np.zeros(OBSERVATION_SIZE)
        self._command_out = np.zeros(4)
        self._action_out = np.zeros(4)
        self._actions = np.zeros((0, 4))
        self.statuses: list[int] = []

    def default_parameters(self) -> np.ndarray:
        """The parameters compiled into the library (``wi_default_parameters``), as doubles."""
        out = np.zeros(self._parameter_size)
        self.library.wi_default_parameters(out.ctypes.data_as(_DOUBLE_P))
        return out

    def _new_memory(self, scene, reference) -> dict[str, Any]:
        memory = super()._new_memory(scene, reference)
        policy = self.policy
        memory["parameters"] = parameter_vector(policy, policy.problem.global_params(scene=scene),
                                                policy.attitude_problem.global_params(scene=scene),
                                                policy._options(reference.yaw))
        memory["native"] = (ctypes.c_double * self._memory_doubles)()  # one wi_memory per vehicle
        self.library.wi_memory_init(memory["native"])
        return memory

    def _commands(self, batch: np.ndarray) -> np.ndarray:
        samples = self.policy.horizon_reference.sampler([m["reference"] for m in self._memory], batch[:, _TIME])
        commands = np.empty((len(batch), 4))
        self._actions = np.empty((len(batch), 4))
        for i, memory in enumerate(self._memory):
            self._observation[:] = batch[i]
            row = np.ascontiguousarray(samples[i])
            status = self._step(self._observation.ctypes.data_as(_DOUBLE_P), row.ctypes.data_as(_DOUBLE_P),
                                memory["parameters"].ctypes.data_as(_DOUBLE_P), memory["native"],
                                self._command_out.ctypes.data_as(_DOUBLE_P), self._action_out.ctypes.data_as(_DOUBLE_P))
            self.statuses.append(int(status))
            if status:
                self.failures += 1
                reason = STATUS_NAMES.get(status, f"status {status}")
                self.failure_log.append(reason)
                warnings.warn(f"{self.name}: {reason}; commanding hover (failure {self.failures})", RuntimeWarning,
                              stacklevel=4)
            commands[i] = self._command_out
            self._actions[i] = self._action_out
        return commands

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """As :meth:`ControllerPolicy.predict`, with the normalised actions the library computed (float32)."""
        actions, state = super().predict(observation, state, episode_start, deterministic)
        native = self._actions.astype(np.float32)
        return (native[0] if actions.ndim == 1 else native), state
