"""--algo dagger: a controller distilled into the network, DAgger-style, and reported as an agent of its own."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import VecNormalize

from agents import load_policy
from agents.batched_vec_env import BatchedVecEnv
from agents.config import default_config, validate_config
from agents.demonstrations import record_demonstrations
from agents.distillation import distil
from agents.learner import make_ppo as _make_ppo
from agents.residual import make_base_controller
from controllers.threads import limit_threads
from wall_inspector.cli import main

HOVER = "WallInspector/WallHover-v0"


def _config(**teacher):
    config = default_config("WallHover")
    config.update(algo="dagger", seed=1)
    config["teacher"].update(controller="pid", envs=4, steps=120, iterations=2, epochs=40, batch_size=128, **teacher)
    return validate_config(config)


def test_the_expert_labels_the_states_the_pilot_flies_into():
    venv = BatchedVecEnv(HOVER, 3)
    try:
        expert = make_base_controller("pid", venv, preset="tuned")
        pilot_action = np.array([0.3, 0.0, 0.2, 0.0], dtype=np.float32)  # climbs and pitches: the PID would not
        demos = record_demonstrations(venv, expert, 40, seed=5, pilot=lambda obs: np.tile(pilot_action, (len(obs), 1)))
    finally:
        venv.close()
    np.testing.assert_array_equal(demos.applied, np.broadcast_to(pilot_action, demos.applied.shape))
    # the labels are the PID's answers on those states, pulling the drifting vehicle back
    assert np.abs(demos.actions - pilot_action).max() > 0.2
    # and the flown action is what the next observation reports as the previous one (but after a reset)
    going_on = ~demos.dones[:-1]
    np.testing.assert_allclose(demos.observations[1:, :, 43:47][going_on], demos.applied[:-1][going_on], atol=1e-6)
    joined = demos.join(demos)
    assert joined.observations.shape == (40, 6, 48) and joined.noise.shape == (6,)


def test_distillation_makes_the_network_act_like_its_teacher_on_flights_it_never_saw(tmp_path):
    torch.manual_seed(0)
    config = _config()
    venv = VecNormalize(BatchedVecEnv(HOVER, 2, **config["env_kwargs"]))
    model = _make_ppo(config, venv, tb_dir=tmp_path / "tb", verbose=0)
    check = BatchedVecEnv(HOVER, 4, **config["env_kwargs"])
    try:
        teacher = make_base_controller("pid", check, preset="tuned")
        fresh = record_demonstrations(check, teacher, 120, seed=777)  # seeds the distillation never flew

        def error() -> float:
            obs, actions = fresh.flat()
            predicted, _ = model.predict(venv.normalize_obs(obs), deterministic=True)
            return float(np.sqrt(np.mean((np.clip(predicted, -1, 1) - actions) ** 2)))

        with limit_threads(1):  # as train() runs it: on the threads the rule gives (the machine may be busy)
            before = error()
            report = distil(config, model, venv, verbose=0)
            after = error()
    finally:
        check.close()
        venv.close()
    assert [it["pilot"] for it in report["iterations"]] == ["pid", "student"]
    assert report["labels"] == 2 * 4 * 120 and report["iterations"][1]["student_return"] is not None
    # iteration i flies seeds of its own: teacher.seed + (run seed * iterations + i) * envs + k
    assert report["iterations"][0]["seeds"] == [2_000_000 + 8, 2_000_000 + 11]
    assert report["iterations"][1]["seeds"] == [2_000_000 + 12, 2_000_000 + 15]
    assert after < 0.6 * before, (before, after)  # half the zero policy's error after 640 gradient steps


def test_dagger_settings_are_checked():
    config = default_config("WallHover")
    config["algo"] = "sac"
    with pytest.raises(ValueError, match=r"algo must be one of \('ppo', 'dagger'\), got 'sac'"):
        validate_config(config)
    config = _config()
    config["teacher"]["iterations"] = 0
    with pytest.raises(ValueError, match="teacher.iterations must be a positive integer, got 0"):
        validate_config(config)
    config = _config()
    config["residual"] = "pid"
    with pytest.raises(ValueError, match="algo dagger distils its teacher"):
        validate_config(config)


def test_train_algo_dagger_writes_a_distilled_agent_of_its_own(tmp_path, monkeypatch, capsys):
    import agents.policy

    monkeypatch.setattr(agents.policy, "PRETRAINED_DIR", tmp_path / "pretrained")
    out = tmp_path / "distilled"
    code = main(["train", "--env", HOVER, "--algo", "dagger", "--seed", "1", "--out", str(out), "--no-progress", "--quiet",
                 "--set", "teacher.controller=pid", "--set", "teacher.envs=4", "--set", "teacher.steps=120",
                 "--set", "teacher.epochs=4", "--set", "teacher.iterations=3", "--set", "card_eval.episodes=1",
                 "--eval-episodes", "1"])
    assert code == 0
    card = json.loads((out / "model_card.json").read_text())
    teacher = card["training"]["teacher"]
    assert card["training"]["total_timesteps"] == 0 and teacher["labels"] == 3 * 4 * 120  # three iterations
    # every iteration was judged on the evaluation envs and the best one kept: best/ holds it
    judged = [it["judged"] for it in teacher["iterations"]]
    assert teacher["kept_iteration"] == int(np.argmax(judged))
    assert json.loads((out / "best" / "policy.json").read_text())["eval_mean_return"] == pytest.approx(max(judged), abs=0.006)
    assert card["training"]["time_split"] is None  # no PPO steps to split
    assert card["summary"].startswith("PID distilled DAgger-style") and "not alone" in card["summary"]
    assert "--algo dagger" in card["command"]
    info = json.loads((out / "best" / "policy.json").read_text())
    assert info["algorithm"] == "DAgger (teacher: pid)"
    policy = load_policy(out / "best")
    obs = np.asarray(info["check"]["observations"], dtype=np.float32)
    np.testing.assert_allclose(policy.predict(obs)[0], np.asarray(info["check"]["actions"]), rtol=1e-5, atol=1e-6)
    # nothing to continue, and a distilled agent ships into a folder of its own, never as the task's agent
    capsys.readouterr()
    assert main(["train", "--resume", str(out), "--timesteps", "5000"]) == 2
    assert "holds a distilled agent (algo dagger)" in capsys.readouterr().err
    from agents.train import ship

    target = ship(out, HOVER, teacher="pid")
    assert target == tmp_path / "pretrained" / "wall_hover_teacher_pid"
