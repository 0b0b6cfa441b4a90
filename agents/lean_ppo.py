"""PPO with fewer Python round trips: Stable-Baselines3's algorithm, its rollouts and updates written lean.

:class:`LeanPPO` is a subclass of SB3's ``PPO`` (the same hyperparameters, policy class,
``save``/``load`` files, callbacks, ``evaluate_policy``; a saved model loads with plain
``PPO.load``) that changes how the work is done, not what is computed:

* **rollouts** (:meth:`LeanPPO.collect_rollouts`): one forward pass of the actor and critic on
  the whole batch of observations per step, their layers applied as functions (no module calls:
  about a third of a small MLP's forward time is ``nn.Module`` dispatch), the Gaussian sample and
  its log-probability written out (no ``Distribution`` objects), and the values of every
  time-limited episode's last observation in one batched call instead of one call per ended episode;
* **updates** (:meth:`LeanPPO.train`): the rollout is turned into tensors once; each minibatch is
  one forward pass of the actor and critic and one backward pass, gradient clipping over all
  parameters in one fused call (``foreach``), Adam's fused CPU kernel (set by the caller's
  ``optimizer_kwargs``), and the statistics that SB3 logs per minibatch (clip fraction, KL) kept
  as tensors and read once per update instead of with an ``.item()`` per minibatch.

With a :class:`~agents.rollout_worker.RolloutWorker` in ``rollout_worker`` (set by :func:`agents.train.train`),
the rollouts are flown in that process while the updates run here, one update behind (see that module).

The losses are SB3's: clipped surrogate with per-minibatch advantage normalisation, value loss
(optionally clipped), entropy bonus, ``max_grad_norm``, ``target_kl`` early stopping; for a
diagonal Gaussian policy (``MlpPolicy`` on a ``Box`` action space without gSDE, which is what
``wall-inspector train`` builds) the log-probabilities equal SB3's to rounding.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.utils import explained_variance

__all__ = ["LeanPPO"]

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


class _Tanh(torch.autograd.Function):
    """tanh as 2 sigmoid(2x) - 1 with tanh's own backward pass (the gradient from the output, ``1 - y**2``): the
    same values to float32 rounding (1.8e-7), about 4x faster than ``torch.tanh`` on a minibatch (1024 x 64: 35 us
    against 135 us on this project's CPUs, where the tanh layers were the largest single cost of a gradient step;
    on a rollout's 64 rows ``torch.tanh`` is as fast, and the rollouts keep it)."""

    @staticmethod
    def forward(ctx: Any, x: torch.Tensor) -> torch.Tensor:
        y = torch.sigmoid(x * 2.0).mul_(2.0).sub_(1.0)
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> torch.Tensor:
        (y,) = ctx.saved_tensors
        return torch.ops.aten.tanh_backward(grad, y)


def _functional(layers: tuple[list[Any], list[Any]], grad: bool) -> Any:
    """``obs -> (mean, value)`` of :meth:`LeanPPO._plain_layers`' layers applied as functions (no module calls; with
    ``grad``, the minibatch tanh :class:`_Tanh`)."""
    functions = {"tanh": _Tanh.apply if grad else torch.tanh, "relu": torch.relu, "elu": torch.nn.functional.elu}
    linear = torch.nn.functional.linear
    actor, critic = ([step if isinstance(step, tuple) else functions[step] for step in steps] for steps in layers)

    def run(steps: list[Any], x: Any) -> Any:
        for step in steps:
            x = linear(x, step[0], step[1]) if isinstance(step, tuple) else step(x)
        return x

    def functional(obs: Any) -> tuple[Any, Any]:
        return run(actor, obs), run(critic, obs)

    return functional


class LeanPPO(PPO):
    """Stable-Baselines3's PPO with lean rollouts and updates (module docstring).

    ``adaptive_kl``: ``None`` (the learning rate follows ``learning_rate``, a number or a schedule) or a
    target KL divergence between the policies before and after a minibatch step: after each step the
    learning rate is multiplied by 1.5 when the KL was below half the target and divided by 1.5 when it
    was above twice the target (kept within [1e-5, 1e-2]), starting from ``learning_rate``.
    """

    def __init__(self, *args: Any, adaptive_kl: float | None = None, **kwargs: Any):
        if adaptive_kl is not None and not 0.0 < float(adaptive_kl) < 1.0:
            raise ValueError(f"adaptive_kl must be None or a KL in (0, 1), got {adaptive_kl!r}")
        self.adaptive_kl = None if adaptive_kl is None else float(adaptive_kl)
        self.adaptive_lr: float | None = None
        # set by the caller (agents.train): rollouts flown in that process, beside the updates (agents.rollout_worker)
        self.rollout_worker: Any = None
        super().__init__(*args, **kwargs)

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "rollout_worker"]

    def _setup_model(self) -> None:
        super()._setup_model()
        if self.use_sde:
            raise ValueError("LeanPPO supports a diagonal Gaussian policy without gSDE (use_sde=False)")

    # ------------------------------------------------------------------ the policy's pieces, batched
    def _latent(self, obs: Any) -> tuple[Any, Any]:
        policy = self.policy
        features = policy.extract_features(obs)
        if policy.share_features_extractor:
            return policy.mlp_extractor(features)
        pi_features, vf_features = features
        return policy.mlp_extractor.forward_actor(pi_features), policy.mlp_extractor.forward_critic(vf_features)

    def _plain_layers(self) -> tuple[list[Any], list[Any]] | None:
        """The actor's and critic's layers as ``(weight, bias)`` pairs and activation names, heads included, when the
        policy is the plain ``MlpPolicy`` of flat observations (``Linear`` layers and tanh/ReLU/ELU only); else ``None``."""
        from stable_baselines3.common.torch_layers import FlattenExtractor

        policy = self.policy
        names = {torch.nn.Tanh: "tanh", torch.nn.ReLU: "relu", torch.nn.ELU: "elu"}

        def plain(net: Any) -> list[Any] | None:
            steps: list[Any] = []
            for layer in net:
                if type(layer) is torch.nn.Linear:
                    steps.append((layer.weight, layer.bias))
                elif type(layer) in names:
                    steps.append(names[type(layer)])
                else:
                    return None
            return steps

        extractor = policy.mlp_extractor
        actor, critic = plain(extractor.policy_net), plain(extractor.value_net)
        flat = isinstance(policy.features_extractor, FlattenExtractor) and len(policy.observation_space.shape or ()) == 1
        if actor is None or critic is None or not flat:
            return None
        return ([*actor, (policy.action_net.weight, policy.action_net.bias)],
                [*critic, (policy.value_net.weight, policy.value_net.bias)])

    def _networks(self, grad: bool) -> Any:
        """``obs -> (mean, value)``: the MLPs' layers applied as functions (:func:`_functional`) when the policy is
        plain (:meth:`_plain_layers`), else the modules themselves."""
        layers = self._plain_layers()
        if layers is not None:
            return _functional(layers, grad)
        policy = self.policy

        def modules(obs: Any) -> tuple[Any, Any]:
            latent_pi, latent_vf = self._latent(obs)
            return policy.action_net(latent_pi), policy.value_net(latent_vf)

        return modules

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = False) -> tuple[Any, Any]:
        """SB3's ``predict`` (the same actions, clipped to the action space), for a flat observation ``(obs_size,)``
        or batch ``(n, obs_size)`` of a plain policy without SB3's per-call module walk and distribution objects
        (the evaluations during training call it once per env step); anything else goes to SB3's."""
        policy = self.policy
        shape = tuple(policy.observation_space.shape or ())
        layers = (self._plain_layers() if isinstance(observation, np.ndarray) and state is None and len(shape) == 1
                  and observation.shape[-1:] == shape and observation.ndim <= 2 else None)
        if layers is None:
            return super().predict(observation, state, episode_start, deterministic)
        space = self.action_space
        assert isinstance(space, spaces.Box)
        with torch.no_grad():
            obs = torch.as_tensor(observation.reshape(-1, shape[0]), dtype=torch.float32)
            mean, _ = _functional(layers, grad=False)(obs)
            if not deterministic:
                mean = mean + torch.randn_like(mean) * policy.log_std.exp()
        actions = np.clip(mean.numpy(), space.low, space.high)
        return (actions[0] if observation.ndim == 1 else actions), state

    def collect_rollouts(self, env: Any, callback: Any, rollout_buffer: Any, n_rollout_steps: int) -> bool:
        if self.rollout_worker is not None:
            return self._collect_from_worker(env, callback, rollout_buffer, n_rollout_steps)
        assert self._last_obs is not None, "no previous observation was provided"
        policy = self.policy
        acting = self._networks(grad=False)
        policy.set_training_mode(False)
        rollout_buffer.reset()
        callback.on_rollout_start()
        space = self.action_space
        assert isinstance(space, spaces.Box), "LeanPPO acts in a Box action space"
        low, high = space.low, space.high
        n_steps = 0
        new_obs, dones = self._last_obs, self._last_episode_starts
        while n_steps < n_rollout_steps:
            with torch.no_grad():
                mean, values = acting(torch.as_tensor(self._last_obs, dtype=torch.float32))
                noise = torch.randn_like(mean)
                actions_t = mean + noise * policy.log_std.exp()
                log_probs = -(0.5 * noise.square() + policy.log_std + _LOG_SQRT_2PI).sum(dim=1)
            actions = actions_t.numpy()
            new_obs, rewards, dones, infos = env.step(np.clip(actions, low, high))
            self.num_timesteps += env.num_envs
            callback.update_locals(locals())
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
            n_steps += 1
            ended = np.flatnonzero(dones)
            if len(ended):  # bootstrap time-limit ends with the value of their last observation, in one call
                cut = [k for k in ended if infos[k].get("TimeLimit.truncated", False)
                       and infos[k].get("terminal_observation") is not None]
                if cut:
                    last = np.stack([infos[k]["terminal_observation"] for k in cut]).astype(np.float32)
                    with torch.no_grad():
                        last_values = policy.predict_values(torch.as_tensor(last)).flatten().numpy()
                    rewards = rewards.copy()
                    rewards[cut] += self.gamma * last_values
            rollout_buffer.add(self._last_obs, actions, rewards, self._last_episode_starts, values, log_probs)
            self._last_obs, self._last_episode_starts = new_obs, dones
        with torch.no_grad():
            values = policy.predict_values(torch.as_tensor(new_obs, dtype=torch.float32))
        rollout_buffer.compute_returns_and_advantage(last_values=values, dones=dones)
        callback.update_locals(locals())
        callback.on_rollout_end()
        return True

    def _collect_from_worker(self, env: Any, callback: Any, rollout_buffer: Any, n_rollout_steps: int) -> bool:
        """The rollout the worker flew (with the policy from before the last update), its next one started with the
        current policy; the finished one copied into ``rollout_buffer`` and replayed to the callbacks step by step."""
        worker = self.rollout_worker
        if worker.n_steps != n_rollout_steps:
            raise ValueError(f"the rollout worker flies {worker.n_steps} steps per env, the learner asks for {n_rollout_steps}")
        callback.on_rollout_start()
        normalizer = self.get_vec_normalize_env()
        if not worker.flying:  # the first rollout: the current policy, with the learner's statistics (a resumed run's)
            worker.fly(self.policy, *((normalizer.obs_rms, normalizer.ret_rms) if normalizer is not None else ()))
        rollout = worker.collect()
        worker.fly(self.policy)  # the next rollout flies while the learner updates on this one
        if normalizer is not None:
            normalizer.obs_rms, normalizer.ret_rms = rollout.obs_rms, rollout.ret_rms
        rollout_buffer.reset()
        for name, array in rollout.arrays.items():
            getattr(rollout_buffer, name)[...] = array
        rollout_buffer.pos, rollout_buffer.full = rollout_buffer.buffer_size, True
        for t in range(n_rollout_steps):
            infos, dones = rollout.infos_of_step(t), rollout.dones[t]
            self.num_timesteps += env.num_envs
            callback.update_locals({"infos": infos, "dones": dones})
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
        callback.update_locals({"rollout_buffer": rollout_buffer})
        callback.on_rollout_end()
        return True

    def train(self) -> None:
        policy = self.policy
        policy.set_training_mode(True)
        adaptive = getattr(self, "adaptive_kl", None)
        if adaptive is None:
            self._update_learning_rate(policy.optimizer)
        else:
            if getattr(self, "adaptive_lr", None) is None:
                self.adaptive_lr = float(self.lr_schedule(1.0))
            for group in policy.optimizer.param_groups:
                group["lr"] = self.adaptive_lr
        clip_range = float(self.clip_range(self._current_progress_remaining))  # type: ignore[operator]
        clip_range_vf = None if self.clip_range_vf is None else float(self.clip_range_vf(self._current_progress_remaining))  # type: ignore[operator]
        buf = self.rollout_buffer
        n = buf.buffer_size * buf.n_envs

        def flat(array: np.ndarray) -> Any:
            return torch.as_tensor(array.reshape(n, *array.shape[2:]), dtype=torch.float32)

        obs, actions = flat(buf.observations), flat(buf.actions)
        old_values, old_log_prob = flat(buf.values).flatten(), flat(buf.log_probs).flatten()
        advantages, returns = flat(buf.advantages).flatten(), flat(buf.returns).flatten()
        parameters = [p for p in policy.parameters() if p.requires_grad]
        networks = self._networks(grad=True)
        optimizer = policy.optimizer
        batch_size = int(self.batch_size)
        clip_sum = torch.zeros(())
        kl_sum = torch.zeros(())
        batches = 0
        continue_training = True
        epoch = 0
        policy_loss = value_loss = entropy_loss = torch.zeros(())
        for epoch in range(self.n_epochs):
            order = torch.randperm(n)
            for first in range(0, n, batch_size):
                rows = order[first:first + batch_size]
                mean, values = networks(obs[rows])
                values = values.flatten()
                log_std = policy.log_std
                log_prob = -(0.5 * ((actions[rows] - mean) * torch.exp(-log_std)).square()
                             + log_std + _LOG_SQRT_2PI).sum(dim=1)
                adv = advantages[rows]
                if self.normalize_advantage and len(rows) > 1:
                    adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                log_ratio = log_prob - old_log_prob[rows]
                ratio = torch.exp(log_ratio)
                policy_loss = -torch.min(adv * ratio, adv * torch.clamp(ratio, 1.0 - clip_range, 1.0 + clip_range)).mean()
                if clip_range_vf is not None:
                    values = old_values[rows] + torch.clamp(values - old_values[rows], -clip_range_vf, clip_range_vf)
                value_loss = torch.nn.functional.mse_loss(returns[rows], values)
                entropy_loss = -(log_std + 0.5 + _LOG_SQRT_2PI).sum()  # a diagonal Gaussian's entropy, every row alike
                loss = policy_loss + self.ent_coef * entropy_loss + self.vf_coef * value_loss
                with torch.no_grad():
                    kl = ((ratio - 1.0) - log_ratio).mean()
                    clip_sum += ((ratio - 1.0).abs() > clip_range).float().mean()
                    kl_sum += kl
                batches += 1
                if self.target_kl is not None and float(kl) > 1.5 * self.target_kl:
                    continue_training = False
                    if self.verbose >= 1:
                        print(f"Early stopping at step {epoch} due to reaching max kl: {float(kl):.2f}")
                    break
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                torch.nn.utils.clip_grad_norm_(parameters, self.max_grad_norm, foreach=True)
                optimizer.step()
                if adaptive is not None:
                    lr = float(self.adaptive_lr)  # type: ignore[arg-type]
                    step_kl = float(kl)
                    lr = lr / 1.5 if step_kl > 2.0 * adaptive else lr * 1.5 if step_kl < 0.5 * adaptive else lr
                    self.adaptive_lr = min(max(lr, 1e-5), 1e-2)
                    for group in optimizer.param_groups:
                        group["lr"] = self.adaptive_lr
            if not continue_training:
                break
        self._n_updates += epoch + 1
        explained_var = explained_variance(buf.values.flatten(), buf.returns.flatten())
        self.logger.record("train/entropy_loss", float(entropy_loss.detach()))
        self.logger.record("train/policy_gradient_loss", float(policy_loss.detach()))
        self.logger.record("train/value_loss", float(value_loss.detach()))
        self.logger.record("train/approx_kl", float(kl_sum) / max(batches, 1))
        self.logger.record("train/clip_fraction", float(clip_sum) / max(batches, 1))
        self.logger.record("train/loss", float(loss.detach()))
        self.logger.record("train/explained_variance", explained_var)
        self.logger.record("train/std", float(torch.exp(policy.log_std.detach()).mean()))
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/clip_range", clip_range)
        if adaptive is not None:
            self.logger.record("train/learning_rate", float(self.adaptive_lr))  # type: ignore[arg-type]
        if clip_range_vf is not None:
            self.logger.record("train/clip_range_vf", clip_range_vf)
