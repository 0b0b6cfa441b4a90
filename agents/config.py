"""Training configuration: one YAML file per task in ``agents/configs/``, plus overrides.

A configuration says everything a training run needs besides its output folder:
which environment (and its keyword arguments), the domain-randomisation ranges,
the residual base controller, the vector env, PPO's hyperparameters, the network,
the normalisation and the evaluation/checkpoint schedule. ``wall-inspector train``
loads the task's file, applies command-line flags and ``--set key=value`` overrides
(dotted keys, YAML values: ``--set ppo.n_steps=128``), and saves the result as
``config.yaml`` in the run folder, so that a run can be resumed and repeated exactly.

The configuration is typed: :class:`TrainingConfig` holds one dataclass per section
(:class:`PPOSettings`, :class:`PolicySettings`, ...), each checking its fields' types and
ranges when it is built, and :meth:`TrainingConfig.from_dict` refuses unknown keys and checks
how the fields go together; every error names the field (``ppo.gamma``) and what it allows.
The training code reads the plain mapping :meth:`TrainingConfig.to_dict` gives (what
``config.yaml`` holds), which :func:`validate_config` checks through the typed configuration.

Task names are accepted in any of the forms ``WallSweep``, ``WallSweep-v0``,
``WallInspector/WallSweep-v0`` and ``wall_sweep``.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import MISSING, asdict, dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

import yaml

from controllers.threads import check_thread_setting
from wall_env.tasks import task_env_id, task_name, task_slug
from wall_env.validation import read_mapping

__all__ = [
    "CONFIG_DIR",
    "task_name",
    "task_env_id",
    "task_slug",
    "TrainingConfig",
    "PPOSettings",
    "PolicySettings",
    "NormalizeSettings",
    "WarmStartSettings",
    "TeacherSettings",
    "HistoryConfig",
    "EvalSettings",
    "CardEvalSettings",
    "default_config",
    "load_config",
    "apply_overrides",
    "validate_config",
    "ALGORITHMS",
    "save_config",
    "base_controller_kwargs",
]

CONFIG_DIR = Path(__file__).resolve().parent / "configs"

_ACTIVATIONS = ("tanh", "relu", "elu")
# sections whose entries are free-form (keywords of the env or of a base controller, ranges by name)
_OPEN_SECTIONS = ("env_kwargs", "randomize_ranges", "residual_base_kwargs")
_RESIDUAL_BASES = (None, "pid", "scmpc")
ALGORITHMS = ("ppo", "dagger")


# ---------------------------------------------------------------------------------------------- field checks
def _positive_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return value


def _whole(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"{name} must be a whole number >= 0, got {value!r}")
    return value


def _integer(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    return value


def _number(name: str, value: Any, low: float, high: float = float("inf"), low_open: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
        raise ValueError(f"{name} must be a number, got {value!r}")
    if value < low or value > high or (low_open and value == low):
        raise ValueError(f"{name} must be in {'(' if low_open else '['}{low}, {high}], got {value!r}")
    return float(value)


def _flag(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return value


def _choice(name: str, value: Any, allowed: tuple) -> Any:
    if value not in allowed:
        raise ValueError(f"{name} must be one of {allowed}, got {value!r}")
    return value


# ---------------------------------------------------------------------------------------------- the sections
@dataclass
class PPOSettings:
    """PPO's hyperparameters (``ppo:``)."""

    n_steps: int = 128  # per environment per rollout: n_envs * n_steps = 4096 transitions per update
    batch_size: int = 1024
    n_epochs: int = 5
    gamma: float = 0.99  # horizon ~1 s at 100 Hz: tracking errors matter within a second
    gae_lambda: float = 0.95
    learning_rate: float = 3.0e-4
    # None: constant; a number: the learning rate falls linearly from learning_rate to this value over the
    # run's planned timesteps (SB3's LinearSchedule)
    learning_rate_final: float | None = None
    # None, or a target KL per minibatch step: the learning rate then adapts to keep the KL near it (x1.5 below
    # half of it, /1.5 above twice it; agents.lean_ppo), starting from learning_rate
    adaptive_kl: float | None = None
    clip_range: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    target_kl: float | None = None

    def __post_init__(self) -> None:
        for key in ("n_steps", "batch_size", "n_epochs"):
            _positive_int(f"ppo.{key}", getattr(self, key))
        _number("ppo.gamma", self.gamma, 0.0, 1.0, low_open=True)
        _number("ppo.gae_lambda", self.gae_lambda, 0.0, 1.0)
        _number("ppo.learning_rate", self.learning_rate, 0.0, low_open=True)
        if self.learning_rate_final is not None:
            _number("ppo.learning_rate_final", self.learning_rate_final, 0.0, self.learning_rate)
        for key in ("clip_range", "max_grad_norm"):
            _number(f"ppo.{key}", getattr(self, key), 0.0, low_open=True)
        for key in ("ent_coef", "vf_coef"):
            _number(f"ppo.{key}", getattr(self, key), 0.0)
        if self.adaptive_kl is not None:
            _number("ppo.adaptive_kl", self.adaptive_kl, 0.0, 1.0, low_open=True)
            if self.learning_rate_final is not None:
                raise ValueError("ppo.adaptive_kl adapts the learning rate itself: leave ppo.learning_rate_final unset "
                                 "(null)")
        if self.target_kl is not None:
            _number("ppo.target_kl", self.target_kl, 0.0, low_open=True)


@dataclass
class PolicySettings:
    """The network (``policy:``)."""

    net_arch: list[int] = field(default_factory=lambda: [64, 64])  # hidden layers of the actor (and of the critic)
    critic_arch: list[int] | None = None  # hidden layers of the critic; None: net_arch's
    activation: str = "tanh"  # one of tanh, relu, elu
    log_std_init: float = -1.0  # initial exploration std exp(-1) = 0.37 of the action range
    ortho_init: bool = True

    def __post_init__(self) -> None:
        _number("policy.log_std_init", self.log_std_init, -20.0, 5.0)
        if not (isinstance(self.net_arch, list)
                and all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in self.net_arch)):
            raise ValueError(f"policy.net_arch must be a list of positive layer widths, got {self.net_arch!r}")
        if self.critic_arch is not None and not (
                isinstance(self.critic_arch, list)
                and all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in self.critic_arch)):
            raise ValueError(f"policy.critic_arch must be null or a list of positive layer widths, got {self.critic_arch!r}")
        if not isinstance(self.activation, str) or self.activation not in _ACTIVATIONS:
            raise ValueError(f"policy.activation must be one of {_ACTIVATIONS}, got {self.activation!r}")
        _flag("policy.ortho_init", self.ortho_init)


@dataclass
class NormalizeSettings:
    """``VecNormalize``'s settings (``normalize:``)."""

    norm_obs: bool = True
    norm_reward: bool = True
    clip_obs: float = 10.0
    clip_reward: float = 10.0

    def __post_init__(self) -> None:
        for key in ("norm_obs", "norm_reward"):
            _flag(f"normalize.{key}", getattr(self, key))
        for key in ("clip_obs", "clip_reward"):
            _number(f"normalize.{key}", getattr(self, key), 0.0, low_open=True)


def _check_supervised(section: str, settings: Any, counts: tuple[str, ...]) -> None:
    """The fields a controller's flights fitted by supervised learning share (a warm start, a teacher): the flight
    counts ``counts``, the fit's epochs and batch size, the action noise, the learning rate and the seed."""
    for key in (*counts, "epochs", "batch_size"):
        _positive_int(f"{section}.{key}", getattr(settings, key))
    _number(f"{section}.noise", settings.noise, 0.0, 1.0)
    _number(f"{section}.learning_rate", settings.learning_rate, 0.0, low_open=True)
    _whole(f"{section}.seed", settings.seed)


@dataclass
class WarmStartSettings:
    """A warm start (``warm_start:``, :mod:`agents.behaviour_cloning`): before PPO, a controller (None, "pid" or
    "scmpc"; built with residual_base_kwargs) flies demo_envs batched envs for demo_steps steps each, acting with
    its action plus Gaussian noise (std spread over the envs from 0 to noise, normalised units) but recording its
    clean action; the actor is cloned on those actions and the critic on their returns for epochs passes
    (minibatches of batch_size, Adam at learning_rate, cosine decay), normaliser fitted to them. Demonstration env
    k flies seed ``seed + run seed * demo_envs + k``: seeds of their own, away from the model card's (card_eval.seed
    up) and the evaluations' (eval.seed up)."""

    controller: str | None = None
    demo_envs: int = 128
    demo_steps: int = 1700
    noise: float = 0.1
    epochs: int = 20
    batch_size: int = 1024
    learning_rate: float = 1.0e-3
    seed: int = 1_000_000

    def __post_init__(self) -> None:
        _choice("warm_start.controller", self.controller, _RESIDUAL_BASES)
        _check_supervised("warm_start", self, ("demo_envs", "demo_steps"))


@dataclass
class TeacherSettings:
    """``--algo dagger`` (``teacher:``, :mod:`agents.distillation`): the teacher ("pid" or "scmpc"; built with
    residual_base_kwargs) flies envs batched envs for steps steps with DART noise up to noise, then iterations - 1
    times the student flies and the teacher labels its states; after each, the normaliser and the actor are fitted
    to every label so far (epochs passes, minibatches of batch_size, Adam at learning_rate) and judged on the
    evaluation envs: the best iteration is kept. Env k of iteration i flies seed
    ``seed + (run seed * iterations + i) * envs + k``: away from the card's and the evaluations' seeds."""

    # 64 envs and one round of the student's states: 5 of 5 seeds at 0.075 cm in 16 s on a quiet machine
    # (wall-inspector bench-train --algo dagger); 16 envs x 3 iterations of 10 epochs fitted worse with every
    # iteration (held-out action error 0.010, 0.038, 0.156) and touched the wall
    controller: str = "scmpc"
    envs: int = 64
    steps: int = 1700
    iterations: int = 2
    noise: float = 0.1
    epochs: int = 10
    batch_size: int = 1024
    learning_rate: float = 1.0e-3
    seed: int = 2_000_000

    def __post_init__(self) -> None:
        if not isinstance(self.controller, str) or self.controller not in ("pid", "scmpc"):
            raise ValueError(f"teacher.controller must be 'pid' or 'scmpc', got {self.controller!r}")
        _check_supervised("teacher", self, ("envs", "steps", "iterations"))


@dataclass
class HistoryConfig:
    """What the agent remembers (``history:``, :mod:`agents.history`): the last ``frames`` observations ``stride``
    steps apart and a leaky integral of the position error with time constant ``integral_time`` (s; 0: none)."""

    frames: int = 1
    stride: int = 1
    integral_time: float = 0.0

    def __post_init__(self) -> None:
        from agents.history import HistorySettings

        HistorySettings(self.frames, self.stride, self.integral_time)  # ValueError naming the field and its range


@dataclass
class EvalSettings:
    """Evaluations during training (``eval:``): every ``freq`` env steps, ``episodes`` episodes from ``seed`` up."""

    freq: int = 100_000
    episodes: int = 5
    seed: int = 10_000

    def __post_init__(self) -> None:
        _positive_int("eval.freq", self.freq)
        _positive_int("eval.episodes", self.episodes)
        _integer("eval.seed", self.seed)


@dataclass
class CardEvalSettings:
    """The final evaluation written to the model card (``card_eval:``)."""

    episodes: int = 10
    seed: int = 0

    def __post_init__(self) -> None:
        _positive_int("card_eval.episodes", self.episodes)
        _integer("card_eval.seed", self.seed)


_SECTIONS: dict[str, type] = {"warm_start": WarmStartSettings, "teacher": TeacherSettings, "history": HistoryConfig,
                              "ppo": PPOSettings, "policy": PolicySettings, "normalize": NormalizeSettings,
                              "eval": EvalSettings, "card_eval": CardEvalSettings}


def _scmpc_base_defaults() -> dict[str, Any]:
    # SC-MPC is given the paper's identified suction model (it is the controller's knowledge, not the simulator's
    # truth); threads: it solves a batched env's rows on the cores free to the run (auto: controllers.threads);
    # solver: one LM iteration per control step from the shifted previous solution (real-time iteration), 1.7x
    # cheaper than iterating to the tolerance (2.2 iterations) and as precise on the sweep: 0.578 mm wall-normal
    # RMSE either way over seeds 100-109
    return {"pid": {"preset": "tuned"},
            "scmpc": {"k_s": 4.1, "d_thr": 0.132, "preset": "tuned", "threads": "auto", "solver": {"max_iterations": 1}}}


@dataclass
class TrainingConfig:
    """Everything a training run needs besides its output folder, typed: the sections are the dataclasses above,
    each checking its fields' types and ranges when built; :meth:`from_dict` refuses unknown keys and checks how
    the fields go together. ``env_kwargs``, ``randomize_ranges`` and ``residual_base_kwargs`` are free-form (the
    env's and the controllers' own keywords, which they check)."""

    env_id: str | None = None
    env_kwargs: dict[str, Any] = field(default_factory=dict)  # passed to gym.make, e.g. {k_s: 4.1, noise: true}
    randomize: bool = False  # draw k_s, d_thr, standoff, mass, ... per episode from randomize_ranges
    randomize_ranges: dict[str, Any] = field(default_factory=dict)
    residual: str | None = None  # None, "pid" or "scmpc": learn a correction on top of that controller
    residual_scale: list[float] = field(default_factory=lambda: [0.2, 0.2, 0.2, 0.2])  # largest correction per entry
    # keywords for each base controller's from_env (residual base, warm start's demonstrator, teacher)
    residual_base_kwargs: dict[str, Any] = field(default_factory=_scmpc_base_defaults)
    warm_start: WarmStartSettings = field(default_factory=WarmStartSettings)
    # the learner: "ppo" (agents.lean_ppo.LeanPPO, the task learned from its reward alone) or "dagger" (a
    # controller distilled into the network, agents.distillation; settings in teacher)
    algo: str = "ppo"
    teacher: TeacherSettings = field(default_factory=TeacherSettings)
    history: HistoryConfig = field(default_factory=HistoryConfig)
    timesteps: int = 1_000_000
    seed: int = 0
    n_envs: int = 32  # environments in the vector env
    n_workers: int = 2  # processes that run them (n_envs / n_workers environments each; vector: subprocess)
    # "batched": every env in one batched env in the learner's process (one compiled call per step);
    # "subprocess": n_envs single envs in n_workers processes
    vector: str = "batched"
    # PyTorch threads of the updates (and of a warm start's cloning or a teacher's distillation): "auto" takes the
    # cores free to the process, measured again before every update (controllers.threads: never more threads than
    # free cores); a number is used as given
    torch_threads: int | str = "auto"
    # PyTorch threads while rollouts are collected: the policy then acts on n_envs observations at a time, which
    # below ROLLOUT_ROWS_PER_THREAD rows per thread runs faster on one thread than split over two; "auto": that
    # rule within the free cores
    rollout_torch_threads: int | str = "auto"
    # rollouts in a second process, flown while the learner updates on the one before (agents.rollout_worker: one
    # update behind; an iteration costs the longer of rollout and update instead of their sum); a run that may use one
    # core only keeps them in its own process
    rollout_worker: bool = False
    ppo: PPOSettings = field(default_factory=PPOSettings)
    policy: PolicySettings = field(default_factory=PolicySettings)
    normalize: NormalizeSettings = field(default_factory=NormalizeSettings)
    eval: EvalSettings = field(default_factory=EvalSettings)  # freq in env steps
    checkpoint_freq: int = 250_000  # env steps; 0 turns checkpoints by steps off
    checkpoint_minutes: float = 10.0  # wall time between checkpoints as well; 0 turns checkpoints by time off
    card_eval: CardEvalSettings = field(default_factory=CardEvalSettings)

    @classmethod
    def defaults(cls) -> dict[str, Any]:
        """The shared defaults as a plain mapping (``env_id`` unset, so not yet a valid configuration)."""
        out: dict[str, Any] = {}
        for f in fields(cls):
            value = f.default_factory() if f.default_factory is not MISSING else f.default
            out[f.name] = asdict(value) if is_dataclass(value) and not isinstance(value, type) else value
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainingConfig:
        """The typed configuration of ``data`` (keys as in the YAML files); ``ValueError`` naming the field and
        its allowed values for anything unknown, missing or out of range."""
        if not isinstance(data, Mapping):
            raise ValueError(f"a training configuration must be a mapping, got {data!r}")
        allowed = {f.name for f in fields(cls)}
        unknown = sorted(map(str, set(data) - allowed))
        if unknown:
            raise ValueError(f"unknown key(s) {unknown}; allowed: {sorted(allowed)}")
        if data.get("env_id") is None:
            raise ValueError("env_id is not set: name the task (--env, or env_id in the configuration file)")
        if not isinstance(data["env_id"], str):
            raise ValueError(f"env_id must be a task name such as WallInspector/WallSweep-v0, got {data['env_id']!r}")
        values = dict(data)
        for name, section_type in _SECTIONS.items():
            section = values.get(name, {})
            if not isinstance(section, Mapping):
                raise ValueError(f"{name} must be a mapping, got {section!r}")
            names = {f.name for f in fields(section_type)}
            unknown = sorted(map(str, set(section) - names))
            if unknown:
                raise ValueError(f"{name}: unknown key(s) {unknown}; allowed: {sorted(names)}")
            missing = sorted(names - set(section))
            if missing and name in data:
                raise ValueError(f"{name}: missing key(s) {missing}")
            values[name] = section_type(**section)
        return cls(**values)

    def __post_init__(self) -> None:
        self.env_id = task_env_id(self.env_id)  # type: ignore[arg-type]
        for key in ("timesteps", "n_envs", "n_workers"):
            _positive_int(key, getattr(self, key))
        for key in ("torch_threads", "rollout_torch_threads"):
            check_thread_setting(getattr(self, key), key)
        if isinstance(self.checkpoint_freq, bool) or not isinstance(self.checkpoint_freq, int) or self.checkpoint_freq < 0:
            raise ValueError(f"checkpoint_freq must be a whole number of env steps >= 0, got {self.checkpoint_freq!r}")
        _number("checkpoint_minutes", self.checkpoint_minutes, 0.0)
        _flag("rollout_worker", self.rollout_worker)
        if self.n_workers > self.n_envs:
            raise ValueError(f"n_workers ({self.n_workers}) must not exceed n_envs ({self.n_envs})")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise ValueError(f"seed must be an integer, got {self.seed!r}")
        if self.ppo.n_steps * self.n_envs < 2:
            raise ValueError("ppo.n_steps * n_envs must be at least 2")
        if self.vector not in ("batched", "subprocess"):
            raise ValueError(f"vector must be 'batched' or 'subprocess', got {self.vector!r}")
        _choice("residual", self.residual, _RESIDUAL_BASES)
        scale: Any = self.residual_scale
        if isinstance(scale, (int, float)) and not isinstance(scale, bool):
            scale = self.residual_scale = [float(scale)] * 4
        if not (isinstance(scale, (list, tuple)) and len(scale) == 4
                and all(isinstance(s, (int, float)) and not isinstance(s, bool) and 0.0 < s <= 2.0 for s in scale)):
            raise ValueError(f"residual_scale must be 4 numbers in (0, 2], got {scale!r}")
        if self.warm_start.controller and self.residual:
            raise ValueError("warm_start clones a controller into a policy that flies the task itself; a residual agent "
                             f"(residual: {self.residual}) already starts from its base controller: use one or the other")
        if not isinstance(self.algo, str) or self.algo not in ALGORITHMS:
            raise ValueError(f"algo must be one of {ALGORITHMS}, got {self.algo!r}")
        if self.algo == "dagger" and (self.residual or self.warm_start.controller):
            raise ValueError("algo dagger distils its teacher into a policy that flies the task itself: it takes neither "
                             "residual nor warm_start")
        base_kwargs = self.residual_base_kwargs
        if not (isinstance(base_kwargs, dict) and all(isinstance(v, dict) or v is None for v in base_kwargs.values())):
            raise ValueError(f"residual_base_kwargs must map a base controller to its keywords, got {base_kwargs!r}")
        if not isinstance(self.env_kwargs, dict):
            raise ValueError(f"env_kwargs must be a mapping, got {self.env_kwargs!r}")
        reserved = sorted({"randomize", "task"} & set(self.env_kwargs))
        if reserved:
            raise ValueError(f"env_kwargs must not set {reserved}; use randomize/randomize_ranges")
        ranges = self.randomize_ranges if self.randomize_ranges is not None else {}
        if not isinstance(ranges, dict):
            raise ValueError(f"randomize_ranges must be a mapping of name: [low, high], got {ranges!r}")
        self.randomize_ranges = ranges
        for key, bounds in ranges.items():
            if not (isinstance(bounds, (list, tuple)) and len(bounds) == 2
                    and all(isinstance(b, (int, float)) and not isinstance(b, bool) for b in bounds)):
                raise ValueError(f"randomize_ranges[{key!r}] must be a [low, high] pair, got {bounds!r}")
        _flag("randomize", self.randomize)
        if self.randomize and not ranges:
            raise ValueError("randomize is on but randomize_ranges is empty")

    def to_dict(self) -> dict[str, Any]:
        """The plain mapping (as in the YAML files and ``config.yaml``) that the training code reads; the free-form
        sections are passed on as given."""
        return {f.name: asdict(value) if f.name in _SECTIONS else value
                for f in fields(self) for value in [getattr(self, f.name)]}


_BASE: dict[str, Any] = TrainingConfig.defaults()  # the shared defaults; a task's YAML file overrides any of them


def _merge(base: dict, update: dict) -> dict:
    out = copy.deepcopy(base)
    for key, value in update.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict) and key not in ("env_kwargs", "randomize_ranges"):
            # sections merge key by key; env_kwargs and randomize_ranges are replaced whole
            out[key] = _merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def default_config(task: str) -> dict[str, Any]:
    """The task's configuration: shared defaults overridden by ``configs/<slug>.yaml``."""
    path = CONFIG_DIR / f"{task_slug(task)}.yaml"
    if not path.is_file():
        raise FileNotFoundError(f"no training configuration for {task_name(task)}: {path} does not exist")
    config = load_config(path, validate=False)
    config["env_id"] = task_env_id(task)
    return validate_config(config)


def load_config(path: str | Path, validate: bool = True) -> dict[str, Any]:
    """Shared defaults overridden by the YAML file at ``path``."""
    path = Path(path)
    data = read_mapping(path, "configuration file", "yaml", empty_is_mapping=True)
    unknown = sorted(set(data) - set(_BASE))
    if unknown:
        raise ValueError(f"configuration file {path}: unknown key(s) {unknown}; allowed: {sorted(_BASE)}")
    config = _merge(_BASE, data)
    return validate_config(config) if validate else config


def apply_overrides(config: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """Apply ``key.sub=value`` strings (values parsed as YAML) to a copy of ``config``."""
    config = copy.deepcopy(config)
    for item in overrides or []:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"override must look like key=value or key.sub=value, got {item!r}")
        parts = key.strip().split(".")
        node = config
        for part in parts[:-1]:
            if not isinstance(node.get(part), dict):
                raise ValueError(f"override {item!r}: {part!r} is not a section of the configuration")
            node = node[part]
        if parts[-1] not in node and (node is config or parts[0] not in _OPEN_SECTIONS):
            raise ValueError(f"override {item!r}: unknown key {parts[-1]!r}; allowed: {sorted(node)}")
        try:
            value = yaml.safe_load(raw)
        except yaml.YAMLError as exc:
            raise ValueError(f"override {item!r}: the value is not valid YAML ({str(exc).splitlines()[0]})") from None
        if isinstance(node.get(parts[-1]), dict) and (node is not config or parts[-1] not in _OPEN_SECTIONS):
            if not isinstance(value, dict):  # a section: its entries change, one by one
                raise ValueError(f"override {item!r}: {key.strip()} is a section; set its entries as "
                                 f"{key.strip()}.KEY=VALUE or give a mapping")
            value = _merge(node[parts[-1]], value)
        node[parts[-1]] = value
    return validate_config(config)


def validate_config(config: dict[str, Any]) -> dict[str, Any]:
    """Check ``config`` through :class:`TrainingConfig` (types, ranges, unknown keys); return ``config``, normalised
    in place (the task's full id, a scalar residual scale as four entries), or raise ``ValueError``."""
    typed = TrainingConfig.from_dict(config)
    config.clear()
    config.update(typed.to_dict())
    return config


def base_controller_kwargs(config: dict[str, Any], name: str) -> dict[str, Any]:
    """A copy of the configured ``from_env`` keywords of controller ``name`` (``"pid"``, ``"scmpc"``): a
    residual agent's base or a warm start's demonstrator."""
    return dict(config["residual_base_kwargs"].get(name) or {})


def save_config(config: dict[str, Any], path: str | Path) -> None:
    Path(path).write_text(yaml.safe_dump(config, sort_keys=False))
