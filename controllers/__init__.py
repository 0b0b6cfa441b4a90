"""Controllers for flight near walls: cascaded PID, nominal MPC and SC-MPC, as Stable-Baselines3-style policies.

Build them from an environment the way an SB3 agent is built, then use them like one::

    import gymnasium as gym
    import wall_env
    from controllers import PID, MPC, SCMPC

    env = gym.make("WallInspector/WallSweep-v0")
    policy = SCMPC.from_env(env, k_s=4.1, d_thr=0.132)   # or SCMPC.from_env(env, model="model.json")
    obs, _ = env.reset(seed=0)
    action, _ = policy.predict(obs, episode_start=True)

They read only the env's public description (:mod:`controllers.env_description`);
``stable_baselines3.common.evaluation.evaluate_policy`` accepts them unchanged, and
:func:`controllers.evaluation.evaluate` measures tracking, wall-normal error,
collisions, effort and solve times of any policy.
"""

from controllers.mpc.policy import MPC, SCMPC
from controllers.pid import PID

__all__ = ["PID", "MPC", "SCMPC"]
