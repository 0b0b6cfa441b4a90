"""Wall Inspector environments: quadrotors near walls with the paper's wall-suction dynamics.

``import wall_env`` registers the tasks with Gymnasium under the ``WallInspector`` namespace::

    import gymnasium as gym
    import wall_env

    env = gym.make("WallInspector/WallSweep-v0", k_s=4.1, d_thr=0.132)
    envs = gym.make_vec("WallInspector/WallSweep-v0", num_envs=1024, vectorization_mode="vector_entry_point")

Each id is registered with a ``vector_entry_point``
(:class:`~wall_env.vector_env.WallInspectorVectorEnv`) and ``max_episode_steps`` =
:data:`~wall_env.config.MAX_EPISODE_STEPS`, the longest episode any settings allow. The
env itself ends each episode at its reference's end (``duration``, a keyword), so a
registered limit of the default length would cut short every flight given a longer
``duration``; stepping on after the end raises a ``RuntimeError`` that says to reset.
"""

from gymnasium.envs.registration import register, registry

from wall_env.actions import ActionMapping
from wall_env.aero import AeroModel
from wall_env.config import MAX_EPISODE_STEPS, EnvConfig
from wall_env.effects import EFFECTS, Effect, effects_from_spec, make_effect
from wall_env.model_file import FlightModel, nominal_aero_model
from wall_env.observation import OBSERVATION_FIELDS, parse_observation
from wall_env.references import Reference
from wall_env.scene import Scene, Wall
from wall_env.tasks import TASKS
from wall_env.vehicle import GRAVITY, VehicleParams

__all__ = [
    "ENV_IDS",
    "WallInspectorEnv",
    "WallInspectorVectorEnv",
    "EnvConfig",
    "VehicleParams",
    "Scene",
    "Wall",
    "AeroModel",
    "FlightModel",
    "ActionMapping",
    "Reference",
    "EFFECTS",
    "Effect",
    "make_effect",
    "effects_from_spec",
    "nominal_aero_model",
    "OBSERVATION_FIELDS",
    "parse_observation",
    "DEFAULT_REWARD_WEIGHTS",
    "GRAVITY",
    "TASKS",
]

ENV_IDS = tuple(f"WallInspector/{name}-v0" for name in TASKS)

for _name in TASKS:
    _id = f"WallInspector/{_name}-v0"
    if _id not in registry:
        register(id=_id, entry_point="wall_env.env:WallInspectorEnv",
                 vector_entry_point="wall_env.vector_env:WallInspectorVectorEnv", kwargs={"task": _name},
                 max_episode_steps=MAX_EPISODE_STEPS)


def __getattr__(name: str):
    # imported on first use: the vector env pulls in Gymnasium's vector module, the single env PyBullet and
    # SciPy's rotations (a quarter of a second that ``wall-inspector discover`` does not need)
    if name == "WallInspectorVectorEnv":
        from wall_env.vector_env import WallInspectorVectorEnv

        return WallInspectorVectorEnv
    if name in ("WallInspectorEnv", "DEFAULT_REWARD_WEIGHTS"):
        from wall_env import env

        return getattr(env, name)
    raise AttributeError(f"module 'wall_env' has no attribute {name!r}")
