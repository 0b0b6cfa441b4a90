"""The training configuration is typed: nested dataclasses built from the YAML files and ``--set``."""

import pytest

from agents.config import (
    CONFIG_DIR,
    PPOSettings,
    TeacherSettings,
    TrainingConfig,
    apply_overrides,
    default_config,
    load_config,
    task_env_id,
    validate_config,
)


@pytest.mark.parametrize("path", sorted(CONFIG_DIR.glob("*.yaml")), ids=lambda p: p.stem)
def test_every_shipped_configuration_file_builds_the_typed_configuration(path):
    config = load_config(path, validate=False)
    config["env_id"] = config["env_id"] or task_env_id(path.stem)  # a task's own file is named after it
    typed = TrainingConfig.from_dict(config)
    assert isinstance(typed.ppo, PPOSettings) and isinstance(typed.teacher, TeacherSettings)
    assert typed.ppo.n_steps == config["ppo"]["n_steps"] and typed.policy.net_arch == config["policy"]["net_arch"]
    assert TrainingConfig.from_dict(typed.to_dict()) == typed  # the plain mapping round-trips exactly


def test_the_typed_defaults_are_the_shared_defaults_a_file_overrides():
    config = default_config("WallHover")
    typed = TrainingConfig.from_dict(config)
    assert typed.env_id == "WallInspector/WallHover-v0"
    assert typed.eval.seed == 10_000 and typed.card_eval.episodes == 10 and typed.normalize.clip_obs == 10.0
    assert validate_config(dict(config)) == config  # validating a valid configuration changes nothing


@pytest.mark.parametrize(("change", "message"), [
    ({"ppo": {"bogus": 1}}, r"ppo: unknown key\(s\) \['bogus'\]; allowed: \['adaptive_kl', "),
    ({"bogus": 1}, r"unknown key\(s\) \['bogus'\]; allowed: \['algo', "),
    ({"ppo": "fast"}, r"ppo must be a mapping, got 'fast'"),
    ({"ppo.gamma": 0.0}, r"ppo.gamma must be in \(0.0, 1.0\], got 0.0"),
    ({"ppo.learning_rate_final": 1.0}, r"ppo.learning_rate_final must be in \[0.0, 0.0005\], got 1.0"),
    ({"policy.activation": "sigmoid"}, r"policy.activation must be one of \('tanh', 'relu', 'elu'\), got 'sigmoid'"),
    ({"policy.ortho_init": "yes"}, r"policy.ortho_init must be true or false, got 'yes'"),
    ({"normalize.clip_obs": -1}, r"normalize.clip_obs must be in \(0.0, inf\], got -1"),
    ({"teacher.seed": -3}, r"teacher.seed must be a whole number >= 0, got -3"),
    ({"history.frames": 0}, r"history.frames must be an integer in \[1, 64\], got 0"),
    ({"card_eval.episodes": 0}, r"card_eval.episodes must be a positive integer, got 0"),
    ({"n_envs": 2, "n_workers": 3}, r"n_workers \(3\) must not exceed n_envs \(2\)"),
])
def test_a_wrong_field_is_refused_with_its_name_and_allowed_values(change, message):
    config = default_config("WallSweep")
    for key, value in change.items():
        section, _, entry = key.partition(".")
        if entry:
            config[section][entry] = value
        elif isinstance(value, dict) and isinstance(config.get(key), dict):
            config[key] = {**config[key], **value}
        else:
            config[key] = value
    with pytest.raises(ValueError, match=message):
        TrainingConfig.from_dict(config)


def test_overrides_reach_the_typed_fields():
    config = apply_overrides(default_config("WallSweep"), ["ppo.n_epochs=2", "policy.net_arch=[32, 16]", "seed=4"])
    typed = TrainingConfig.from_dict(config)
    assert (typed.ppo.n_epochs, typed.policy.net_arch, typed.seed) == (2, [32, 16], 4)


def test_the_critic_can_be_wider_than_the_actor():
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.envs import make_vec_env
    from agents.learner import make_ppo

    config = apply_overrides(default_config("WallSweep"), ["policy.critic_arch=[128, 128]", "n_envs=2"])
    policy = make_ppo(config, VecNormalize(make_vec_env(config, 2, vector="batched")), None).policy
    assert [layer.out_features for layer in policy.mlp_extractor.policy_net if hasattr(layer, "out_features")] == [64, 64]
    assert [layer.out_features for layer in policy.mlp_extractor.value_net if hasattr(layer, "out_features")] == [128, 128]
    with pytest.raises(ValueError, match="policy.critic_arch"):
        apply_overrides(config, ["policy.critic_arch=[0]"])


def test_a_learner_without_a_log_folder_writes_nothing_to_the_temp_dir(tmp_path, monkeypatch):
    """SB3's learn() makes an empty SB3-<time> folder in the temp dir when no logger is set up; ours has none."""
    import tempfile

    from stable_baselines3.common.vec_env import VecNormalize

    from agents.envs import make_vec_env
    from agents.learner import make_ppo

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)  # the test session's own folder (conftest) would hide it
    config = apply_overrides(default_config("WallHover"), ["n_envs=2", "ppo.n_steps=32", "ppo.batch_size=64",
                                                           "ppo.n_epochs=1", "env_kwargs.duration=0.5"])
    model = make_ppo(config, VecNormalize(make_vec_env(config, 2, vector="batched")), None)
    model.learn(total_timesteps=64)
    assert model.num_timesteps == 64
    assert sorted(p.name for p in tmp_path.glob("SB3-*")) == []
