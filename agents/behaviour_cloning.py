"""Behaviour cloning into a Stable-Baselines3 PPO model, so PPO starts from a controller's flight.

::

    normalizer = VecNormalize(venv, gamma=0.99)
    model = PPO("MlpPolicy", normalizer, policy_kwargs={"log_std_init": -3.0})
    report = warm_start(model, normalizer, demos, epochs=30)     # then model.learn(...)

Three steps, each in the space PPO itself works in:

1. :func:`fit_normalizer`: the ``VecNormalize`` statistics are set from the demonstrations
   (observation mean and variance; the running discounted return's variance, accumulated
   as ``VecNormalize.step_wait`` does), so cloning and PPO see the same normalised inputs
   and rewards. PPO goes on updating them from its own rollouts.
2. The actor's mean (``policy.get_distribution(obs).distribution.mean``: PPO's
   deterministic action before the env's clipping) is regressed on the controller's
   clean actions, mean squared error.
3. At the same time the critic (``policy.predict_values``) is regressed on the discounted
   returns of the normalised rewards (:func:`~agents.demonstrations.discounted_returns`),
   so that the first PPO updates get sensible advantages and do not wreck the cloned actor.

The actor's ``log_std`` is not trained: PPO starts exploring with the configured
``policy.log_std_init``. A share of the envs (whole flights) is held out and the
report gives the actor's error on it.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from agents.demonstrations import Demonstrations, discounted_returns

__all__ = ["fit_normalizer", "warm_start"]


def fit_normalizer(normalizer: Any, demos: Demonstrations) -> None:
    """Set ``normalizer``'s (a ``VecNormalize``) observation and return statistics from ``demos``."""
    from stable_baselines3.common.running_mean_std import RunningMeanStd

    if normalizer.norm_obs:
        obs_rms = RunningMeanStd(shape=normalizer.observation_space.shape)
        obs_rms.update(demos.observations.reshape(demos.n_samples, -1).astype(np.float64))
        normalizer.obs_rms = obs_rms
    if normalizer.norm_reward:
        ret_rms = RunningMeanStd(shape=())
        running = np.zeros(demos.rewards.shape[1])
        for reward, done in zip(demos.rewards, demos.dones):  # as VecNormalize.step_wait accumulates them
            running = running * normalizer.gamma + reward
            ret_rms.update(running)
            running[done] = 0.0
        normalizer.ret_rms = ret_rms


def _scaled_rewards(normalizer: Any, rewards: np.ndarray) -> np.ndarray:
    return np.asarray(normalizer.normalize_reward(rewards.astype(np.float64)), dtype=np.float64)


def warm_start(model: Any, normalizer: Any, demos: Demonstrations, *, epochs: int = 30, batch_size: int = 1024,
               learning_rate: float = 1e-3, holdout: float = 0.05, seed: int = 0, fit_critic: bool = True) -> dict[str, Any]:
    """Fit ``normalizer`` to ``demos``, then clone the demonstrated actions into ``model``'s actor and
    their returns into its critic (module docstring; ``fit_critic=False``: the actor alone, for an agent
    that PPO will not go on training). Returns a report for the model card: samples, epochs, seconds,
    and the actor's RMS action error on the held-out flights."""
    import torch

    if isinstance(epochs, bool) or not isinstance(epochs, int) or epochs < 1:
        raise ValueError(f"epochs must be a positive integer, got {epochs!r}")
    if not 0.0 <= holdout < 1.0:
        raise ValueError(f"holdout must be in [0, 1), got {holdout!r}")
    start = time.perf_counter()
    fit_normalizer(normalizer, demos)
    policy = model.policy
    gamma = float(model.gamma)
    returns = discounted_returns(_scaled_rewards(normalizer, demos.rewards), demos.dones, demos.truncated, gamma)

    n_envs = demos.observations.shape[1]
    rng = np.random.default_rng(seed)
    held = np.zeros(n_envs, dtype=bool)
    if holdout > 0 and n_envs > 1:
        held[rng.choice(n_envs, size=max(1, int(round(holdout * n_envs))), replace=False)] = True

    def tensors(envs: np.ndarray) -> tuple[Any, Any, Any]:
        obs = demos.observations[:, envs].reshape(-1, demos.observations.shape[-1])
        obs = np.asarray(normalizer.normalize_obs(obs), dtype=np.float32)
        actions = demos.actions[:, envs].reshape(-1, demos.actions.shape[-1])
        values = returns[:, envs].reshape(-1).astype(np.float32)
        return torch.as_tensor(obs), torch.as_tensor(actions, dtype=torch.float32), torch.as_tensor(values)

    obs, actions, values = tensors(~held)
    trained = [p for name, p in policy.named_parameters()
               if name != "log_std" and (fit_critic or not name.startswith(("value_net", "mlp_extractor.value_net")))]
    optimizer = torch.optim.Adam(trained, lr=learning_rate)
    updates = epochs * int(np.ceil(len(obs) / batch_size))
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=updates)
    generator = torch.Generator().manual_seed(seed)
    policy.set_training_mode(True)
    actor_loss = critic_loss = float("nan")
    for _ in range(epochs):
        order = torch.randperm(len(obs), generator=generator)
        actor_sum = critic_sum = 0.0
        for first in range(0, len(obs), batch_size):
            rows = order[first:first + batch_size]
            mean = policy.get_distribution(obs[rows]).distribution.mean
            actor = torch.mean((mean - actions[rows]) ** 2)
            critic = (torch.mean((policy.predict_values(obs[rows]).squeeze(-1) - values[rows]) ** 2) if fit_critic
                      else torch.zeros(()))
            optimizer.zero_grad()
            (actor + critic).backward()
            optimizer.step()
            schedule.step()
            actor_sum += actor.item() * len(rows)
            critic_sum += critic.item() * len(rows)
        actor_loss, critic_loss = actor_sum / len(obs), critic_sum / len(obs)
    policy.set_training_mode(False)

    report: dict[str, Any] = {
        "samples": int(len(obs)), "epochs": epochs, "batch_size": batch_size, "learning_rate": learning_rate,
        "train_action_rmse": round(float(np.sqrt(actor_loss)), 5),
        **({"train_value_rmse": round(float(np.sqrt(critic_loss)), 4)} if fit_critic else {}),
        "value_target_mean": round(float(values.mean()), 3),
    }
    if held.any():
        held_obs, held_actions, held_values = tensors(held)
        with torch.no_grad():
            mean = policy.get_distribution(held_obs).distribution.mean
            report["heldout_samples"] = int(len(held_obs))
            report["heldout_action_rmse"] = round(float(torch.sqrt(torch.mean((mean - held_actions) ** 2))), 5)
            if fit_critic:
                report["heldout_value_rmse"] = round(
                    float(torch.sqrt(torch.mean((policy.predict_values(held_obs).squeeze(-1) - held_values) ** 2))), 4)
    report["wall_time_s"] = round(time.perf_counter() - start, 2)
    return report
