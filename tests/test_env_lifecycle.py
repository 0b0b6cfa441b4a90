"""The single env's lifecycle and input checks: clear errors instead of crashes deep inside."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import wall_env
from wall_env.env import WallInspectorEnv


def test_registrations_declare_a_time_limit_and_a_vector_entry_point():
    for env_id in wall_env.ENV_IDS:
        spec = gym.spec(env_id)
        assert spec.max_episode_steps == wall_env.config.MAX_EPISODE_STEPS
        assert spec.vector_entry_point == "wall_env.vector_env:WallInspectorVectorEnv"


def test_step_before_reset_after_the_end_and_after_close_raise_clear_errors():
    env = WallInspectorEnv("WallHover", duration=0.05, noise=False, standoff=0.4)
    with pytest.raises(RuntimeError, match=r"step\(\) before reset\(\)"):
        env.step(np.zeros(4))
    env.reset(seed=0)
    for _ in range(5):
        _, _, terminated, truncated, _ = env.step(np.zeros(4))
    assert truncated and not terminated
    with pytest.raises(RuntimeError, match="after the episode ended"):
        env.step(np.zeros(4))
    env.reset()
    env.step(np.zeros(4))  # a new episode steps again
    env.close()
    with pytest.raises(RuntimeError, match=r"step\(\) after close\(\)"):
        env.step(np.zeros(4))
    with pytest.raises(RuntimeError, match=r"reset\(\) after close\(\)"):
        env.reset()
    env.close()  # closing twice is fine


def test_metadata_is_static_and_videos_play_at_the_control_rate():
    assert WallInspectorEnv.metadata == {"render_modes": ["human", "rgb_array"], "render_fps": 100}
    env = gym.make("WallInspector/WallHover-v0", control_dt=0.02)
    assert env.metadata["render_fps"] == pytest.approx(50.0)
    assert WallInspectorEnv.metadata["render_fps"] == 100  # the class's stays
    env.close()


def test_human_rendering_without_a_display_gives_the_envs_own_message(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    with pytest.raises(ValueError, match="render_mode='human' opens a window and needs a display"):
        gym.make("WallInspector/WallHover-v0", render_mode="human")


@pytest.mark.parametrize("kwargs, message", [
    ({"reward_weights": {"position": float("nan")}}, r"reward_weights\['position'\] must be finite"),
    ({"reward_weights": {"position": "high"}}, r"reward_weights\['position'\] must be a number"),
    ({"reward_weights": [1, 2]}, r"reward_weights must be a dict"),
    ({"noise": "no"}, r"noise must be True or False"),
    ({"noise": 0}, r"noise must be True or False"),
    ({"terminate_on_collision": "yes"}, r"terminate_on_collision must be True or False"),
    ({"physics_substeps": 2.0}, r"physics_substeps must be an integer"),
    ({"duration": 3600.0, "control_dt": 0.001}, r"duration / control_dt must be at most"),
])
def test_values_once_accepted_silently_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("WallInspector/WallHover-v0", **kwargs)


@pytest.mark.parametrize("action, message", [
    (np.zeros((2, 2)), r"shape \(4,\)"),
    (np.zeros((1, 4)), r"shape \(4,\)"),
    (np.zeros(4, dtype=complex), "real numbers"),
    (np.array(["0", "0", "0", "0"]), "real numbers"),
    ([0.0, np.inf, 0.0, 0.0], "finite"),
])
def test_actions_of_the_wrong_shape_or_kind_are_refused(action, message):
    env = gym.make("WallInspector/WallHover-v0", disable_env_checker=True)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        env.step(action)
    env.close()


def test_bad_reset_options_are_refused():
    env = WallInspectorEnv("WallHover")
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"reset_mask": [True]})
    with pytest.raises(ValueError, match="perturb_start must be True or False"):
        env.reset(options={"perturb_start": "no"})
    env.close()
