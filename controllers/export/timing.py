"""Time an exported controller's ``wi_step`` with a C timing loop, beside the Python ``predict``, on one flight.

:func:`record_flight` flies a Python MPC or SC-MPC for one episode and keeps, per control
step, everything its compiled step was given (episode start, observation, reference
samples, parameters) and how long each ``predict`` took. :func:`time_native_steps`
hands those steps to the exported folder's ``wi_bench`` (a C program, ``c_sources/wi_bench.c``),
which runs them in order, once to warm the caches and then ``passes`` times, timing
each ``wi_step`` call alone with the monotonic clock, and returns the times with the
commands of the last pass (so the figures come with a check that the C code computed the
Python controller's actions on every step). :func:`measure_exported_controller` does
both on the paper's Table II flight (:data:`controllers.paper_tables.TABLE_II`:
``WallSweep-v0``, k_s = 4.1 N/m, d_thr = 0.132 m, command noise on, contacts do not end it).
"""

from __future__ import annotations

import os
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import wall_env  # noqa: F401  (registers the environments)
from controllers.evaluation import solve_time_stats
from controllers.export.c_code import export_controller, parameter_vector
from controllers.export.native import BENCH_PROGRAM, build
from controllers.mpc.policy import MPC, SCMPC
from controllers.mpc.step import StepInput
from controllers.paper_tables import TABLE_II

__all__ = ["RecordedFlight", "NativeTiming", "record_flight", "time_native_steps", "measure_exported_controller",
           "realtime_permitted", "TARGETS"]

TARGETS = {"median_ms": 0.1, "p99_8_ms": 0.3}  # of the exported step in the C timing loop


@dataclass
class RecordedFlight:
    """Per control step of one flight: what the compiled step was given and what the Python controller did."""

    starts: np.ndarray  # (n,) 1.0 at the episode start
    observations: np.ndarray  # (n, 48)
    samples: np.ndarray  # (n, 9 (N + 1))
    parameters: np.ndarray  # (n, P): wi_parameters
    actions: np.ndarray  # (n, 4) float32, the Python controller's
    predict_seconds: np.ndarray  # (n,) wall clock of each predict call
    predict_cpu_seconds: np.ndarray  # (n,) CPU time of the calling thread

    def write(self, path: str | Path) -> None:
        """The ``PROBLEMS`` file of ``wi_bench``: a header, then one record of doubles per step."""
        records = np.hstack([self.starts[:, None], self.observations, self.samples, self.parameters])
        header = np.array([len(records), self.observations.shape[1], self.samples.shape[1], self.parameters.shape[1]])
        Path(path).write_bytes(np.concatenate([header, records.ravel()]).astype("<f8").tobytes())


@dataclass
class NativeTiming:
    seconds: np.ndarray  # (passes * n,) each timed wi_step call, wall clock
    cpu_seconds: np.ndarray  # (passes * n,) the same in CPU time of the thread
    passes: int
    statuses: np.ndarray  # (n,) of the last pass
    commands: np.ndarray  # (n, 4)
    actions: np.ndarray  # (n, 4)
    iterations: np.ndarray  # (n,) LM iterations
    cold: np.ndarray  # (n,) bool: the step started cold (episode start, time gone back, after a failure)


def record_flight(policy: MPC, env: Any, seed: int) -> RecordedFlight:
    """Fly ``policy`` (built for ``env``) for one episode from ``env.reset(seed=seed)``; see the module docstring."""
    if not isinstance(policy, MPC):
        raise ValueError(f"policy must be a controllers.MPC or SCMPC, got {type(policy).__name__}")
    rows: dict[str, list] = {k: [] for k in ("starts", "observations", "samples", "parameters", "actions",
                                             "predict_seconds", "predict_cpu_seconds")}
    observation, _ = env.reset(seed=seed)
    start, done = True, False
    while not done:
        wall, cpu = time.perf_counter(), time.thread_time()
        action, _ = policy.predict(observation, episode_start=np.array([start]))
        rows["predict_cpu_seconds"].append(time.thread_time() - cpu)
        rows["predict_seconds"].append(time.perf_counter() - wall)
        inputs = policy.step.inputs  # (bound again when the batch size changes)
        rows["starts"].append(float(start))
        rows["observations"].append(np.asarray(observation, dtype=float))
        rows["samples"].append(inputs[StepInput.samples][0].copy())
        rows["parameters"].append(parameter_vector(policy, inputs[StepInput.global_params][0],
                                                   inputs[StepInput.attitude_global][0], inputs[StepInput.options][0]))
        rows["actions"].append(np.asarray(action))
        start = False
        observation, _, terminated, truncated, _ = env.step(action)
        done = terminated or truncated
    return RecordedFlight(**{k: np.asarray(v) for k, v in rows.items()})


def realtime_permitted() -> bool:
    """Whether this process may give a child real-time FIFO scheduling (tried on itself, then undone)."""
    if not hasattr(os, "sched_setscheduler"):
        return False
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except OSError:
        return False
    return True


def _realtime() -> None:  # runs in the timing loop's process before it starts
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))


def time_native_steps(folder: str | Path, flight: RecordedFlight, passes: int = 5,
                      realtime: bool = False) -> NativeTiming:
    """Run ``flight``'s steps through the built ``wi_bench`` of ``folder`` (see the module docstring).

    ``realtime``: run the timing loop with real-time FIFO scheduling, as a flight computer runs its
    control thread, so that other processes on a shared machine do not preempt it (check
    :func:`realtime_permitted` first). The loop runs in the CPUs this process may use (pin it to
    one core first for steady figures)."""
    if isinstance(passes, bool) or not isinstance(passes, int) or passes < 1:
        raise ValueError(f"passes must be a positive integer, got {passes!r}")
    program = Path(folder) / BENCH_PROGRAM
    if not program.is_file():
        raise FileNotFoundError(f"{program} does not exist; build the folder first (controllers.export.build)")
    with tempfile.TemporaryDirectory() as tmp:
        problems, results = Path(tmp, "problems.bin"), Path(tmp, "results.bin")
        flight.write(problems)
        done = subprocess.run([str(program.resolve()), str(problems), str(results), str(passes)],
                              capture_output=True, text=True, preexec_fn=_realtime if realtime else None)
        if done.returncode != 0:
            raise RuntimeError(f"{program} failed: {done.stderr.strip()}")
        data = np.frombuffer(results.read_bytes(), dtype="<f8")
    n, passes_run = int(data[0]), int(data[1])
    outputs = data[2:2 + 11 * n].reshape(n, 11)
    times = data[2 + 11 * n:].reshape(2, passes_run * n)
    return NativeTiming(times[0].copy(), times[1].copy(), passes_run, outputs[:, 0].astype(int),
                        outputs[:, 1:5].copy(), outputs[:, 5:9].copy(), outputs[:, 9].astype(int), outputs[:, 10] != 0)


def measure_exported_controller(folder: str | Path, method: str = "scmpc", seed: int = 0, passes: int = 5,
                                preset: str | Path | None = "tuned", realtime: bool = False) -> dict[str, Any]:
    """Export ``method`` (``"scmpc"`` or ``"mpc"``) for the Table II flight into ``folder``, build it, fly the
    Python controller once (seed ``seed``) and time the C step on that flight's steps (``realtime`` as
    :func:`time_native_steps`); returns the figures (milliseconds,
    :func:`controllers.evaluation.solve_time_stats`) and the largest difference between the C and the Python
    actions."""
    if method not in ("scmpc", "mpc"):
        raise ValueError(f"method must be 'scmpc' or 'mpc', got {method!r}")
    scenario = TABLE_II[0]
    env = gym.make(scenario.env_id, **scenario.make_kwargs())
    try:
        policy: MPC = (SCMPC.from_env(env, k_s=scenario.k_s, d_thr=scenario.d_thr, preset=preset) if method == "scmpc"
                       else MPC.from_env(env, preset=preset))
        export_controller(policy, folder)
        build(folder)
        flight = record_flight(policy, env, seed)
    finally:
        env.close()
    native = time_native_steps(folder, flight, passes, realtime)
    return {
        "controller": policy.name,
        "env": scenario.env_id,
        "env_kwargs": scenario.make_kwargs(),
        "seed": seed,
        "steps": len(flight.starts),
        "passes": native.passes,
        "priority": "real-time FIFO" if realtime else "normal",
        "c_step_ms": solve_time_stats(native.seconds.tolist()),
        "c_step_cpu_ms": solve_time_stats(native.cpu_seconds.tolist()),
        "lm_iterations_mean": float(np.mean(native.iterations)),
        "python_predict_ms": solve_time_stats(flight.predict_seconds.tolist()),
        "python_predict_cpu_ms": solve_time_stats(flight.predict_cpu_seconds.tolist()),
        "max_action_difference": float(np.max(np.abs(native.actions.astype(np.float32) - flight.actions))),
        "c_failures": int(np.count_nonzero(native.statuses)),
        "python_failures": policy.failures,
        "targets": TARGETS,
    }
