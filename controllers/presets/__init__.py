"""Controller presets: the gains of the PID and the weights, horizon and compensation of the MPCs, as YAML files.

A preset is a YAML mapping in this folder (or any file a user writes in the same
form) with a ``name``, a one-line ``description``, a ``provenance`` (where the
numbers come from: the task and seeds they were tuned on, the budget, the objective
value, the command and the commit) and one section per method it sets:

.. code-block:: yaml

    name: paper
    description: the authors' released gains and sigmas
    provenance: {source: ...}
    pid: {kp: [8, 8, 10], kv: [4, 4, 6], k_attitude: [6, 6, 4]}
    mpc: {horizon: 20, dt: 0.01, weights: {position: [0.15, 0.15, 0.2], ...}}
    scmpc: {horizon: 20, dt: 0.01, compensation: dynamics+attitude, weights: {...}}

Named presets:

``paper``
    the authors' released PID gains and MPC sigmas (a soft loop in this simulator:
    about 2.8 N/m per kg of lateral stiffness, :mod:`controllers.stiffness`);
``paper-sim``
    the MPC sigmas with which this simulator reproduces the paper's Table I (the
    file's comment gives the reasoning and the figures);
``tuned``
    for each task and method, the result of ``wall-inspector tune`` with the same
    budget for every method: ``tuned/<task>_<method>.yaml`` (for example
    ``tuned/wall_sweep_scmpc.yaml``). ``PID.from_env``, ``MPC.from_env`` and
    ``SCMPC.from_env`` use the tuned preset of the env's task unless told otherwise.

Methods are ``pid``, ``mpc`` and ``scmpc``. :func:`load_preset` reads a preset by
name or path and checks every key; :meth:`ControllerPreset.controller_kwargs` gives
the constructor keywords of one method.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from wall_env.tasks import task_slug
from wall_env.validation import read_mapping

__all__ = ["ControllerPreset", "load_preset", "preset_names", "tuned_preset_path", "PRESET_DIR", "METHODS",
           "METHOD_LABELS"]

PRESET_DIR = Path(__file__).resolve().parent
METHODS = ("pid", "mpc", "scmpc")
METHOD_LABELS = {"pid": "PID", "mpc": "MPC", "scmpc": "SC-MPC"}
NAMED = ("paper", "paper-sim", "tuned")

_PID_KEYS = {"kp", "kv", "k_attitude", "position_error_limit", "velocity_error_limit", "max_tilt_deg"}
_MPC_KEYS = {"horizon", "dt", "weights", "max_tilt_deg"}
_SCMPC_KEYS = _MPC_KEYS | {"compensation"}
_TOP_KEYS = {"name", "description", "provenance", *METHODS}


@dataclass(frozen=True)
class ControllerPreset:
    """One preset: its name, description, provenance and the settings of each method it holds."""

    name: str
    description: str
    provenance: dict[str, Any] = field(default_factory=dict)
    methods: dict[str, dict[str, Any]] = field(default_factory=dict)
    path: Path | None = None

    @classmethod
    def from_dict(cls, data: dict[str, Any], path: Path | None = None) -> ControllerPreset:
        where = f"preset {path}" if path is not None else "preset"
        unknown = sorted(set(data) - _TOP_KEYS)
        if unknown:
            raise ValueError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(_TOP_KEYS)}")
        methods = {m: dict(data[m]) for m in METHODS if data.get(m) is not None}
        for method, settings in methods.items():
            allowed = {"pid": _PID_KEYS, "mpc": _MPC_KEYS, "scmpc": _SCMPC_KEYS}[method]
            unknown = sorted(set(settings) - allowed)
            if unknown:
                raise ValueError(f"{where}: unknown key(s) {unknown} in '{method}'; allowed: {sorted(allowed)}")
        if not methods:
            raise ValueError(f"{where} sets no method; give at least one of {list(METHODS)}")
        preset = cls(str(data.get("name", path.stem if path else "preset")), str(data.get("description", "")),
                     dict(data.get("provenance") or {}), methods, path)
        for method in methods:  # build once so that a bad value fails at load time, naming the key
            try:
                preset.controller_kwargs(method)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{where}, '{method}': {exc}") from None
        return preset

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "description": self.description, "provenance": self.provenance, **self.methods}

    def controller_kwargs(self, method: str) -> dict[str, Any]:
        """Keywords for the constructor of ``method`` (``PID``, ``MPC`` or ``SCMPC``)."""
        if method not in self.methods:
            raise ValueError(f"preset {self.name!r} has no settings for {method!r}; it has {sorted(self.methods)}")
        settings = dict(self.methods[method])
        if method == "pid":
            return settings
        from controllers.mpc.cost import MPCWeights

        weights = settings.pop("weights", None) or {}
        if not isinstance(weights, dict):
            raise ValueError(f"weights must be a mapping of sigma names to values, got {weights!r}")
        names = {f.name for f in dataclasses.fields(MPCWeights)}
        unknown = sorted(set(weights) - names)
        if unknown:
            raise ValueError(f"unknown weights key(s) {unknown}; allowed: {sorted(names)}")
        settings["weights"] = MPCWeights(**{k: tuple(v) if isinstance(v, list) else v for k, v in weights.items()})
        if "horizon" in settings:
            horizon = settings["horizon"]
            if isinstance(horizon, bool) or not isinstance(horizon, int):
                raise ValueError(f"horizon must be an integer, got {horizon!r}")
        return settings

    def save(self, path: str | Path, comment: str = "") -> Path:
        """Write the preset as YAML (``comment`` lines first, each prefixed with ``#``)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        header = "".join(f"# {line}".rstrip() + "\n" for line in comment.splitlines()) if comment else ""
        path.write_text(header + yaml.dump(_plain(self.to_dict()), Dumper=_PresetDumper, sort_keys=False, width=100))
        return path


class _PresetDumper(yaml.SafeDumper):
    """YAML with lists of numbers on one line (``[0.15, 0.15, 0.2]``)."""


def _represent_list(dumper, data):
    flow = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_PresetDumper.add_representer(list, _represent_list)


def _plain(value: Any) -> Any:
    """Tuples to lists and NumPy scalars to Python numbers, for YAML."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item") and callable(value.item):
        return value.item()
    return value


def tuned_preset_path(task: str, method: str) -> Path:
    """Where the tuned preset of ``method`` on ``task`` is shipped: ``tuned/<task_slug>_<method>.yaml``."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {list(METHODS)}, got {method!r}")
    return PRESET_DIR / "tuned" / f"{task_slug(task)}_{method}.yaml"


def preset_names() -> list[str]:
    """The named presets (``paper``, ``paper-sim``, ``tuned``)."""
    return list(NAMED)


def load_preset(preset: str | Path | ControllerPreset, method: str | None = None,
                task: str | None = None) -> ControllerPreset:
    """A preset by name (``"paper"``, ``"paper-sim"``, ``"tuned"``) or by file path.

    ``"tuned"`` needs the ``task`` and the ``method``. With ``method`` given, a preset
    that has no settings for it raises ``ValueError``.
    """
    if isinstance(preset, ControllerPreset):
        loaded = preset
    else:
        text = str(preset)
        if text == "tuned":
            if method is None or task is None:
                raise ValueError("the 'tuned' preset depends on the task and method; this env names no task "
                                 "(pass preset='paper', a preset file, or preset=None)")
            path = tuned_preset_path(task, method)
            if not path.is_file():
                raise ValueError(f"no tuned preset of {method} for {task} ({path}); make one with "
                                 f"`wall-inspector tune --env {task} --method {method}` or pass preset='paper'")
        elif text in NAMED:
            path = PRESET_DIR / f"{text}.yaml"
        else:
            path = Path(text)
            if path.suffix.lower() not in (".yaml", ".yml", ".json"):
                raise ValueError(f"preset must be one of {list(NAMED)} or a .yaml/.json file, got {text!r}")
            if not path.is_file():
                raise ValueError(f"preset file {path} does not exist")
        loaded = ControllerPreset.from_dict(read_mapping(path, "preset file"), path)
    if method is not None and method not in loaded.methods:
        raise ValueError(f"preset {loaded.name!r} has no settings for {method!r}; it has {sorted(loaded.methods)}")
    return loaded
