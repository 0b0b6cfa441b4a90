"""What a controller may know about an environment: its documented public description.

Controllers are built from an environment the way a Stable-Baselines3 agent is,
but they read only the attributes that :class:`wall_env.WallInspectorEnv`
documents for controllers: ``vehicle``, ``scene``, ``reference``,
``action_mapping``, ``nominal_model``, ``control_dt`` and ``task`` (its
:class:`~wall_env.tasks.TaskSpec`, whose name picks the controllers' tuned presets). The simulator's own
effect settings (its hidden suction parameters, noise, randomisation) are never
read; a controller that wants to know the suction gets it from its caller or a
model file.

:func:`describe_env` accepts a bare env, a wrapped env (``gym.make`` adds
wrappers), a Gymnasium vector env or a Stable-Baselines3 ``VecEnv``; for vector
envs the description of the first sub-env is used (all sub-envs of one vector env
run the same task).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from wall_env.actions import ActionMapping
from wall_env.aero import AeroModel
from wall_env.references import Reference
from wall_env.scene import Scene
from wall_env.vehicle import VehicleParams

__all__ = ["EnvDescription", "describe_env", "read_scene_and_reference", "PUBLIC_ATTRIBUTES"]

PUBLIC_ATTRIBUTES = ("vehicle", "scene", "reference", "action_mapping", "nominal_model", "control_dt", "task")


@dataclass(frozen=True)
class EnvDescription:
    """The public description of a Wall Inspector environment (all SI)."""

    vehicle: VehicleParams
    scene: Scene
    reference: Reference
    action_mapping: ActionMapping
    nominal_model: AeroModel
    control_dt: float  # s
    task: str  # task name, e.g. "WallSweep"


def _read_attribute(env: Any, name: str) -> Any:
    # SB3 VecEnv and Gymnasium vector envs: one value per sub-env
    if hasattr(env, "num_envs") and hasattr(env, "get_attr"):
        values = env.get_attr(name)
        return values[0]
    if hasattr(env, "get_wrapper_attr"):
        try:
            return env.get_wrapper_attr(name)
        except AttributeError:
            pass
    unwrapped = getattr(env, "unwrapped", env)
    if hasattr(unwrapped, name):
        return getattr(unwrapped, name)
    raise AttributeError(name)


def describe_env(env: Any) -> EnvDescription:
    """Read the public description from ``env`` (plain, wrapped or vectorised).

    Raises ``ValueError`` naming the missing attributes if ``env`` is not a Wall
    Inspector environment.
    """
    values: dict[str, Any] = {}
    missing = []
    for name in PUBLIC_ATTRIBUTES:
        try:
            values[name] = _read_attribute(env, name)
        except AttributeError:
            missing.append(name)
    if missing:
        raise ValueError(
            f"env must be a Wall Inspector environment (or a wrapper / vector env of one) exposing "
            f"{list(PUBLIC_ATTRIBUTES)}; {type(env).__name__} lacks {missing}"
        )
    values["control_dt"] = float(values["control_dt"])
    values["task"] = str(getattr(values["task"], "name", values["task"]))  # the env holds a TaskSpec
    return EnvDescription(**values)


def read_scene_and_reference(env: Any, index: int) -> tuple[Scene, Reference]:
    """The scene and reference of sub-env ``index`` of ``env`` now (after its latest reset).

    A randomised stand-off makes the env rebuild both at every reset; controllers
    read them again at each episode start through this function. The batched envs
    (:class:`wall_env.vector_env.WallInspectorVectorEnv`, SB3's ``BatchedVecEnv``) answer
    through their ``scene_and_reference(index)``.
    """
    rows = getattr(env, "scene_and_reference", None)
    if rows is None and hasattr(env, "unwrapped"):
        rows = getattr(env.unwrapped, "scene_and_reference", None)
    if callable(rows):
        return rows(index)
    if hasattr(env, "num_envs") and hasattr(env, "get_attr"):
        try:  # Stable-Baselines3 VecEnv: get_attr(name, indices)
            return env.get_attr("scene", indices=[index])[0], env.get_attr("reference", indices=[index])[0]
        except TypeError:  # Gymnasium vector env: get_attr(name) gives every sub-env's value
            return env.get_attr("scene")[index], env.get_attr("reference")[index]
    return _read_attribute(env, "scene"), _read_attribute(env, "reference")
