"""LeanPPO computes what Stable-Baselines3's PPO computes: the same rollouts' log-probabilities and values,
the same update, the same files."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecNormalize

from agents.batched_vec_env import BatchedVecEnv
from agents.lean_ppo import LeanPPO

SWEEP = "WallInspector/WallSweep-v0"


def _model(cls, n_envs=4, n_steps=32, seed=0, **kwargs):
    venv = VecNormalize(BatchedVecEnv(SWEEP, n_envs))
    return cls("MlpPolicy", venv, n_steps=n_steps, batch_size=n_envs * n_steps, n_epochs=1, seed=seed, device="cpu",
               policy_kwargs={"net_arch": [16, 16], "log_std_init": -1.0}, **kwargs)


class _Collect(BaseCallback):
    def _on_step(self) -> bool:
        return True


def _rollout(model):
    model._setup_learn(10_000, callback=None)
    callback = model._init_callback(_Collect())
    assert model.collect_rollouts(model.env, callback, model.rollout_buffer, model.n_steps)
    return model.rollout_buffer


def test_rollouts_record_sb3s_log_probabilities_and_values():
    model = _model(LeanPPO)
    buffer = _rollout(model)
    obs = torch.as_tensor(buffer.observations.reshape(-1, 48))
    actions = torch.as_tensor(buffer.actions.reshape(-1, 4))
    with torch.no_grad():
        values, log_prob, _ = model.policy.evaluate_actions(obs, actions)
    np.testing.assert_allclose(buffer.log_probs.reshape(-1), log_prob.numpy(), rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(buffer.values.reshape(-1), values.numpy().reshape(-1), rtol=1e-5, atol=1e-5)
    # the actions were sampled around the mean with the policy's std (exp(-1) = 0.37)
    with torch.no_grad():
        mean = model.policy.get_distribution(obs).distribution.mean
    spread = (actions - mean).std().item()
    assert 0.3 < spread < 0.45
    assert model.num_timesteps == 4 * 32


def test_one_update_moves_the_weights_as_sb3s_update_does():
    lean = _model(LeanPPO, ent_coef=0.01, clip_range_vf=0.5)
    reference = _model(PPO, ent_coef=0.01, clip_range_vf=0.5)
    reference.policy.load_state_dict(lean.policy.state_dict())
    buffer = _rollout(lean)
    _rollout(reference)
    reference.rollout_buffer = copy.deepcopy(buffer)  # the same rollout; one minibatch of all of it
    reference.rollout_buffer.generator_ready = False
    before = {k: v.clone() for k, v in lean.policy.state_dict().items()}
    lean.train()
    reference.train()
    for name, value in lean.policy.state_dict().items():
        np.testing.assert_allclose(value.numpy(), reference.policy.state_dict()[name].numpy(), rtol=1e-4, atol=1e-6,
                                   err_msg=name)
    moved = max(float((lean.policy.state_dict()[k] - v).abs().max()) for k, v in before.items())
    assert moved > 1e-5  # the update did something (so the comparison above compares something)


def test_a_saved_lean_model_is_plain_sb3_ppo(tmp_path):
    model = _model(LeanPPO)
    model.save(tmp_path / "model.zip")
    loaded = PPO.load(tmp_path / "model.zip", device="cpu")
    obs = np.random.default_rng(0).normal(size=(5, 48)).astype(np.float32)
    np.testing.assert_allclose(loaded.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0],
                               rtol=1e-6)


def test_lean_ppo_refuses_gsde():
    with pytest.raises(ValueError, match="without gSDE"):
        _model(LeanPPO, use_sde=True)


@pytest.mark.parametrize("target, factors", [(0.5, 1.5 * 1.5), (1e-9, 1.5 / 1.5)])
def test_adaptive_kl_steps_the_learning_rate_by_the_kl_of_each_minibatch(target, factors):
    model = _model(LeanPPO, adaptive_kl=target, learning_rate=3e-4)
    model.n_epochs = 2
    _rollout(model)
    model.train()
    # the first step starts from the rollout's own policy (KL 0: the rate grows); the second sees the
    # first step's change: far below half of 0.5 (grows again), far above twice 1e-9 (shrinks back)
    assert model.adaptive_lr == pytest.approx(3e-4 * factors)
    assert model.policy.optimizer.param_groups[0]["lr"] == pytest.approx(3e-4 * factors)
    with pytest.raises(ValueError, match=r"adaptive_kl must be None or a KL in \(0, 1\), got 2"):
        _model(LeanPPO, adaptive_kl=2)


def test_the_minibatch_tanh_has_tanhs_values_and_gradient():
    from agents.lean_ppo import _Tanh

    x = torch.randn(256, 64, dtype=torch.float32, generator=torch.Generator().manual_seed(0)) * 3.0
    weights = torch.randn(256, 64, generator=torch.Generator().manual_seed(1))
    fast, exact = x.clone().requires_grad_(True), x.clone().requires_grad_(True)
    (_Tanh.apply(fast) * weights).sum().backward()
    (torch.tanh(exact) * weights).sum().backward()
    np.testing.assert_allclose(_Tanh.apply(x).numpy(), torch.tanh(x).numpy(), rtol=0, atol=3e-7)
    np.testing.assert_allclose(fast.grad.numpy(), exact.grad.numpy(), rtol=0, atol=1e-6)
    assert float(exact.grad.abs().max()) > 0.5  # a gradient that the comparison can miss


@pytest.mark.parametrize("deterministic", [True, False])
def test_predict_gives_sb3s_actions(deterministic):
    model = _model(LeanPPO)
    obs = np.random.default_rng(2).normal(size=(200, 48)).astype(np.float32)
    ours = model.predict(obs, deterministic=deterministic)[0]
    theirs = PPO.predict(model, obs, deterministic=True)[0]  # SB3's own path: the mean, clipped
    assert ours.shape == (200, 4) and model.predict(obs[0], deterministic=deterministic)[0].shape == (4,)
    assert np.all(np.abs(ours) <= 1.0)
    if deterministic:
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-7)
        np.testing.assert_allclose(model.predict(obs[0], deterministic=True)[0], theirs[0], rtol=0, atol=1e-7)
    else:  # drawn around the mean with the policy's std, exp(-1) = 0.37
        assert np.std(ours - theirs) == pytest.approx(np.exp(-1.0), rel=0.1)
