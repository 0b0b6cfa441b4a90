"""PPO agents (Stable-Baselines3) trained on the Wall Inspector tasks.

``wall-inspector train`` (:mod:`agents.train`) trains one; :func:`load_policy` loads a
checkpoint folder or a shipped agent by task name and returns an object with
Stable-Baselines3-style ``predict``. A checkpoint folder holds Stable-Baselines3's own
files (``model.zip`` and ``vecnormalize.pkl``, loadable with ``PPO.load`` and
``VecNormalize.load`` alone) plus ``policy.json``; :func:`policy_factory` gives the ``env -> policy``
function the comparison tables take.

Modules: :mod:`agents.config` (per-task YAML in ``agents/configs/``),
:mod:`agents.envs` (environments from a configuration), :mod:`agents.vec_env`
(several environments per worker process), :mod:`agents.residual` (corrections on
top of PID / SC-MPC), :mod:`agents.demonstrations` and :mod:`agents.behaviour_cloning` (a controller's
flight recorded and cloned into PPO before training: ``--warm-start``), :mod:`agents.callbacks`, :mod:`agents.checkpoints` (files,
model cards), :mod:`agents.evaluate`, :mod:`agents.policy`, :mod:`agents.train`,
:mod:`agents.export` (an agent as one ONNX file for onnxruntime).
Importing this package does not import PyTorch; loading a policy does.
"""

from agents.checkpoints import CheckpointError, CheckpointNotFoundError
from agents.policy import TaskMismatchError, TrainedPolicy, load_policy, policy_factory, pretrained_path

__all__ = ["CheckpointError", "CheckpointNotFoundError", "TaskMismatchError", "TrainedPolicy", "load_policy",
           "policy_factory", "pretrained_path"]
