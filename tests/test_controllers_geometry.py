"""Controllers among bodies: SC-MPC predicts the suction along its path, and compensates at a facade and a pier."""

import gymnasium as gym
import numpy as np

import wall_env  # noqa: F401
from controllers import MPC, PID, SCMPC
from controllers.evaluation import evaluate_batched
from controllers.mpc.manifold import PointIndex
from controllers.mpc.step import StepInput, StepOutput
from wall_env.aero import rotor_suction_function

SWEEP = "controllers/presets/tuned/wall_sweep_{}.yaml"  # presets of another task: these tests tune nothing


def test_scmpc_predicts_the_suction_it_meets_a_tenth_of_a_second_ahead_past_a_window():
    env = gym.make("WallInspector/Facade-v0", duration=9.0, noise=False)
    policy = SCMPC.from_env(env, preset=SWEEP.format("scmpc"), dt=0.01)  # stage k is k control steps ahead
    problem, ahead = policy.problem, 10
    N = problem.horizon
    suction = rotor_suction_function(policy.model, policy.model_vehicle.rotor_positions_array,
                                     problem.scene_structure)
    planes, theta = problem.scene.to_vector()[: problem.plane_size], policy.model.theta()
    observation, _ = env.reset(seed=0)
    predicted, met = [], []
    for _ in range(850):  # along the facade past the first window (its jambs at y = -1.65 and -0.75 m)
        action, _ = policy.predict(observation)
        block = policy.step.outputs[StepOutput.Z][0].reshape(N, -1)[ahead - 1]  # (u, x) of x_10
        surfaces = policy.step.inputs[StepInput.surfaces][0].reshape(N + 1, -1)[ahead]  # what stage 10 reads
        R = block[PointIndex.R_body_to_world].reshape(3, 3).T
        force = suction(block[PointIndex.p_world], R, block[PointIndex.v_world], np.zeros(3),
                        np.full(4, block[0] / 4), policy.model_vehicle.mass, theta, np.r_[planes, surfaces])
        predicted.append(np.asarray(force).sum(axis=1))
        observation, _, _, _, info = env.step(action)
        met.append(info["suction_force_world"])
    predicted, met = np.array(predicted), np.array(met)
    assert info["collisions"] == 0
    assert np.ptp(met[:, 0]) > 0.3  # the pull drops by more than 0.3 N over the recess and comes back
    error = np.sqrt(np.mean(np.sum((predicted[:-ahead] - met[ahead:]) ** 2, axis=1)))
    persistence = np.sqrt(np.mean(np.sum((met[:-ahead] - met[ahead:]) ** 2, axis=1)))
    assert error < 0.15 * persistence and error < 0.005  # N (measured 1.3 mN against 30 mN)


def test_the_nominal_mpc_asks_pybullet_nothing_and_scmpc_has_its_own_query():
    env = gym.make("WallInspector/Pier-v0")
    assert MPC.from_env(env, preset=SWEEP.format("mpc")).surfaces is None
    assert SCMPC.from_env(env, preset=SWEEP.format("scmpc")).surfaces is not None


def test_scmpc_holds_the_pier_tighter_than_mpc_and_pid_flies_it_too():
    kwargs = {"terminate_on_collision": False, "duration": 6.0}
    results = {name: evaluate_batched(make, "WallInspector/Pier-v0", seeds=[40, 41], env_kwargs=kwargs).metrics()
               for name, make in (("pid", lambda e: PID.from_env(e, preset=SWEEP.format("pid"))),
                                  ("mpc", lambda e: MPC.from_env(e, preset=SWEEP.format("mpc"))),
                                  ("scmpc", lambda e: SCMPC.from_env(e, preset=SWEEP.format("scmpc"))))}
    assert results["scmpc"]["collisions"] == 0 and results["mpc"]["collisions"] == 0
    assert results["scmpc"]["wall_normal_rmse"] < 0.5 * results["mpc"]["wall_normal_rmse"]
    assert results["pid"]["steps"] == 1200 and np.isfinite(results["pid"]["wall_normal_rmse"])


def test_a_controller_for_a_scene_with_bodies_is_not_exported_and_says_why(tmp_path):
    import pytest

    from controllers.export import export_controller

    env = gym.make("WallInspector/Pier-v0")
    with pytest.raises(ValueError, match="scene with bodies .* cannot be exported"):
        export_controller(SCMPC.from_env(env, preset=SWEEP.format("scmpc")), tmp_path / "out")
    assert not (tmp_path / "out").exists()
