"""A trained PPO agent as one ONNX file: the observation in, the action out, for onnxruntime on a flight computer.

:func:`export_onnx` writes what :class:`~agents.policy.TrainedPolicy` computes for a
deterministic action into one ONNX graph (PyTorch's exporter, ``torch.onnx.export`` with
``dynamo=True``):

1. the observation normalisation of the agent's ``VecNormalize`` statistics
   ``clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs)``, in float64 as
   Stable-Baselines3 computes it, then float32;
2. the policy network's mean action (the deterministic action of the Gaussian policy);
3. the clip to the action space, as Stable-Baselines3's ``predict`` does;
4. the all-zero hover action for an observation with a NaN or infinity, as
   :class:`~agents.policy.TrainedPolicy` gives.

Input ``observation``: float32 ``(n, obs_size)``; output ``action``: float32 ``(n, 4)``
(normalised, see :mod:`wall_env.actions`); ``n`` is free. The file's metadata holds the
env id, the source folder and the observation size. Before the file is put in place, the
agent's recorded check observations (``policy.json``) and random observations are run
through onnxruntime and the Python policy, and the export fails if any action differs by
more than :data:`TOLERANCE`. :class:`OnnxPolicy` runs the file with onnxruntime behind
Stable-Baselines3's ``predict``; :func:`time_onnx_steps` times it one observation per call.

Residual agents are not exported: their action needs the base controller's (MPC or
PID) action as an input, which an ONNX file does not hold. An agent with an observation
history (:mod:`agents.history`) is exported from its network's input, the history features
(the last observations and the position-error integral): the vehicle keeps that history
itself, as :class:`agents.history.ObservationHistory` does; the file's metadata ``history``
gives its settings.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import logging
import os
import tempfile
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from agents.checkpoints import POLICY_FILE, read_json
from agents.policy import TrainedPolicy, _resolve, load_policy

__all__ = ["export_onnx", "OnnxPolicy", "time_onnx_steps", "measure_onnx_policy", "ONNX_FILE", "TOLERANCE", "TARGETS"]

ONNX_FILE = "policy.onnx"
TOLERANCE = 1e-5  # largest difference from the Python agent's action the export accepts
TARGETS = {"median_ms": 0.05}  # of one onnxruntime call on one observation
_RANDOM_CHECKS = 256


def _require(module: str) -> Any:
    """Import ``module`` of the ``export`` extra, or say how to install it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise ImportError(f"exporting to ONNX needs {module}: pip install 'wall-inspector[export]'") from None


def _load(source: str | Path | TrainedPolicy) -> TrainedPolicy:
    if isinstance(source, TrainedPolicy):
        return source
    folder = _resolve(source)
    info_path = folder / POLICY_FILE
    if info_path.is_file():
        residual = (read_json(info_path) or {}).get("residual")
        if residual:
            raise ValueError(f"{folder} holds a residual agent on top of {residual.get('base')!r}: its action needs the "
                             "base controller's action, which an ONNX file does not hold; export a plain PPO agent")
    policy = load_policy(source)
    if not isinstance(policy, TrainedPolicy):
        raise ValueError(f"{source} is not a plain PPO agent ({type(policy).__name__})")
    return policy


def _actor(policy: TrainedPolicy) -> Any:
    """The ``torch.nn.Module`` of steps 1-4 of the module docstring."""
    import torch
    from gymnasium import spaces
    from stable_baselines3.common.distributions import DiagGaussianDistribution, StateDependentNoiseDistribution
    from stable_baselines3.common.policies import ActorCriticPolicy, BaseModel

    network = policy.model.policy
    if not isinstance(network, ActorCriticPolicy):
        raise ValueError(f"only actor-critic (PPO) policies are exported, got {type(network).__name__}")
    if not isinstance(policy.action_space, spaces.Box) or not isinstance(policy.observation_space, spaces.Box):
        raise ValueError("only Box observation and action spaces are exported")
    if not isinstance(network.action_dist, (DiagGaussianDistribution, StateDependentNoiseDistribution)) \
            or network.squash_output:
        raise ValueError(f"only Gaussian policies without squashing are exported, got {type(network.action_dist).__name__}")
    size = int(np.prod(policy.observation_space.shape))
    statistics = policy.vec_normalize
    if statistics is not None and statistics.norm_obs:
        mean = np.asarray(statistics.obs_rms.mean, dtype=np.float64)
        scale = np.sqrt(np.asarray(statistics.obs_rms.var, dtype=np.float64) + statistics.epsilon)
        clip = float(statistics.clip_obs)
    else:  # trained without observation normalisation
        mean, scale, clip = np.zeros(size), np.ones(size), float("inf")

    class DeterministicActor(torch.nn.Module):
        mean: torch.Tensor
        scale: torch.Tensor
        low: torch.Tensor
        high: torch.Tensor

        def __init__(self) -> None:
            super().__init__()
            self.network = network
            self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float64))
            self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float64))
            self.register_buffer("low", torch.as_tensor(policy.action_space.low, dtype=torch.float32))
            self.register_buffer("high", torch.as_tensor(policy.action_space.high, dtype=torch.float32))
            self.clip = clip

        def forward(self, observation: torch.Tensor) -> torch.Tensor:
            x = (observation.to(torch.float64) - self.mean) / self.scale
            x = torch.clamp(x, -self.clip, self.clip).to(torch.float32)
            features = BaseModel.extract_features(self.network, x, self.network.pi_features_extractor)
            action = self.network.action_net(self.network.mlp_extractor.forward_actor(features))
            action = torch.minimum(torch.maximum(action, self.low), self.high)
            finite = torch.isfinite(observation).all(dim=-1, keepdim=True)
            return torch.where(finite, action, torch.zeros_like(action))

    return DeterministicActor().eval()


@contextlib.contextmanager
def _quiet_exporter() -> Iterator[None]:
    """PyTorch's exporter logs progress and missing optional packages (torchvision); none of it is for the user."""
    loggers = [logging.getLogger(name) for name in ("torch.onnx", "torch.export", "torch._dynamo", "onnxscript")]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.ERROR)
    try:
        with open(os.devnull, "w") as sink, contextlib.redirect_stdout(sink), warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)  # PyTorch's own deprecations inside its exporter
            warnings.simplefilter("ignore", DeprecationWarning)
            yield
    finally:
        for logger, level in zip(loggers, levels):
            logger.setLevel(level)


def _check_observations(policy: TrainedPolicy) -> np.ndarray:
    """The agent's recorded check observations and random ones around them (a fixed seed)."""
    recorded = np.asarray(policy.info.get("check", {}).get("observations", []), dtype=np.float32)
    size = int(np.prod(policy.observation_space.shape))
    rng = np.random.default_rng(0)
    centre = recorded.mean(axis=0) if len(recorded) else np.zeros(size)
    random = (centre + rng.normal(0.0, 0.5, (_RANDOM_CHECKS, size))).astype(np.float32)
    return np.vstack([recorded.reshape(-1, size), random]) if len(recorded) else random


def export_onnx(source: str | Path | TrainedPolicy, path: str | Path) -> Path:
    """Write the agent ``source`` (anything :func:`agents.load_policy` accepts without an env, or a loaded
    :class:`~agents.policy.TrainedPolicy`) to the ONNX file ``path`` (see the module docstring); return ``path``.

    ``ValueError`` for an agent that cannot be exported (residual, not a Gaussian actor-critic policy);
    ``RuntimeError`` if the ONNX graph does not reproduce the Python agent's actions within :data:`TOLERANCE`
    (``path`` is then not written).
    """
    import torch

    onnx = _require("onnx")
    _require("onnxscript")  # PyTorch's exporter imports it
    policy = _load(source)
    path = Path(path)
    if path.exists() and not path.is_file():
        raise ValueError(f"{path} exists and is not a file")
    actor = _actor(policy)
    size = int(np.prod(policy.observation_space.shape))
    example = torch.zeros((2, size), dtype=torch.float32)
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
        draft = Path(tmp, ONNX_FILE)
        with _quiet_exporter(), torch.no_grad():
            torch.onnx.export(actor, (example,), str(draft), dynamo=True, input_names=["observation"],
                              output_names=["action"], dynamic_shapes={"observation": {0: torch.export.Dim("batch")}},
                              external_data=False, verbose=False)
        model = onnx.load(str(draft))
        metadata = {"producer": "wall-inspector export", "env_id": str(policy.env_id),
                    "source": str(policy.path) if policy.path else "", "observation_size": str(size),
                    "action": "normalised [T, wx, wy, wz] in [-1, 1] (wall_env.actions)",
                    "history": json.dumps(policy.info.get("history"))}
        onnx.helper.set_model_props(model, metadata)
        onnx.save(model, str(draft))
        observations = _check_observations(policy)  # the network's inputs (history features, if it has one)
        expected, _ = policy.model.predict(policy.normalize(observations), deterministic=True)
        actions = OnnxPolicy(draft).run_network(observations)
        worst = float(np.max(np.abs(actions - expected)))
        if not worst <= TOLERANCE:
            raise RuntimeError(f"the ONNX graph of {source} differs from the Python agent by {worst:.3g} "
                               f"(tolerance {TOLERANCE:g}); nothing was written")
        os.replace(draft, path)
    return path


class OnnxPolicy:
    """An exported agent run by onnxruntime, with Stable-Baselines3's ``predict``.

    ``threads``: onnxruntime's intra-op threads (default 1, as a flight computer's control
    thread runs it). :attr:`metadata` holds the file's metadata (env id, source, sizes).
    """

    def __init__(self, path: str | Path, threads: int = 1):
        onnxruntime = _require("onnxruntime")
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path} does not exist")
        if isinstance(threads, bool) or not isinstance(threads, int) or not 1 <= threads <= 64:
            raise ValueError(f"threads must be an integer in [1, 64], got {threads!r}")
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = threads
        options.inter_op_num_threads = 1
        options.log_severity_level = 3
        self.session = onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        self.metadata = dict(self.session.get_modelmeta().custom_metadata_map)
        self.input_size = int(self.session.get_inputs()[0].shape[1])  # the network's inputs
        self.memory: Any = None
        history = json.loads(self.metadata.get("history") or "null")
        if history:  # the agent remembers: predict keeps its history, as the Python policy does
            from agents.history import FlightMemory, HistorySettings

            settings = HistorySettings.from_spec(history)
            self.memory = FlightMemory(settings, settings.observation_size(self.input_size))
        self.observation_size = self.input_size if self.memory is None else self.memory.observation_size
        self.path = path

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """Actions for one env observation ``(obs_size,)`` or a batch ``(n, obs_size)`` (float32); an agent with
        a history remembers each row's observations between calls, as :class:`~agents.policy.TrainedPolicy` does,
        and a non-finite row gets the hover action (zero)."""
        obs = np.asarray(observation, dtype=np.float32)
        if obs.shape[-1:] != (self.observation_size,) or obs.ndim > 2:
            raise ValueError(f"observation must have shape ({self.observation_size},) or (n, {self.observation_size}), "
                             f"got {obs.shape}")
        rows = obs.reshape(-1, self.observation_size)
        if self.memory is None:  # the graph itself gives hover for a non-finite row
            (actions,) = self.session.run(["action"], {"observation": rows})
        else:
            inputs = self.memory(rows, episode_start).astype(np.float32)
            (actions,) = self.session.run(["action"], {"observation": inputs})
            actions[~np.all(np.isfinite(rows), axis=1)] = 0.0
        return (actions[0] if obs.ndim == 1 else actions), state

    def run_network(self, inputs: np.ndarray) -> np.ndarray:
        """The graph's actions ``(n, 4)`` for the network's own inputs ``(n, input_size)`` (history features
        when the agent has a history; nothing remembered)."""
        (actions,) = self.session.run(["action"], {"observation": np.asarray(inputs, dtype=np.float32).reshape(
            -1, self.input_size)})
        return np.asarray(actions)

    def __repr__(self) -> str:
        return f"OnnxPolicy({self.path}, {json.dumps(self.metadata.get('env_id'))})"


def time_onnx_steps(policy: OnnxPolicy, observations: np.ndarray) -> np.ndarray:
    """Seconds of each ``session.run`` on one row ``(1, input_size)`` of the network's inputs ``observations``
    (wall clock), after one untimed call; the inputs are prepared before the clock starts."""
    batch = np.ascontiguousarray(np.asarray(observations, dtype=np.float32).reshape(-1, 1, policy.input_size))
    session = policy.session
    session.run(["action"], {"observation": batch[0]})
    seconds = np.empty(len(batch))
    for i, row in enumerate(batch):
        start = time.perf_counter()
        session.run(["action"], {"observation": row})
        seconds[i] = time.perf_counter() - start
    return seconds


def measure_onnx_policy(source: str | Path | TrainedPolicy, folder: str | Path, seed: int = 0) -> dict[str, Any]:
    """Export ``source`` to ``folder/policy.onnx``, fly the Python agent once on the paper's Table II flight
    (:data:`controllers.paper_tables.TABLE_II`, seed ``seed``) and time, on that flight's observations, the
    Python ``predict`` and one onnxruntime call per observation (:func:`time_onnx_steps`); returns the figures
    in milliseconds and the largest difference between the two policies' actions over the flight."""
    import gymnasium as gym

    from controllers.evaluation import solve_time_stats
    from controllers.paper_tables import TABLE_II

    policy = _load(source)
    onnx_policy = OnnxPolicy(export_onnx(policy, Path(folder) / ONNX_FILE))
    scenario = TABLE_II[0]
    env = gym.make(scenario.env_id, **scenario.make_kwargs())
    observations, actions, seconds = [], [], []
    try:
        observation, _ = env.reset(seed=seed)
        done = False
        while not done:
            start = time.perf_counter()
            action, _ = policy.predict(observation)
            seconds.append(time.perf_counter() - start)
            observations.append(observation)
            actions.append(action)
            observation, _, terminated, truncated, _ = env.step(action)
            done = terminated or truncated
    finally:
        env.close()
    inputs = np.asarray(observations, dtype=np.float32)
    if policy.history is not None:  # the network's inputs: the flight's observations through a fresh history
        from agents.history import ObservationHistory

        history = ObservationHistory(policy.history.settings, policy.history.observation_size)
        inputs = np.vstack([history(row[None], np.array([k == 0]))[0] for k, row in enumerate(inputs)])
    onnx_actions = onnx_policy.run_network(inputs)  # the same network inputs the timing below runs
    return {
        "agent": str(policy.path or source),
        "env": scenario.env_id,
        "env_kwargs": scenario.make_kwargs(),
        "seed": seed,
        "steps": len(observations),
        "onnx_step_ms": solve_time_stats(time_onnx_steps(onnx_policy, inputs).tolist()),
        "python_predict_ms": solve_time_stats(seconds),
        "max_action_difference": float(np.max(np.abs(onnx_actions - np.asarray(actions)))),
        "targets": TARGETS,
    }
