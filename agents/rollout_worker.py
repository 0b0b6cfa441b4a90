"""PPO's rollouts in a second process, flown while the learner updates: each iteration costs the longer of the two.

A PPO iteration is a rollout (env steps and the policy acting on them, one core busy) followed by an
update (PyTorch), and in one process they take turns: on the 2-core machines the project is built for,
the sweep's iteration is a 44 ms rollout and a 28-36 ms update, one after the other. With a
:class:`RolloutWorker` the next rollout is flown in a worker process while the learner updates on the
previous one. The worker holds the training env (the same vector env and ``VecNormalize`` that
:func:`agents.envs.make_training_env` builds in the learner) and a copy of the learner
(:class:`~agents.lean_ppo.LeanPPO`, its own ``collect_rollouts``), so a rollout is collected exactly as
the learner collects one; only the weights it acts with differ.

**One update behind.** The rollout flown while the learner updates on rollout k acts with the policy
from before that update, so the update on it starts one update past the policy that acted. PPO's
ratio is taken against the log-probabilities the acting policy recorded (the rollout buffer's, as
always), so the clipping bounds each step from the acting policy; the advantages are the acting
critic's. The first rollout of a run is flown with the initial policy, as in one process. Stale
rollouts cost samples: on the sweep, 3M steps took 35 s instead of 56 s, but reaching the one-process
recipe's error took more steps than the time saved (``agents/configs/wall_sweep.yaml`` records the
runs), so training stays in one process unless ``rollout_worker`` is set.

**What the learner sees.** :meth:`LeanPPO.collect_rollouts <agents.lean_ppo.LeanPPO.collect_rollouts>`
hands the next rollout to the worker, then copies the finished one into its rollout buffer and replays
its steps to the callbacks (``num_timesteps``, ``infos`` and ``dones`` per step, so evaluations,
checkpoints, episode statistics and the progress bar work as before; an evaluation runs in the learner
while the worker flies). The worker owns the observation and return statistics; the learner's
``VecNormalize`` receives a copy with every rollout, so checkpoints and evaluations use them.

The worker runs one PyTorch thread and ignores Ctrl-C (the learner saves, then closes it).
"""

from __future__ import annotations

import multiprocessing as mp
import signal
import time
import traceback
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Rollout", "RolloutWorker", "WorkerError"]

# the rollout buffer's arrays that a finished rollout carries (advantages and returns: computed by the worker,
# with the acting critic's values)
BUFFER_ARRAYS = ("observations", "actions", "rewards", "returns", "episode_starts", "values", "log_probs", "advantages")


class WorkerError(RuntimeError):
    """The rollout worker failed; the message holds its traceback."""


@dataclass
class Rollout:
    """A finished rollout: the rollout buffer's arrays, each step's ``dones`` and non-empty ``infos`` (as
    ``{env index: info}``), the observation and return statistics after it, and where the worker's time went."""

    arrays: dict[str, np.ndarray]
    dones: np.ndarray  # (n_steps, n_envs)
    infos: list[dict[int, dict[str, Any]]]
    obs_rms: Any
    ret_rms: Any
    env_step_s: float  # inside the vector env's step
    fly_s: float  # the whole rollout

    def infos_of_step(self, t: int) -> list[dict[str, Any]]:
        """Step ``t``'s infos as the vector env returned them: one dict per env."""
        infos: list[dict[str, Any]] = [{} for _ in range(self.dones.shape[1])]
        for k, info in self.infos[t].items():
            infos[k] = info
        return infos


def _steps_recorder() -> Any:
    """A callback that keeps each step's ``dones`` and non-empty infos (built here: SB3 is imported lazily)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Recorder(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.dones: list[np.ndarray] = []
            self.infos: list[dict[int, dict[str, Any]]] = []

        def _on_step(self) -> bool:
            self.dones.append(np.array(self.locals["dones"], dtype=bool))
            self.infos.append({k: info for k, info in enumerate(self.locals["infos"]) if info})
            return True

    return Recorder()


def _serve(remote: Any, parent_remote: Any, config: dict[str, Any]) -> None:
    """The worker: build the training env and a learner on it, then fly a rollout per ``fly`` command."""
    parent_remote.close()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the learner's to handle: it saves, then closes us
    try:
        import torch

        torch.set_num_threads(1)
        from agents.envs import make_training_env
        from agents.learner import make_ppo

        env = make_training_env(config)
        model = make_ppo(config, env, None)  # seeded with the run's seed, as the learner is: the same first rollout
        model._setup_learn(int(config["timesteps"]), callback=None, reset_num_timesteps=True, progress_bar=False)
    except Exception:  # noqa: BLE001 - the learner raises it with this traceback
        remote.send(("error", traceback.format_exc()))
        remote.close()
        return
    remote.send(("ready", None))
    try:
        while True:
            command, data = remote.recv()
            if command == "close":
                break
            try:
                remote.send(("rollout", _fly(model, env, data)))
            except Exception:  # noqa: BLE001
                remote.send(("error", traceback.format_exc()))
    except (EOFError, BrokenPipeError, KeyboardInterrupt):
        pass
    finally:
        env.close()
        remote.close()


def _fly(model: Any, env: Any, data: dict[str, Any]) -> Rollout:
    import torch

    from agents.timing import step_seconds

    started = time.perf_counter()
    model.policy.load_state_dict({k: torch.as_tensor(v) for k, v in data["weights"].items()})
    if data.get("obs_rms") is not None:  # the learner's statistics (a resumed run's): ours from here on
        env.obs_rms, env.ret_rms = data["obs_rms"], data["ret_rms"]
    recorder = _steps_recorder()
    callback = model._init_callback(recorder)
    env_time = step_seconds(env)
    buffer = model.rollout_buffer
    if not model.collect_rollouts(env, callback, buffer, int(data["n_steps"])):  # pragma: no cover - never stops
        raise RuntimeError("the worker's rollout stopped early")
    arrays = {name: np.array(getattr(buffer, name)) for name in BUFFER_ARRAYS}
    return Rollout(arrays, np.stack(recorder.dones), recorder.infos, env.obs_rms, env.ret_rms,
                   env_step_s=step_seconds(env) - env_time, fly_s=time.perf_counter() - started)


class RolloutWorker:
    """A worker process that flies the training env's rollouts (module docstring).

    ``config``: the run's training configuration (the worker builds its env and learner from it, seeded alike).
    :meth:`fly` hands over the weights to act with and returns at once; :meth:`collect` waits for that
    rollout. ``start_method``: ``"forkserver"`` where available (no copy of the learner's threads), else ``"spawn"``.
    """

    def __init__(self, config: dict[str, Any], start_method: str | None = None):
        if start_method is None:
            start_method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
        ctx: Any = mp.get_context(start_method)
        self.remote, work_remote = ctx.Pipe()
        self.process = ctx.Process(target=_serve, args=(work_remote, self.remote, config), daemon=True)
        self.process.start()
        work_remote.close()
        self.n_steps = int(config["ppo"]["n_steps"])
        self._ready = False
        self.flying = False
        self.closed = False
        self.waited_s = 0.0  # the learner's time spent waiting for a rollout
        self.env_step_s = 0.0  # the worker's time inside the env's step
        self.fly_s = 0.0  # the worker's time flying rollouts

    def _receive(self) -> Any:
        try:
            kind, data = self.remote.recv()
        except (EOFError, ConnectionResetError, BrokenPipeError):
            raise WorkerError(f"the rollout worker (pid {self.process.pid}) died "
                              f"(exit code {self.process.exitcode})") from None
        if kind == "error":
            raise WorkerError(f"the rollout worker failed:\n{data}")
        return data

    def fly(self, policy: Any, obs_rms: Any = None, ret_rms: Any = None) -> None:
        """Start the next rollout, acting with ``policy``'s current weights (and, if given, these statistics)."""
        if self.closed:
            raise WorkerError("the rollout worker is closed")
        if self.flying:
            raise RuntimeError("a rollout is already flying: collect() it first")
        if not self._ready:  # the worker's first message: it built its env and learner, or why not
            self._receive()
            self._ready = True
        weights = {k: v.detach().cpu().numpy().copy() for k, v in policy.state_dict().items()}
        self.remote.send(("fly", {"weights": weights, "n_steps": self.n_steps, "obs_rms": obs_rms, "ret_rms": ret_rms}))
        self.flying = True

    def collect(self) -> Rollout:
        """Wait for the rollout that :meth:`fly` started."""
        if not self.flying:
            raise RuntimeError("no rollout is flying: fly() one first")
        started = time.perf_counter()
        rollout: Rollout = self._receive()
        self.flying = False
        self.waited_s += time.perf_counter() - started
        self.env_step_s += rollout.env_step_s
        self.fly_s += rollout.fly_s
        return rollout

    def close(self) -> None:
        """Stop the worker (a rollout still flying is dropped)."""
        if self.closed:
            return
        self.closed = True
        try:
            if self.flying and self.remote.poll(30.0):  # the worker sends its rollout before it reads again
                self.remote.recv()
            self.remote.send(("close", None))
        except (BrokenPipeError, EOFError, OSError):
            pass
        self.process.join(timeout=5)
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout=5)
        self.remote.close()

    def __enter__(self) -> RolloutWorker:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
