"""The configuration's learner: :class:`agents.lean_ppo.LeanPPO` with the network, optimiser and schedule that a
training configuration (:mod:`agents.config`) names; :func:`agents.train.train` and a
:class:`~agents.rollout_worker.RolloutWorker` build theirs alike."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

__all__ = ["make_ppo"]


def make_ppo(config: dict[str, Any], env: Any, tb_dir: Path | None, verbose: int = 0) -> Any:
    """The configuration's learner (:class:`agents.lean_ppo.LeanPPO`) on ``env``; TensorBoard logs into ``tb_dir``."""
    import torch
    from stable_baselines3.common.utils import LinearSchedule

    from agents.lean_ppo import LeanPPO

    activation = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU}[config["policy"]["activation"]]
    arch = list(config["policy"]["net_arch"])
    critic = list(config["policy"]["critic_arch"] or arch)
    # SB3's Adam (eps 1e-5) with PyTorch's fused CPU kernel: one call updates every tensor (the same
    # algorithm; a gradient step of 1024 samples measured 3.3 ms against 4.5 ms with the default loop)
    policy_kwargs = {"net_arch": {"pi": arch, "vf": critic}, "activation_fn": activation,
                     "log_std_init": float(config["policy"]["log_std_init"]), "ortho_init": bool(config["policy"]["ortho_init"]),
                     "optimizer_kwargs": {"eps": 1e-5, "fused": True}}
    ppo = dict(config["ppo"])
    final = ppo.pop("learning_rate_final")
    ppo["adaptive_kl"] = ppo.pop("adaptive_kl")
    if final is not None:  # progress runs over the planned timesteps, resumed runs included
        ppo["learning_rate"] = LinearSchedule(float(ppo["learning_rate"]), float(final), 1.0)
    model = LeanPPO("MlpPolicy", env, policy_kwargs=policy_kwargs, seed=config["seed"],
                    tensorboard_log=None if tb_dir is None else str(tb_dir),
                    device="cpu", verbose=verbose, **ppo)
    if tb_dir is None:  # without a folder, SB3's learn() makes an empty SB3-<time> folder in the temp dir each call
        from stable_baselines3.common.logger import HumanOutputFormat, Logger

        model.set_logger(Logger(None, [HumanOutputFormat(sys.stdout)] if verbose >= 1 else []))
    return model
