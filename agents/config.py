"""Training configuration: one YAML file per task in ``agents/configs/``, plus overrides.

A configuration says everything a training run needs besides its output folder:
which environment (and its keyword arguments), the domain-randomisation ranges,
the residual base controller, the vector env, PPO's hyperparameters, the network,
the normalisation and the evaluation/checkpoint schedule. ``wall-inspector train``
loads the task's file, applies command-line flags and ``--set key=value`` overrides
(dotted keys, YAML values: ``--set ppo.n_steps=128``), and saves the result as
``config.yaml`` in the run folder, so that a run can be resumed and repeated exactly.

Task names are accepted in any of the forms ``WallSweep``, ``WallSweep-v0``,
``WallInspector/WallSweep-v0`` and ``wall_sweep``.
"""

from __future__ import annotations

import copy
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
    "default_config",
    "load_config",
    "apply_overrides",
    "validate_config",
    "ALGORITHMS",
    "save_config",
    "base_controller_kwargs",
]

CONFIG_DIR = Path(__file__).resolve().parent / "configs"

# Defaults shared by every task; a task's YAML file overrides any of them.
_BASE: dict[str, Any] = {
    "env_id": None,
    "env_kwargs": {},  # passed to gym.make, e.g. {k_s: 4.1, d_thr: 0.132, noise: true}
    "randomize": False,  # draw k_s, d_thr, standoff, mass per episode from randomize_ranges
    "randomize_ranges": {},
    "residual": None,  # None, "pid" or "scmpc": learn a correction on top of that controller
    "residual_scale": [0.2, 0.2, 0.2, 0.2],  # largest correction per normalised action entry
    # keywords for each base controller's from_env (residual base, or demonstrator of warm_start):
    # SC-MPC is given the paper's identified suction model (it is the controller's knowledge, not the simulator's truth)
    "residual_base_kwargs": {"pid": {"preset": "tuned"},
                             # threads: SC-MPC solves a batched env's rows on the cores free to the run
                             # (auto: controllers.threads; both cores of a quiet 2-core machine);
                             # solver: one LM iteration per control step from the shifted previous
                             # solution (real-time iteration), 1.7x cheaper than iterating to the
                             # tolerance (2.2 iterations) and as precise on the sweep: 0.578 mm
                             # wall-normal RMSE either way over seeds 100-109
                             "scmpc": {"k_s": 4.1, "d_thr": 0.132, "preset": "tuned", "threads": "auto",
                                       "solver": {"max_iterations": 1}}},
    # warm start (agents.behaviour_cloning): before PPO, a controller (None, "pid" or "scmpc"; built with
    # residual_base_kwargs) flies demo_envs batched envs for demo_steps steps each, acting with its action
    # plus Gaussian noise (std spread over the envs from 0 to noise, normalised units) but recording its
    # clean action; the actor is cloned on those actions and the critic on their returns for epochs
    # passes (minibatches of batch_size, Adam at learning_rate, cosine decay), normaliser fitted to them.
    # Demonstration env k flies seed warm_start.seed + seed * demo_envs + k: seeds of their own, away from
    # the model card's (card_eval.seed up) and the evaluations' (eval.seed up)
    "warm_start": {"controller": None, "demo_envs": 128, "demo_steps": 1700, "noise": 0.1, "epochs": 20,
                   "batch_size": 1024, "learning_rate": 1.0e-3, "seed": 1_000_000},
    # the learner: "ppo" (agents.lean_ppo.LeanPPO, the task learned from its reward alone) or "dagger" (a
    # controller distilled into the network, agents.distillation; settings in teacher)
    "algo": "ppo",
    # --algo dagger: teacher ("pid" or "scmpc"; built with residual_base_kwargs) flies envs batched envs
    # for steps steps with DART noise up to noise, then iterations - 1 times the student flies and the teacher
    # labels its states; after each, the normaliser and the actor are fitted to every label so far (epochs
    # passes, minibatches of batch_size, Adam at learning_rate) and judged on the evaluation envs: the best
    # iteration is kept. Env k of iteration i flies seed
    # seed + (run seed * iterations + i) * envs + k: away from the card's and the evaluations' seeds
    "teacher": {"controller": "scmpc", "envs": 16, "steps": 1700, "iterations": 3, "noise": 0.1, "epochs": 10,
                "batch_size": 1024, "learning_rate": 1.0e-3, "seed": 2_000_000},
    # what the agent remembers (agents.history): the last `frames` observations `stride` steps apart and a
    # leaky integral of the position error with time constant `integral_time` (s; 0: none)
    "history": {"frames": 1, "stride": 1, "integral_time": 0.0},
    "timesteps": 1_000_000,
    "seed": 0,
    "n_envs": 32,  # environments in the vector env (16 per worker: IPC and SB3 overhead amortised)
    "n_workers": 2,  # processes that run them (n_envs / n_workers environments each; vector: subprocess)
    # "batched": every env in one batched env in the learner's process (one compiled call per step);
    # "subprocess": n_envs single envs in n_workers processes.
    "vector": "batched",
    # PyTorch threads of the updates (and of a warm start's cloning or a teacher's distillation):
    # "auto" takes the cores free to the process, measured again before every update
    # (controllers.threads: never more threads than free cores); a number is used as given
    "torch_threads": "auto",
    # PyTorch threads while rollouts are collected: the policy then acts on n_envs observations at a
    # time, which below ROLLOUT_ROWS_PER_THREAD rows per thread runs faster on one thread than split
    # over two; "auto": that rule within the free cores
    "rollout_torch_threads": "auto",
    "ppo": {
        "n_steps": 128,  # per environment per rollout: n_envs * n_steps = 4096 transitions per update
        "batch_size": 1024,
        "n_epochs": 5,
        "gamma": 0.99,  # horizon ~1 s at 100 Hz: tracking errors matter within a second
        "gae_lambda": 0.95,
        "learning_rate": 3.0e-4,
        # None: constant; a number: the learning rate falls linearly from learning_rate to this
        # value over the run's planned timesteps (SB3's LinearSchedule)
        "learning_rate_final": None,
        # None, or a target KL per minibatch step: the learning rate then adapts to keep the KL near it
        # (x1.5 below half of it, /1.5 above twice it; agents.lean_ppo), starting from learning_rate
        "adaptive_kl": None,
        "clip_range": 0.2,
        "ent_coef": 0.0,
        "vf_coef": 0.5,
        "max_grad_norm": 0.5,
        "target_kl": None,
    },
    "policy": {
        "net_arch": [64, 64],  # hidden layers of both the actor and the critic
        "activation": "tanh",
        "log_std_init": -1.0,  # initial exploration std exp(-1) = 0.37 of the action range
        "ortho_init": True,
    },
    "normalize": {"norm_obs": True, "norm_reward": True, "clip_obs": 10.0, "clip_reward": 10.0},
    "eval": {"freq": 100_000, "episodes": 5, "seed": 10_000},  # freq in env steps
    "checkpoint_freq": 250_000,  # env steps; 0 turns checkpoints by steps off
    "checkpoint_minutes": 10.0,  # wall time between checkpoints as well; 0 turns checkpoints by time off
    "card_eval": {"episodes": 10, "seed": 0},  # final evaluation written to the model card
}

_ACTIVATIONS = ("tanh", "relu", "elu")
# sections whose entries are free-form (keywords of the env or of a base controller, ranges by name)
_OPEN_SECTIONS = ("env_kwargs", "randomize_ranges", "residual_base_kwargs")
_RESIDUAL_BASES = (None, "pid", "scmpc")
ALGORITHMS = ("ppo", "dagger")


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
    """Check types and ranges; return ``config`` (normalised in place) or raise ``ValueError``."""
    if config.get("env_id") is None:
        raise ValueError("env_id is not set: name the task (--env, or env_id in the configuration file)")
    if not isinstance(config["env_id"], str):
        raise ValueError(f"env_id must be a task name such as WallInspector/WallSweep-v0, got {config['env_id']!r}")
    config["env_id"] = task_env_id(config["env_id"])

    def positive_int(name: str, value: Any) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
        return value

    for section, allowed in _BASE.items():
        if isinstance(allowed, dict) and section not in _OPEN_SECTIONS:
            if not isinstance(config.get(section), dict):
                raise ValueError(f"{section} must be a mapping, got {config.get(section)!r}")
            unknown = sorted(set(config[section]) - set(allowed))
            if unknown:
                raise ValueError(f"{section}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")
            missing = sorted(set(allowed) - set(config[section]))
            if missing:
                raise ValueError(f"{section}: missing key(s) {missing}")

    def number(name: str, value: Any, low: float, high: float = float("inf"), low_open: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
            raise ValueError(f"{name} must be a number, got {value!r}")
        if value < low or value > high or (low_open and value == low):
            raise ValueError(f"{name} must be in {'(' if low_open else '['}{low}, {high}], got {value!r}")
        return float(value)

    for key in ("timesteps", "n_envs", "n_workers"):
        positive_int(key, config[key])
    for key in ("torch_threads", "rollout_torch_threads"):
        check_thread_setting(config[key], key)
    if isinstance(config["checkpoint_freq"], bool) or not isinstance(config["checkpoint_freq"], int) \
            or config["checkpoint_freq"] < 0:
        raise ValueError(f"checkpoint_freq must be a whole number of env steps >= 0, got {config['checkpoint_freq']!r}")
    number("checkpoint_minutes", config["checkpoint_minutes"], 0.0)
    if config["n_workers"] > config["n_envs"]:
        raise ValueError(f"n_workers ({config['n_workers']}) must not exceed n_envs ({config['n_envs']})")
    if not isinstance(config["seed"], int):
        raise ValueError(f"seed must be an integer, got {config['seed']!r}")
    ppo = config["ppo"]
    for key in ("n_steps", "batch_size", "n_epochs"):
        positive_int(f"ppo.{key}", ppo[key])
    if ppo["n_steps"] * config["n_envs"] < 2:
        raise ValueError("ppo.n_steps * n_envs must be at least 2")
    number("ppo.gamma", ppo["gamma"], 0.0, 1.0, low_open=True)
    number("ppo.gae_lambda", ppo["gae_lambda"], 0.0, 1.0)
    number("ppo.learning_rate", ppo["learning_rate"], 0.0, low_open=True)
    if ppo["learning_rate_final"] is not None:
        number("ppo.learning_rate_final", ppo["learning_rate_final"], 0.0, ppo["learning_rate"])
    for key in ("clip_range", "max_grad_norm"):
        number(f"ppo.{key}", ppo[key], 0.0, low_open=True)
    for key in ("ent_coef", "vf_coef"):
        number(f"ppo.{key}", ppo[key], 0.0)
    if ppo["adaptive_kl"] is not None:
        number("ppo.adaptive_kl", ppo["adaptive_kl"], 0.0, 1.0, low_open=True)
        if ppo["learning_rate_final"] is not None:
            raise ValueError("ppo.adaptive_kl adapts the learning rate itself: leave ppo.learning_rate_final unset (null)")
    if ppo["target_kl"] is not None:
        number("ppo.target_kl", ppo["target_kl"], 0.0, low_open=True)
    number("policy.log_std_init", config["policy"]["log_std_init"], -20.0, 5.0)
    norm = config["normalize"]
    for key in ("norm_obs", "norm_reward"):
        if not isinstance(norm[key], bool):
            raise ValueError(f"normalize.{key} must be true or false, got {norm[key]!r}")
    for key in ("clip_obs", "clip_reward"):
        number(f"normalize.{key}", norm[key], 0.0, low_open=True)
    policy = config["policy"]
    if not (isinstance(policy["net_arch"], list) and all(isinstance(n, int) and n > 0 for n in policy["net_arch"])):
        raise ValueError(f"policy.net_arch must be a list of positive layer widths, got {policy['net_arch']!r}")
    if policy["activation"] not in _ACTIVATIONS:
        raise ValueError(f"policy.activation must be one of {_ACTIVATIONS}, got {policy['activation']!r}")
    if config["vector"] not in ("batched", "subprocess"):
        raise ValueError(f"vector must be 'batched' or 'subprocess', got {config['vector']!r}")
    if config["residual"] not in _RESIDUAL_BASES:
        raise ValueError(f"residual must be one of {_RESIDUAL_BASES}, got {config['residual']!r}")
    scale = config["residual_scale"]
    if isinstance(scale, (int, float)) and not isinstance(scale, bool):
        scale = config["residual_scale"] = [float(scale)] * 4
    if not (isinstance(scale, (list, tuple)) and len(scale) == 4
            and all(isinstance(s, (int, float)) and not isinstance(s, bool) and 0.0 < s <= 2.0 for s in scale)):
        raise ValueError(f"residual_scale must be 4 numbers in (0, 2], got {scale!r}")
    warm = config["warm_start"]
    if warm["controller"] not in _RESIDUAL_BASES:
        raise ValueError(f"warm_start.controller must be one of {_RESIDUAL_BASES}, got {warm['controller']!r}")
    if warm["controller"] and config["residual"]:
        raise ValueError("warm_start clones a controller into a policy that flies the task itself; a residual agent "
                         f"(residual: {config['residual']}) already starts from its base controller: use one or the other")
    for key in ("demo_envs", "demo_steps", "epochs", "batch_size"):
        positive_int(f"warm_start.{key}", warm[key])
    number("warm_start.noise", warm["noise"], 0.0, 1.0)
    number("warm_start.learning_rate", warm["learning_rate"], 0.0, low_open=True)
    if isinstance(warm["seed"], bool) or not isinstance(warm["seed"], int) or warm["seed"] < 0:
        raise ValueError(f"warm_start.seed must be a whole number >= 0, got {warm['seed']!r}")
    from agents.history import HistorySettings

    HistorySettings.from_spec(config["history"])  # ValueError naming the field and its range
    if config["algo"] not in ALGORITHMS:
        raise ValueError(f"algo must be one of {ALGORITHMS}, got {config['algo']!r}")
    teacher = config["teacher"]
    if teacher["controller"] not in ("pid", "scmpc"):
        raise ValueError(f"teacher.controller must be 'pid' or 'scmpc', got {teacher['controller']!r}")
    for key in ("envs", "steps", "iterations", "epochs", "batch_size"):
        positive_int(f"teacher.{key}", teacher[key])
    number("teacher.noise", teacher["noise"], 0.0, 1.0)
    number("teacher.learning_rate", teacher["learning_rate"], 0.0, low_open=True)
    if isinstance(teacher["seed"], bool) or not isinstance(teacher["seed"], int) or teacher["seed"] < 0:
        raise ValueError(f"teacher.seed must be a whole number >= 0, got {teacher['seed']!r}")
    if config["algo"] == "dagger" and (config["residual"] or warm["controller"]):
        raise ValueError("algo dagger distils its teacher into a policy that flies the task itself: it takes neither "
                         "residual nor warm_start")
    base_kwargs = config["residual_base_kwargs"]
    if not (isinstance(base_kwargs, dict) and all(isinstance(v, dict) or v is None for v in base_kwargs.values())):
        raise ValueError(f"residual_base_kwargs must map a base controller to its keywords, got {base_kwargs!r}")
    if not isinstance(config["env_kwargs"], dict):
        raise ValueError(f"env_kwargs must be a mapping, got {config['env_kwargs']!r}")
    reserved = sorted({"randomize", "task"} & set(config["env_kwargs"]))
    if reserved:
        raise ValueError(f"env_kwargs must not set {reserved}; use randomize/randomize_ranges")
    ranges = config["randomize_ranges"] or {}
    if not isinstance(ranges, dict):
        raise ValueError(f"randomize_ranges must be a mapping of name: [low, high], got {ranges!r}")
    for key, bounds in ranges.items():
        if not (isinstance(bounds, (list, tuple)) and len(bounds) == 2
                and all(isinstance(b, (int, float)) and not isinstance(b, bool) for b in bounds)):
            raise ValueError(f"randomize_ranges[{key!r}] must be a [low, high] pair, got {bounds!r}")
    if config["randomize"] and not ranges:
        raise ValueError("randomize is on but randomize_ranges is empty")
    for name in ("eval.freq", "eval.episodes", "card_eval.episodes"):
        section, key = name.split(".")
        positive_int(name, config[section][key])
    for name in ("eval.seed", "card_eval.seed"):
        section, key = name.split(".")
        if isinstance(config[section][key], bool) or not isinstance(config[section][key], int):
            raise ValueError(f"{name} must be an integer, got {config[section][key]!r}")
    if not isinstance(config["randomize"], bool):
        raise ValueError(f"randomize must be true or false, got {config['randomize']!r}")
    return config


def base_controller_kwargs(config: dict[str, Any], name: str) -> dict[str, Any]:
    """A copy of the configured ``from_env`` keywords of controller ``name`` (``"pid"``, ``"scmpc"``): a
    residual agent's base or a warm start's demonstrator."""
    return dict(config["residual_base_kwargs"].get(name) or {})


def save_config(config: dict[str, Any], path: str | Path) -> None:
    Path(path).write_text(yaml.safe_dump(config, sort_keys=False))
