"""A subprocess vector env that runs several environments in each worker process.

Stable-Baselines3's ``SubprocVecEnv`` puts one environment in each process, so every
vector step costs one pipe round trip (and one pickled ``info`` dict) per environment.
The wall environments step in about 0.1 ms, so with one env per process the
inter-process traffic, not the physics, sets the speed, and on a 2-core machine more
processes than cores only add context switches.

:class:`MultiEnvSubprocVecEnv` splits ``n_envs`` environments over ``n_workers``
processes (``n_envs / n_workers`` per worker). A vector step sends each worker one
message with its slice of the actions and gets back one message with stacked
observations, rewards and done flags, so the round trips per step are ``n_workers``
however many environments there are. Workers keep only the ``info`` entries that
training needs (``info_keys``, plus Stable-Baselines3's ``episode``,
``terminal_observation`` and ``TimeLimit.truncated``), because pickling the wall env's
full info (true state, per-effect forces) costs more than the step itself.

Semantics follow Stable-Baselines3's ``VecEnv``: an environment that ends an episode is
reset at once, its last observation goes into ``info["terminal_observation"]`` and
``info["TimeLimit.truncated"]`` tells a time-limit end from a termination.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import traceback
from collections.abc import Callable, Sequence
from typing import Any

import cloudpickle
import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

__all__ = ["MultiEnvSubprocVecEnv", "split_evenly"]

# keys that Stable-Baselines3 itself reads from step infos
_SB3_INFO_KEYS = ("episode", "terminal_observation", "TimeLimit.truncated", "is_success")


def split_evenly(n_items: int, n_parts: int) -> list[range]:
    """``n_parts`` consecutive ranges covering ``range(n_items)``, sizes differing by at most one."""
    if n_parts < 1 or n_items < n_parts:
        raise ValueError(f"need 1 <= n_parts <= n_items, got n_items={n_items}, n_parts={n_parts}")
    base, extra = divmod(n_items, n_parts)
    ranges, start = [], 0
    for k in range(n_parts):
        size = base + (1 if k < extra else 0)
        ranges.append(range(start, start + size))
        start += size
    return ranges


class _WorkerFailure:
    """Sent instead of a result when a worker's environment raised; carries the traceback."""

    def __init__(self, text: str):
        self.text = text


def _receive_all(remotes) -> list[Any]:
    """One message from each remote (all of them, so the pipes stay in step), raising a
    worker's failure as ``RuntimeError`` with its traceback."""
    messages = [remote.recv() for remote in remotes]
    for message in messages:
        if isinstance(message, _WorkerFailure):
            raise RuntimeError(f"an environment in a worker process failed:\n{message.text}")
    return messages


def _keep(info: dict[str, Any], keys: tuple[str, ...]) -> dict[str, Any]:
    return {k: info[k] for k in keys if k in info}


def _worker(remote, parent_remote, pickled_fns: bytes, info_keys: tuple[str, ...]) -> None:
    """Worker loop: build this worker's environments, then answer commands until ``close``."""
    parent_remote.close()
    # Ctrl-C reaches the whole process group; the parent decides what happens (save, then close us)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # the wall env is NumPy only; keep BLAS/OpenMP from spawning threads that fight for 2 cores
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover - torch is a dependency, but the worker does not need it
        pass
    keys = tuple(dict.fromkeys(_SB3_INFO_KEYS + info_keys))
    envs: list[gym.Env] = []
    try:
        envs = [fn() for fn in cloudpickle.loads(pickled_fns)]
    except Exception:  # noqa: BLE001 - report it to the parent instead of the spaces
        remote.send(_WorkerFailure(traceback.format_exc()))
        remote.close()
        return
    remote.send((envs[0].observation_space, envs[0].action_space, envs[0].render_mode))
    try:
        while True:
            command, data = remote.recv()
            try:
                _answer(remote, envs, keys, command, data)
            except StopIteration:
                break
            except Exception:  # noqa: BLE001 - the parent raises it with this traceback
                remote.send(_WorkerFailure(traceback.format_exc()))
    except (KeyboardInterrupt, EOFError, BrokenPipeError):
        pass
    finally:
        for env in envs:
            env.close()
        remote.close()


def _answer(remote, envs: list[gym.Env], keys: tuple[str, ...], command: str, data: Any) -> None:
    """Carry out one command from the parent and send the result (``StopIteration`` on close)."""
    if command == "step":
        n = len(envs)
        obs_list, rewards, dones = [], np.empty(n, dtype=np.float32), np.empty(n, dtype=bool)
        infos, reset_infos = [], []
        for k, (env, action) in enumerate(zip(envs, data)):
            obs, reward, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            info = _keep(info, keys)
            info["TimeLimit.truncated"] = bool(truncated and not terminated)
            reset_info: dict[str, Any] = {}
            if done:
                info["terminal_observation"] = obs
                obs, reset_info = env.reset()
                reset_info = _keep(reset_info, keys)
            obs_list.append(obs)
            rewards[k] = reward
            dones[k] = done
            infos.append(info)
            reset_infos.append(reset_info)
        remote.send((np.stack(obs_list), rewards, dones, infos, reset_infos))
    elif command == "reset":
        out = []
        for env, (seed, options) in zip(envs, data):
            obs, info = env.reset(seed=seed, **({"options": options} if options else {}))
            out.append((obs, _keep(info, keys)))
        remote.send((np.stack([o for o, _ in out]), [i for _, i in out]))
    elif command == "get_attr":
        index, name = data
        remote.send(envs[index].get_wrapper_attr(name))
    elif command == "set_attr":
        index, name, value = data
        remote.send(envs[index].set_wrapper_attr(name, value))
    elif command == "env_method":
        index, name, args, kwargs = data
        remote.send(envs[index].get_wrapper_attr(name)(*args, **kwargs))
    elif command == "is_wrapped":
        index, wrapper_class = data
        from stable_baselines3.common.env_util import is_wrapped

        remote.send(is_wrapped(envs[index], wrapper_class))
    elif command == "render":
        remote.send([env.render() for env in envs])
    elif command == "close":
        raise StopIteration
    else:
        raise NotImplementedError(f"unknown command {command!r}")


class MultiEnvSubprocVecEnv(VecEnv):
    """``len(env_fns)`` environments in ``n_workers`` processes; see the module docstring.

    Parameters
    ----------
    env_fns: functions that each build one environment (called inside the workers, so
        they must be picklable with cloudpickle).
    n_workers: processes; default ``min(len(env_fns), os.cpu_count())``.
    start_method: multiprocessing start method; default ``"forkserver"`` where available
        (safe after PyTorch has started threads), else ``"spawn"``.
    info_keys: further ``info`` entries to send back from the workers.
    """

    def __init__(
        self,
        env_fns: Sequence[Callable[[], gym.Env]],
        n_workers: int | None = None,
        start_method: str | None = None,
        info_keys: Sequence[str] = (),
    ):
        n_envs = len(env_fns)
        if n_envs < 1:
            raise ValueError("need at least one environment function")
        n_workers = min(n_envs, os.cpu_count() or 1) if n_workers is None else int(n_workers)
        self._slices = split_evenly(n_envs, n_workers)
        if start_method is None:
            start_method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
        ctx: Any = mp.get_context(start_method)
        self.remotes, self.processes = [], []
        self.waiting = False
        self.closed = False
        for part in self._slices:
            remote, work_remote = ctx.Pipe()
            payload = cloudpickle.dumps([env_fns[i] for i in part])
            process = ctx.Process(target=_worker, args=(work_remote, remote, payload, tuple(info_keys)), daemon=True)
            process.start()
            work_remote.close()
            self.remotes.append(remote)
            self.processes.append(process)
        try:  # each worker first reports its spaces, or why it could not build its environments
            observation_space, action_space, render_mode = _receive_all(self.remotes)[0]
        except (RuntimeError, EOFError, BrokenPipeError):
            self.closed = True
            for process in self.processes:
                process.join(timeout=5)
                if process.is_alive():
                    process.terminate()
            raise
        super().__init__(n_envs, observation_space, action_space)
        self.render_mode = render_mode
        self.n_workers = n_workers
        self._actions: np.ndarray | None = None

    # ------------------------------------------------------------------ stepping
    def step_async(self, actions: np.ndarray) -> None:
        actions = np.asarray(actions)
        for remote, part in zip(self.remotes, self._slices):
            remote.send(("step", actions[part.start : part.stop]))
        self.waiting = True

    def step_wait(self) -> VecEnvStepReturn:
        self.waiting = False
        results = _receive_all(self.remotes)
        obs = np.concatenate([r[0] for r in results])
        rewards = np.concatenate([r[1] for r in results])
        dones = np.concatenate([r[2] for r in results])
        infos = [info for r in results for info in r[3]]
        self.reset_infos = [info for r in results for info in r[4]]
        return obs, rewards, dones, infos

    def reset(self):
        for remote, part in zip(self.remotes, self._slices):
            remote.send(("reset", [(self._seeds[i], self._options[i]) for i in part]))
        results = _receive_all(self.remotes)
        self.reset_infos = [info for r in results for info in r[1]]
        self._reset_seeds()
        self._reset_options()
        return np.concatenate([r[0] for r in results])

    def close(self) -> None:
        if self.closed:
            return
        for remote in self.remotes:
            try:
                if self.waiting:
                    remote.recv()
                remote.send(("close", None))
            except (EOFError, OSError):  # the worker is gone already
                pass
        for process in self.processes:
            process.join(timeout=10)
            if process.is_alive():
                process.terminate()
        self.closed = True

    # ------------------------------------------------------------------ per-environment access
    def _locate(self, index: int) -> tuple[Any, int]:
        for remote, part in zip(self.remotes, self._slices):
            if index in part:
                return remote, index - part.start
        raise IndexError(f"environment index {index} out of range 0..{self.num_envs - 1}")

    def _ask(self, indices: VecEnvIndices, make_message: Callable[[int], tuple[str, Any]]) -> list[Any]:
        out = []
        for i in self._get_indices(indices):
            remote, local = self._locate(i)
            remote.send(make_message(local))
            out.append(_receive_all([remote])[0])
        return out

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return self._ask(indices, lambda k: ("get_attr", (k, attr_name)))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        self._ask(indices, lambda k: ("set_attr", (k, attr_name, value)))

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        return self._ask(indices, lambda k: ("env_method", (k, method_name, method_args, method_kwargs)))

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return self._ask(indices, lambda k: ("is_wrapped", (k, wrapper_class)))

    def get_images(self) -> Sequence[np.ndarray | None]:
        images = []
        for remote in self.remotes:
            remote.send(("render", None))
        for result in _receive_all(self.remotes):
            images.extend(result)
        return images
