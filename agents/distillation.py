"""A controller distilled into a network, DAgger-style: the third way to an agent, beside PPO alone and PPO warm-started.

``wall-inspector train --algo dagger`` (the ``teacher`` section of the configuration)::

    iteration 0: the teacher (SC-MPC on the batched env) flies ``teacher.envs`` envs for
                 ``teacher.steps`` steps, DART noise on the flown action, clean action recorded
    iteration i: the student (the network so far, deterministic) flies as many envs, and the
                 teacher labels every state it reaches (its memory follows the student's flight)
    after each:  normaliser and actor fitted to every labelled state so far
                 (:func:`agents.behaviour_cloning.warm_start` on the teacher's actions), and the
                 network judged (train: its mean return on the evaluation envs); the best is kept

Iteration 0 alone is behaviour cloning; the later ones show the teacher the states the student's
own mistakes lead to (Ross et al., 2011), which cloning never sees. The result is an SB3 PPO
model (its ``save``/``load`` files, ``evaluate_policy``, loaded by :func:`agents.load_policy`
and ``fly --policy`` like any other agent) whose model card says it learned from a teacher: it
is reported in a row of its own, never as the agent that learned the task alone.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["distil"]


def distil(config: dict[str, Any], model: Any, normalizer: Any, verbose: int = 1,
           judge: Callable[[], float] | None = None) -> dict[str, Any]:
    """Distil ``config["teacher"]["controller"]`` into ``model`` (an SB3 PPO model) and ``normalizer``
    (its training ``VecNormalize``) as the module docstring says; the report for the model card.

    ``judge``: scores the network after each iteration (e.g. its mean evaluation return); the best
    iteration's network and normaliser are kept. A later iteration fits harder data (the states of
    the student's mistakes, where the teacher's actions are largest) and can come out worse.
    """
    import copy

    import torch

    from agents.behaviour_cloning import warm_start
    from agents.config import base_controller_kwargs
    from agents.demonstrations import Demonstrations, record_demonstrations
    from agents.envs import make_vec_env
    from agents.residual import make_base_controller

    settings = config["teacher"]
    name = settings["controller"]
    envs, steps = int(settings["envs"]), int(settings["steps"])
    first_seed = int(settings["seed"]) + int(config["seed"]) * envs * int(settings["iterations"])
    venv = make_vec_env(config, envs, vector="batched")
    iterations: list[dict[str, Any]] = []
    data: Demonstrations | None = None
    best: tuple[float, int, Any, Any, Any] | None = None  # score, iteration, weights, normaliser statistics
    started = time.perf_counter()
    try:
        expert = make_base_controller(name, venv, **base_controller_kwargs(config, name))

        def student(obs: np.ndarray) -> np.ndarray:
            with torch.no_grad():
                actions, _ = model.predict(normalizer.normalize_obs(obs), deterministic=True)
            return np.asarray(actions)

        for i in range(int(settings["iterations"])):
            seed = first_seed + i * envs
            flights = record_demonstrations(venv, expert, steps, noise=float(settings["noise"]) if i == 0 else 0.0,
                                            seed=seed, pilot=None if i == 0 else student)
            data = flights if data is None else data.join(flights)
            fit = warm_start(model, normalizer, data, epochs=int(settings["epochs"]),
                             batch_size=int(settings["batch_size"]), learning_rate=float(settings["learning_rate"]),
                             seed=int(config["seed"]) + i, fit_critic=False)
            score = None if judge is None else float(judge())
            if score is not None and (best is None or score > best[0]):
                best = (score, i, copy.deepcopy(model.policy.state_dict()), copy.deepcopy(normalizer.obs_rms),
                        copy.deepcopy(normalizer.ret_rms))
            iterations.append({"pilot": name if i == 0 else "student", "seeds": [seed, seed + envs - 1],
                               "labels": flights.n_samples, "flight_and_labels_s": round(flights.wall_time_s, 2),
                               "student_return": None if i == 0 else round(float(flights.rewards.sum(axis=0).mean()), 1),
                               "fit": fit, **({"judged": round(score, 2)} if score is not None else {})})
            if verbose:
                print(f"teacher: iteration {i}: {'the teacher' if i == 0 else 'the student'} flew {flights.n_samples} "
                      f"labelled steps in {flights.wall_time_s:.1f} s; fitted on {data.n_samples} in {fit['wall_time_s']:.1f} s "
                      f"(held-out action RMS error {fit.get('heldout_action_rmse', float('nan')):.4f})", file=sys.stderr)
    finally:
        venv.close()
    assert data is not None
    if best is not None and best[1] != len(iterations) - 1:  # an earlier iteration flew better: keep it
        model.policy.load_state_dict(best[2])
        normalizer.obs_rms, normalizer.ret_rms = best[3], best[4]
    return {"controller": name, "iterations": iterations, "labels": data.n_samples,
            "kept_iteration": best[1] if best is not None else len(iterations) - 1,
            "controller_failures": int(getattr(expert, "failures", 0)),
            "wall_time_s": round(time.perf_counter() - started, 2)}
