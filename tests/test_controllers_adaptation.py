"""The adaptive SC-MPC: it finds a wall's k_s and d_thr and a push in flight, and flies as SC-MPC told the truth."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import MPC, SCMPC
from controllers.adaptation import ESTIMATED, AdaptationSettings
from controllers.evaluation import evaluate, evaluate_batched

SWEEP = "WallInspector/WallSweep-v0"


def _fly(policy_factory, seeds, **kwargs):
    holder = {}

    def make(envs):
        holder["policy"] = policy_factory(envs)
        return holder["policy"]

    env_kwargs = {"noise": True, "terminate_on_collision": False, **kwargs}
    return evaluate_batched(make, SWEEP, seeds, env_kwargs).metrics(), holder["policy"]


def test_it_learns_a_stronger_wall_than_told_and_flies_as_if_told_the_truth():
    # the first 9 s of the sweep come to within 5.6 cm of the wall and back; the wall pulls from 16 cm at 12 N/m
    world = {"k_s": 12.0, "d_thr": 0.16, "duration": 9.0}
    adaptive, policy = _fly(lambda e: SCMPC.from_env(e, k_s=4.1, d_thr=0.132, adapt=True), [11, 12], **world)
    told, _ = _fly(lambda e: SCMPC.from_env(e, k_s=12.0, d_thr=0.16), [11, 12], **world)
    nominal, _ = _fly(lambda e: SCMPC.from_env(e, k_s=4.1, d_thr=0.132), [11, 12], **world)
    estimates = policy.estimates
    assert estimates["k_s"] == pytest.approx([12.0, 12.0], rel=0.05)
    assert estimates["d_thr"] == pytest.approx([0.16, 0.16], abs=0.004)
    assert np.abs(np.column_stack([estimates[f"F_{a}"] for a in "xyz"])).max() < 0.05  # no residual invented
    assert adaptive["collisions"] == 0 and nominal["collisions"] > 0  # told the nominal model alone, it hits the wall
    assert adaptive["wall_normal_rmse"] <= 1.2 * told["wall_normal_rmse"] + 2e-4
    history = np.array(policy.estimate_history)  # (steps, rows, 5)
    assert history.shape == (900, 2, len(ESTIMATED))
    assert np.all(np.abs(np.diff(history[:, :, 0], axis=0)) <= 20.0 * 0.01 + 1e-9)  # k_s moves at most 20 N/m/s


def test_a_push_toward_the_wall_becomes_the_residual_force_and_nothing_else_moves():
    push = {"effects": {"constant_force": {"F": [-0.6, 0.2, 0.0]}}, "duration": 4.0}
    metrics, policy = _fly(lambda e: SCMPC.from_env(e, adapt=True), [3], **push)
    estimates = policy.estimates
    assert [estimates["F_x"][0], estimates["F_y"][0]] == pytest.approx([-0.6, 0.2], abs=0.03)
    assert estimates["k_s"][0] == pytest.approx(4.1, abs=0.3) and estimates["d_thr"][0] == pytest.approx(0.132, abs=0.01)
    mpc, _ = _fly(lambda e: MPC.from_env(e), [3], **push)
    assert metrics["collisions"] == 0 and metrics["wall_normal_rmse"] < 0.5 * mpc["wall_normal_rmse"]


def test_in_the_told_world_it_keeps_the_told_model():
    metrics, policy = _fly(lambda e: SCMPC.from_env(e, adapt=True), [5], duration=5.0)
    told, _ = _fly(lambda e: SCMPC.from_env(e), [5], duration=5.0)
    assert policy.estimates["k_s"][0] == pytest.approx(4.1, rel=0.05)
    assert policy.estimates["d_thr"][0] == pytest.approx(0.132, abs=0.003)
    assert metrics["wall_normal_rmse"] == pytest.approx(told["wall_normal_rmse"], rel=0.1, abs=2e-4)


def test_bad_adaptation_settings_are_named():
    import gymnasium as gym

    import wall_env  # noqa: F401

    env = gym.make(SWEEP)
    with pytest.raises(ValueError, match="adapt settings take .*unknown \\['speed'\\]"):
        SCMPC.from_env(env, adapt={"speed": 1})
    with pytest.raises(ValueError, match=r"adaptation.window \(s\) must be in \(0, 1000\]"):
        SCMPC.from_env(env, adapt={"window": -1})
    with pytest.raises(ValueError, match="adaptation.threshold_grid must be"):
        AdaptationSettings(threshold_grid=(0.2, 0.1, 0.01))
    with pytest.raises(AttributeError, match="adapt=True"):
        _ = SCMPC.from_env(env).estimates


def test_batched_evaluation_equals_one_env_per_seed():
    kwargs = {"noise": True, "terminate_on_collision": False, "duration": 1.5, "conditions": "realistic"}
    seeds = [21, 22, 23]
    batched = evaluate_batched(lambda e: SCMPC.from_env(e, adapt=True), SWEEP, seeds, kwargs)
    single = evaluate(lambda e: SCMPC.from_env(e, adapt=True), SWEEP, seeds, kwargs)
    for a, b in zip(batched.episodes, single.episodes):
        np.testing.assert_allclose(a.p_world, b.p_world, rtol=0, atol=1e-9)
        np.testing.assert_allclose(a.action, b.action, rtol=0, atol=1e-6)
    assert batched.metrics()["wall_normal_rmse"] == pytest.approx(single.metrics()["wall_normal_rmse"], rel=1e-6)
