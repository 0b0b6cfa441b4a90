"""Evaluation of policies, SB3's evaluate_policy on vector envs, the paper-table runner and the CLI commands."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

import wall_env  # noqa: F401
from controllers import MPC, PID, SCMPC
from controllers import paper_tables as pt
from controllers.evaluation import evaluate, solve_time_stats
from wall_inspector.cli import main as cli_main

SHORT_HOVER = {"duration": 1.0, "k_s": 0.0, "standoff": 2.0}


class HoverOnly:
    """A minimal SB3-style predictor that always commands hover thrust and zero rates."""

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(observation)
        return np.zeros(obs.shape[:-1] + (4,), dtype=np.float32), state


# ====================================================================== SB3 compatibility
@pytest.mark.parametrize("policy_class", [PID, MPC, SCMPC])
def test_evaluate_policy_runs_each_controller_on_a_two_env_vector_env(policy_class):
    # a 0.3 m circle far from the wall: following it needs real control (hover-only scores 68-127)
    vec_env = make_vec_env("WallInspector/WallCircle-v0", n_envs=2, seed=0, vec_env_cls=DummyVecEnv,
                           env_kwargs={"duration": 3.0, "k_s": 0.0, "standoff": 1.5, "noise": False})
    policy = policy_class.from_env(vec_env)
    rewards, lengths = evaluate_policy(policy, vec_env, n_eval_episodes=4, return_episode_rewards=True, warn=False)
    vec_env.close()
    assert lengths == [300, 300, 300, 300]  # nobody strayed or crashed
    assert min(rewards) > 0.93 * 300  # reward 1 per step on the reference, less 2 per metre of error
    assert policy.failures == 0


def test_evaluate_policy_with_a_subprocess_vector_env():
    vec_env = make_vec_env("WallInspector/WallHover-v0", n_envs=2, seed=1, vec_env_cls=SubprocVecEnv,
                           vec_env_kwargs={"start_method": "fork"}, env_kwargs=SHORT_HOVER)
    policy = SCMPC.from_env(vec_env)  # the description crosses the process boundary (get_attr)
    mean_reward, _ = evaluate_policy(policy, vec_env, n_eval_episodes=2, warn=False)
    vec_env.close()
    assert mean_reward > 80.0
    assert len(policy.solve_times) >= 200


# ====================================================================== evaluate()
def test_evaluate_records_metrics_that_match_the_steps():
    # the authors' PID gains: pulled onto the wall at k_s = 10 N/m, so contacts are recorded too
    result = evaluate(lambda env: PID.from_env(env, preset="paper"), "WallInspector/WallCircle-v0", [0, 1],
                      {"k_s": 10.0, "d_thr": 0.1, "terminate_on_collision": False, "duration": 3.0})
    m = result.metrics()
    assert m["episodes"] == 2 and m["steps"] == 600
    episode = result.episodes[0]
    # one wall, normal +x: the wall-normal error is the x error
    np.testing.assert_allclose(episode.wall_normal_error, episode.error[:, 0])
    all_x = np.concatenate([e.error[:, 0] for e in result.episodes])
    assert m["wall_normal_rmse"] == pytest.approx(np.sqrt(np.mean(all_x**2)))
    assert m["rmse"][0] == pytest.approx(m["wall_normal_rmse"])
    assert m["collisions"] == sum(int(e.collision.sum()) for e in result.episodes) > 0
    assert m["collision_episodes"] == 2
    # contacts are resolved within the step, so the recorded clearance is just above zero
    assert m["min_wall_clearance"] == min(e.wall_clearance.min() for e in result.episodes) < 2e-3
    # effort is measured on the noise-free command: thrust minus m g, rates
    assert m["thrust_effort_rms"] > 0 and m["body_rate_effort_rms"] > 0
    assert "solve_ms" not in m  # the PID does not solve anything
    per = result.per_episode()
    assert [p["seed"] for p in per] == [0, 1]


def test_same_seed_same_flight_and_every_policy_meets_the_same_start():
    first = evaluate(PID.from_env, "WallInspector/WallSweep-v0", [7], {"duration": 1.0})
    again = evaluate(PID.from_env, "WallInspector/WallSweep-v0", [7], {"duration": 1.0})
    np.testing.assert_array_equal(first.episodes[0].p_world, again.episodes[0].p_world)
    hover = evaluate(HoverOnly(), "WallInspector/WallSweep-v0", [7], {"duration": 1.0})
    # the same perturbed start: the first step moves both from the same state for 10 ms
    assert np.linalg.norm(hover.episodes[0].p_world[0] - first.episodes[0].p_world[0]) < 2e-3
    assert hover.policy == "HoverOnly" and first.policy == "PID"


def test_evaluate_reports_mpc_solve_times():
    m = evaluate(MPC.from_env, "WallInspector/WallHover-v0", [0], SHORT_HOVER).metrics()
    assert m["solve_ms"]["count"] == 100
    assert 0.0 < m["solve_ms"]["median"] < 50.0


def test_evaluate_rejects_bad_arguments():
    with pytest.raises(ValueError, match="seeds"):
        evaluate(HoverOnly(), "WallInspector/WallHover-v0", [])
    with pytest.raises(ValueError, match="policy"):
        evaluate(42, "WallInspector/WallHover-v0", [0])
    with pytest.raises(ValueError, match="env_kwargs"):
        evaluate(HoverOnly(), lambda: gym.make("WallInspector/WallHover-v0"), [0], {"k_s": 1.0})


def test_solve_time_stats_percentiles():
    stats = solve_time_stats(np.arange(1, 1001) * 1e-6)  # 1 .. 1000 microseconds
    assert stats["median"] == pytest.approx(0.5005)
    assert stats["max"] == pytest.approx(1.0)
    assert stats["p99_8"] == pytest.approx(0.998002, rel=1e-4)
    assert stats["count"] == 1000


# ====================================================================== paper tables
def test_runner_tables_json_and_figures(tmp_path):
    short = {"duration": 1.5}
    scenarios = [pt.Scenario("I", "WallInspector/WallCircle-v0", 10.0, 0.10, (0,), short),
                 pt.Scenario("II", "WallInspector/WallSweep-v0", 4.1, 0.132, (0, 1), short)]
    seen = []

    def two_argument_factory(env, scenario):
        seen.append(scenario.k_s)
        return HoverOnly()

    policies = {**pt.controller_policies("paper", dynamics_only=False), "hover": two_argument_factory,
                "hover1": lambda env: HoverOnly()}
    results = pt.run_scenarios(scenarios, policies, progress=False)
    assert len(results) == 10 and seen == [10.0, 4.1]
    sc = next(r for r in results if r.policy == "SC-MPC" and r.scenario.table == "II")
    assert sc.evaluation.env_kwargs["terminate_on_collision"] is False
    assert sc.evaluation.env_kwargs["k_s"] == 4.1 and sc.evaluation.seeds == [0, 1]
    assert all(len(e.time) == 150 for r in results for e in r.evaluation.episodes)  # no early ends
    text = pt.markdown_tables(results)
    assert "**Table I**" in text and "**Table II**" in text and "| SC-MPC | 10 |" in text
    checks = {c["check"]: c for c in pt.acceptance(results)}
    assert len(checks) == 5
    ratio = checks["Table II: SC-MPC / MPC wall-normal RMSE <= 0.4"]["value"]
    assert ratio == pytest.approx(sc.metrics()["wall_normal_rmse"] /
                                  next(r for r in results if r.policy == "MPC" and r.scenario.table == "II")
                                  .metrics()["wall_normal_rmse"])
    paths = pt.write_outputs(results, tmp_path)
    assert paths["table_i_figure"].stat().st_size > 10_000 and paths["table_ii_figure"].stat().st_size > 10_000
    data = json.loads(paths["json"].read_text())
    assert len(data["runs"]) == 10 and len(data["runs"][0]["per_episode"]) == 1


def test_paper_scenarios_are_the_papers():
    assert [(s.env_id, s.k_s, s.d_thr, len(s.seeds), s.env_kwargs) for s in pt.TABLE_I] == [
        ("WallInspector/WallCircle-v0", k, 0.10, 5, {"standoff": 0.15}) for k in (1.0, 4.0, 10.0)]
    # where Table I puts the vehicle: near rotors 2.07 cm inside d_thr, ducts 3.93 cm off the wall
    assert ("stand-off 0.15 m: near rotors 7.93 cm from the wall (2.07 cm inside d_thr), ducts 3.93 cm off it"
            in pt._table_i_geometry(pt.TABLE_I[0]))
    assert [(s.env_id, s.k_s, s.d_thr, len(s.seeds)) for s in pt.TABLE_II] == [
        ("WallInspector/WallSweep-v0", 4.1, 0.132, 10)]
    kwargs = pt.TABLE_II[0].make_kwargs()
    assert kwargs["noise"] is True and kwargs["terminate_on_collision"] is False
    assert "standoff" not in kwargs  # the task's own geometry


def test_compare_command_writes_its_outputs(tmp_path, capsys):
    code = cli_main(["compare", "--out", str(tmp_path), "--seeds-i", "1", "--seeds-ii", "1", "--seeds-structures", "1",
                     "--duration", "0.3", "--no-progress"])
    assert code == 0
    out = capsys.readouterr().out
    assert "Acceptance checks" in out and "**Table II**" in out and out.startswith("**Tuned presets**")
    assert "**Structures**" in out
    # tuned rows, the paper's SC-MPC form and the authors' settings as extra rows, PPO's budget beside theirs
    for row in ("| SC-MPC (dynamics only) |", "| MPC (authors') |", "| PID (authors') |", "| WallSweep | PPO |",
                "| Facade | SC-MPC |", "| Pier | MPC (authors') |"):
        assert row in out
    data = json.loads((tmp_path / "results.json").read_text())
    checks = data["acceptance"]
    assert checks[-1]["check"].startswith("Table II: PPO")
    assert any(c["check"] == "Table II: MPC / MPC (authors') wall-normal RMSE <= 1" for c in checks)
    assert {"Facade: SC-MPC has no collision", "Pier: SC-MPC / MPC wall-normal RMSE <= 0.5"} <= {
        c["check"] for c in checks}
    assert {r["method"] for r in data["budgets"]} == {"PID", "MPC", "SC-MPC", "PPO"}
    assert sum(line.startswith("- ") for line in (tmp_path / "tables.md").read_text().splitlines()) == len(checks) == 12
    assert {p.name for p in tmp_path.iterdir()} == {"tables.md", "results.json", "timing.json", "table_i_circle.png",
                                                   "table_ii_sweep.png", "structures.png"}


@pytest.mark.parametrize("args, message", [
    (["--seeds-ii", "0"], "--seeds-ii must be in"),
    (["--mpc-sigma", "stiffness=3"], "mpc-sigma"),
    (["--mpc-sigma", "position=-1"], "weights.position"),
    (["--weights", "tunde"], "preset must be one of"),
])
def test_bad_compare_arguments_are_one_line_and_exit_2(tmp_path, capsys, args, message):
    assert cli_main(["compare", "--out", str(tmp_path / "x"), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "x").exists()


def test_compare_with_other_mpc_sigmas_says_so(tmp_path, capsys):
    code = cli_main(["compare", "--out", str(tmp_path), "--tables", "II", "--seeds-ii", "1", "--duration", "0.2",
                     "--no-progress", "--no-ppo", "--no-authors", "--mpc-sigma", "position=0.07/0.07/0.093",
                     "--mpc-sigma", "terminal_position=0.02"])
    assert code == 0
    text = (tmp_path / "tables.md").read_text()
    assert "**Not the preset's MPC weights**" in text and "position = (0.07, 0.07, 0.093)" in text
    assert "terminal_position = 0.02" in capsys.readouterr().out


def test_compare_with_paper_sim_checks_the_paper_s_table_i(tmp_path):
    code = cli_main(["compare", "--out", str(tmp_path), "--tables", "I", "--seeds-i", "1", "--duration", "0.2",
                     "--no-progress", "--no-ppo", "--weights", "paper-sim"])
    assert code == 0
    text = (tmp_path / "tables.md").read_text()
    assert text.startswith("**Preset `paper-sim`**")
    checks = [c["check"] for c in json.loads((tmp_path / "results.json").read_text())["acceptance"]]
    assert "Table I: MPC at k_s=4 within a factor 1.5 of the paper's 0.98 cm (ratio)" in checks
    assert "Table I: SC-MPC below MPC at every k_s (largest SC-MPC / MPC)" in checks
    assert "Table I: MPC's RMSE grows with k_s (smallest step ratio)" in checks


def test_bench_mpc_command_reports_and_checks(tmp_path, capsys):
    path = tmp_path / "bench.json"
    table = tmp_path / "bench.md"
    code = cli_main(["bench-mpc", "--steps", "60", "--no-pin", "--batch", "3", "--batched-steps", "5",
                     "--json", str(path), "--markdown", str(table)])
    assert code == 1  # fewer than 2000 steps can never pass
    figures = json.loads(path.read_text())
    assert figures["steps"] == 60 and figures["lm_solve_ms"]["count"] == 60
    assert figures["single"]["predict_cpu_ms"]["count"] == 60
    assert figures["batched"]["vehicles"] == 3 and figures["batched"]["predict_cpu_ms"]["count"] == 5
    assert "predict CPU per vehicle, batched N=3: p99.8 <= 1.0 ms" in figures["targets"]
    assert figures["ipopt_solve_ms"]["count"] == 60
    assert figures["cost_gap"]["share_within_1pct"] == 1.0
    assert figures["targets"]["steps >= 2000"] is False
    assert "IPOPT / LM median time" in capsys.readouterr().out
    text = table.read_text()
    assert "| SC-MPC, compiled step with Levenberg-Marquardt (wall clock) |" in text
    assert "whole `predict` on 3 envs, per vehicle (CPU time)" in text and "same problems, CasADi + IPOPT" in text
    assert f"{figures['lm_solve_ms']['median']:.3f}" in text
