"""Training an agent on a Wall Inspector task: PPO (Stable-Baselines3, PyTorch), or a distilled controller.

:func:`train` is a whole run (``wall-inspector train`` reads its options, :mod:`wall_inspector.train`).
What a run does:

* the configuration (:mod:`agents.config`) is saved as ``OUT/config.yaml``;
* ``n_envs`` environments (the batched env, or single envs in ``n_workers`` processes), under
  ``VecNormalize`` (observations and rewards), stepped by PPO; with ``rollout_worker``, a second
  process flies each rollout while the learner updates on the one before
  (:class:`~agents.rollout_worker.RolloutWorker`);
* an ``EvalCallback`` on a separate environment (same settings, its own seeds) every
  ``eval.freq`` env steps, saving the best model to ``OUT/best/``; periodic checkpoints
  in ``OUT/checkpoints/<steps>/``; TensorBoard logs in ``OUT/tb/``; a progress bar;
* at the end: the final checkpoint in ``OUT/``, an evaluation of the best checkpoint on
  the task's nominal settings (no randomisation, command noise as configured) over
  ``card_eval.episodes`` seeds, and the model card ``OUT/model_card.{json,md}`` with the
  exact command, timesteps, wall-clock time, throughput and those metrics.
  ``--ship`` then copies the best checkpoint and its card into
  ``agents/pretrained/<task>/``.

PPO learns from whole rollouts of ``n_envs * ppo.n_steps`` env steps, so a run trains
the most whole rollouts that fit in ``--timesteps`` (never more steps than asked for).

Ctrl-C (``SIGINT``) stops a run cleanly: the model, its normalisation statistics and the
step count are saved into ``OUT/checkpoints/<steps>/`` (:class:`TrainingInterrupted` says
where); ``train(..., resume=True)`` continues from the latest checkpoint with the same step
count. Checkpoints are also written every ``checkpoint_freq`` env steps and every
``checkpoint_minutes`` of wall time.

Throughput is total env steps of the run divided by its wall time, PPO updates,
evaluations and checkpoints included.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from agents.config import (
    base_controller_kwargs,
    save_config,
)
from agents.envs import vector_kind
from wall_env import interrupts

if TYPE_CHECKING:  # imported where used: agents.callbacks loads Stable-Baselines3
    from agents.callbacks import SameEpisodesEval

__all__ = [
    "TrainingInterrupted",
    "TrainingRun",
    "check_observations",
    "planned_timesteps",
    "card_written",
    "policy_description",
    "train",
]

_FINAL_FILES = ("model.zip", "vecnormalize.pkl", "policy.json")


class TrainingInterrupted(KeyboardInterrupt):
    """Training was stopped by Ctrl-C; ``checkpoint`` holds everything needed to resume."""

    def __init__(self, run_dir: Path, checkpoint: Path, num_timesteps: int):
        super().__init__(f"interrupted at {num_timesteps} env steps; saved in {checkpoint}")
        self.run_dir, self.checkpoint, self.num_timesteps = run_dir, checkpoint, num_timesteps


def card_written(run_dir: Path) -> bool:
    """Whether the run in ``run_dir`` finished: its model card is the last thing a run writes."""
    return (Path(run_dir) / "model_card.json").is_file()


def planned_timesteps(config: dict[str, Any], start: int = 0, unfinished: bool = False) -> int:
    """The step count a run reaches: ``start`` plus the most whole PPO rollouts
    (``n_envs * ppo.n_steps`` env steps each) that fit in ``config["timesteps"]``.

    ``ValueError`` if not even one rollout fits, unless the run is ``unfinished`` (resumed, its card not
    written: stopped after its last rollout, while its final model was judged or its card made) and
    ``config["timesteps"]`` covers ``start``: then no step is left and the run only finishes.
    """
    if config.get("algo", "ppo") == "dagger":  # no PPO steps: the teacher's labels are the training
        return int(start)
    rollout = int(config["n_envs"]) * int(config["ppo"]["n_steps"])
    rollouts = (int(config["timesteps"]) - int(start)) // rollout
    if unfinished and 0 < int(start) <= int(config["timesteps"]) and rollouts < 1:
        return int(start)
    if rollouts < 1:
        raise ValueError(f"--timesteps {config['timesteps']} leaves no room for one PPO rollout of {rollout} env steps "
                         f"(n_envs {config['n_envs']} x ppo.n_steps {config['ppo']['n_steps']})"
                         + (f" after the {start} steps already trained" if start else "")
                         + f"; ask for at least {int(start) + rollout}")
    return int(start) + rollouts * rollout


# ---------------------------------------------------------------------- pieces of a run
def policy_description(config: dict[str, Any]) -> dict[str, Any]:
    """What ``policy.json`` says about every checkpoint of this configuration."""
    residual = None
    if config["residual"]:
        residual = {"base": config["residual"], "scale": [float(s) for s in config["residual_scale"]],
                    "base_kwargs": base_controller_kwargs(config, config["residual"])}
    algorithm = "PPO" if config.get("algo", "ppo") == "ppo" else f"DAgger (teacher: {config['teacher']['controller']})"
    from agents.envs import history_settings

    history = history_settings(config)
    return {"env_id": config["env_id"], "algorithm": algorithm, "residual": residual,
            "history": None if history.trivial else history.to_dict()}


def check_observations(config: dict[str, Any], n: int = 8, seed: int = 12345) -> np.ndarray:
    """A few of the network's inputs from one short flight (zero actions) for the save/load check: raw
    observations, through the configuration's observation history if it has one."""
    from agents.envs import history_settings, make_env
    from agents.history import ObservationHistory, observation_width

    env = make_env(config, randomize=False, monitor=False)
    history = ObservationHistory(history_settings(config), observation_width(env.observation_space))
    try:
        obs, _ = env.reset(seed=seed)
        out = [history(obs[None], np.array([True]))[0]]
        for _ in range(n * 5):
            obs, _, terminated, truncated, _ = env.step(np.zeros(4, dtype=np.float32))
            out.append(history(obs[None], np.array([False]))[0])
            if terminated or truncated:
                obs, _ = env.reset()
                history(obs[None], np.array([True]))
        return np.asarray(out[:: 5][:n], dtype=np.float32)
    finally:
        env.close()


_TRACKED = ("agents", "wall_env", "controllers")  # the code a trained agent depends on


def git_state() -> dict[str, Any] | None:
    """``{"commit": sha, "uncommitted": [files]}`` of the code in ``agents/``, ``wall_env/``
    and ``controllers/`` (the files that differ from the commit, shipped agents excluded),
    or ``None`` outside a git checkout (:func:`wall_env.provenance.git_state`)."""
    from wall_env.provenance import git_state as state

    return state(_TRACKED, exclude=("agents/pretrained",))


def _latest_checkpoint(run_dir: Path) -> Path:
    """The checkpoint folder in ``run_dir`` with the most timesteps (final or periodic)."""
    from agents.checkpoints import CheckpointNotFoundError, read_json

    candidates = []
    for folder in [run_dir, *sorted((run_dir / "checkpoints").glob("*"))]:
        if all((folder / name).is_file() for name in _FINAL_FILES):
            info = read_json(folder / "policy.json")
            candidates.append((int(info.get("num_timesteps", 0)) if isinstance(info, dict) else 0, str(folder)))
    if not candidates:
        raise CheckpointNotFoundError(f"nothing to resume in {run_dir}: no {'/'.join(_FINAL_FILES)} there or in "
                                      f"{run_dir / 'checkpoints'}/*")
    return Path(max(candidates)[1])


@contextmanager
def _unchecked_distributions() -> Iterator[None]:
    """PyTorch's distributions without their argument checks, restored afterwards. The checks cost
    about 50 us per policy call (a few per cent of training); a NaN action still stops the run,
    as the env refuses actions that are not finite (:func:`wall_env.batch.check_actions`)."""
    import torch

    before = torch.distributions.Distribution._validate_args
    torch.distributions.Distribution.set_default_validate_args(False)
    try:
        yield
    finally:
        torch.distributions.Distribution.set_default_validate_args(before)


def _machine() -> str:
    return f"{os.cpu_count()} CPUs, {platform.machine()}, {platform.system()} {platform.release()}"


def _versions() -> dict[str, str]:
    import gymnasium
    import stable_baselines3
    import torch

    return {"python": platform.python_version(), "torch": torch.__version__, "stable_baselines3": stable_baselines3.__version__,
            "gymnasium": gymnasium.__version__, "numpy": np.__version__}


# ---------------------------------------------------------------------- the run
@dataclass
class TrainingRun:
    """What :func:`train` leaves: the model card, the trained model and its (closed)
    ``VecNormalize``, whose statistics are the ones saved in ``folder``."""

    card: dict[str, Any]
    model: Any
    normalizer: Any
    folder: Path


def train(config: dict[str, Any], out_dir: str | Path, *, resume: bool = False, progress_bar: bool = True,
          verbose: int = 1, command: str | None = None, checks: np.ndarray | None = None,
          on_checkpoint: Callable[[Path], object] | None = None, most_threads: int | None = None) -> TrainingRun:
    """Train (or, with ``resume``, continue) a run in ``out_dir``.

    ``checks``: the observations of :func:`check_observations` if already computed.
    ``on_checkpoint``: called with every periodic checkpoint folder right after it is written
    (``wall-inspector train --ray`` hands them to Ray Tune, to resume a trial whose worker died).
    ``most_threads``: the most PyTorch threads the run may take whatever is free (a Ray trial's CPUs).

    Raises :class:`TrainingInterrupted` on Ctrl-C, after saving a checkpoint to resume from.
    """
    import torch
    from stable_baselines3.common.callbacks import CallbackList
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.callbacks import (
        CollisionLog,
        PeriodicCheckpoint,
        ProgressBar,
        SameEpisodesEval,
        SaveBestCheckpoint,
        TorchThreads,
        TrainingClock,
        policy_info,
    )
    from agents.checkpoints import load_model, read_json, save_checkpoint, write_model_card
    from agents.envs import evaluation_config, make_training_env, make_vec_env
    from agents.learner import make_ppo
    from agents.rollout_worker import RolloutWorker
    from controllers.threads import allowed_cores, choose_threads

    started = time.perf_counter()
    out = Path(out_dir)
    start_threads = choose_threads(config["torch_threads"], most=most_threads)  # a warm start's cloning runs on these
    torch.set_num_threads(start_threads.threads)
    description = policy_description(config)
    norm = config["normalize"]
    git = git_state()  # the code this run starts from

    previous_wall = 0.0
    best_so_far = -np.inf
    start_steps = 0
    if resume:
        source = _latest_checkpoint(out)
        model, saved_normalizer, info = load_model(source)
        start_steps = int(model.num_timesteps)
        previous_wall = float(info.get("wall_time_s", 0.0))
        if (out / "best" / "policy.json").is_file():
            best_so_far = float(read_json(out / "best" / "policy.json").get("eval_mean_return", -np.inf))
    # ValueError before any worker starts
    target_steps = planned_timesteps(config, start_steps, unfinished=resume and not card_written(out))
    if checks is None:
        checks = check_observations(config)  # builds the env once: bad env settings fail here
    if not resume:
        out.mkdir(parents=True, exist_ok=True)
        save_config(config, out / "config.yaml")

    # the worker's start (imports, its env and learner) overlaps the learner's own. One process instead: a resumed run
    # (it continues with Stable-Baselines3's own PPO as loaded, agents.checkpoints.load_model) and a run that may use
    # one core only (a Ray trial of one CPU, an affinity of one core), where a second busy process would oversubscribe
    cores = min(len(allowed_cores()), most_threads or sys.maxsize)
    use_worker = config["rollout_worker"] and config["algo"] == "ppo" and not resume and cores >= 2
    train_env = make_training_env(config)
    venv = train_env.venv
    worker = None
    eval_env = None
    warm: dict[str, Any] | None = None
    teacher: dict[str, Any] | None = None
    try:
        worker = RolloutWorker(config) if use_worker else None
        clock = TrainingClock(previous_wall)  # a warm start's demonstrations and cloning count as training time
        if resume:
            train_env.obs_rms, train_env.ret_rms = saved_normalizer.obs_rms, saved_normalizer.ret_rms
            model.set_env(train_env)
            model.tensorboard_log = str(out / "tb")
        else:
            model = make_ppo(config, train_env, out / "tb", verbose)
            if config["warm_start"]["controller"]:
                warm = warm_start_from_controller(config, model, train_env, verbose=verbose)

        # the same wrappers as the training env (sync_envs_normalization walks both stacks); one env
        # per evaluation episode (up to 32), so an evaluation flies its episodes side by side; the task from its
        # start (no curriculum), the same episodes every time
        eval_envs = min(int(config["eval"]["episodes"]), 32)
        eval_env = VecNormalize(make_vec_env(evaluation_config(config), eval_envs, 0, vector=vector_kind(config)),
                                training=False, norm_obs=norm["norm_obs"], norm_reward=False,
                                clip_obs=float(norm["clip_obs"]))
        best = SaveBestCheckpoint(out / "best", description, clock, checks)
        evaluation = SameEpisodesEval(eval_env, int(config["eval"]["seed"]), callback_on_new_best=best,
                                      n_eval_episodes=int(config["eval"]["episodes"]),
                                      eval_freq=max(int(config["eval"]["freq"]) // config["n_envs"], 1),
                                      log_path=str(out / "eval"), deterministic=True, verbose=verbose)
        evaluation.best_mean_reward = best_so_far
        history_file = out / "eval" / "evaluations.npz"
        if resume and history_file.is_file():  # keep the earlier evaluations: EvalCallback rewrites the file
            with np.load(history_file) as history:
                evaluation.evaluations_timesteps = [int(t) for t in history["timesteps"]]
                evaluation.evaluations_results = [list(r) for r in history["results"]]
                evaluation.evaluations_length = [list(n) for n in history["ep_lengths"]]
        from agents.timing import TimeSplit

        if warm is not None:  # the cloned policy is the first candidate for best/: PPO has to beat it
            warm["eval_mean_return"] = _evaluate_as_best(model, train_env, evaluation, out / "best",
                                                         policy_info(model, clock, description), checks)
        if config["algo"] == "dagger" and not resume:
            from stable_baselines3.common.evaluation import evaluate_policy
            from stable_baselines3.common.vec_env import sync_envs_normalization

            from agents.distillation import distil

            def judge() -> float:  # the mean return of the evaluation episodes, the same ones for every iteration
                sync_envs_normalization(train_env, eval_env)
                evaluation.rewind()
                returns, _ = evaluate_policy(model, eval_env, n_eval_episodes=int(config["eval"]["episodes"]),
                                             deterministic=True, return_episode_rewards=True)
                return float(np.mean(returns))

            teacher = distil(config, model, train_env, verbose=verbose, judge=judge)
        if teacher is not None:  # the distilled policy is the result (no PPO steps follow); judged on the same episodes
            teacher["eval_mean_return"] = _evaluate_as_best(model, train_env, evaluation, out / "best",
                                                            policy_info(model, clock, description), checks)
        if worker is not None:
            model.rollout_worker = worker
        ppo_started = time.perf_counter()
        time_split = TimeSplit(venv)  # wrappers pass step_time_s on from the env (and a residual's base) that count it
        periodic = PeriodicCheckpoint(out / "checkpoints", int(config["checkpoint_freq"]), description, clock, checks,
                                      every_s=60.0 * float(config["checkpoint_minutes"]), on_save=on_checkpoint)
        threads = TorchThreads(rollout=config["rollout_torch_threads"], update=config["torch_threads"],
                               n_envs=int(config["n_envs"]), most=most_threads)
        callbacks = [threads, time_split, evaluation, CollisionLog(), periodic]
        if progress_bar:
            callbacks.append(ProgressBar(target_steps, initial=start_steps))

        try:
            if target_steps > start_steps:
                with _unchecked_distributions():
                    model.learn(total_timesteps=target_steps - start_steps, callback=CallbackList(callbacks),
                                reset_num_timesteps=not resume, tb_log_name="ppo", progress_bar=False)
            if 0 <= _last_evaluated(evaluation) < int(model.num_timesteps):
                # the steps after the last evaluation (the learning rate lowest there) were never judged: the final
                # model is a candidate for best/ on the same episodes, kept only if it beats the best so far (a run
                # that evaluated nothing keeps its final model as best/ unjudged, below); stopped here, the resumed
                # run judges it
                _evaluate_as_best(model, train_env, evaluation, out / "best", policy_info(model, clock, description),
                                  checks, only_if_better=True)
        except (KeyboardInterrupt, Exception) as exc:
            if not interrupts.is_interrupt(exc):  # a real error; one raised after Ctrl-C is the interrupt's
                raise
            saved = periodic.save()  # model, statistics, step count and wall time: all --resume needs
            raise TrainingInterrupted(out, saved, int(model.num_timesteps)) from None
        ppo_time = time.perf_counter() - ppo_started
        run_time = clock.this_run_s
        total_time = clock.total_s
        save_checkpoint(out, model, train_env, {**description, "num_timesteps": int(model.num_timesteps),
                                                "wall_time_s": round(total_time, 3)}, checks)
    finally:
        if worker is not None:
            worker.close()
        venv.close()
        if eval_env is not None:
            eval_env.close()
    if worker is not None:
        model.rollout_worker = None  # the model goes on alone (a later learn() collects in this process)

    if not (out / "best" / "policy.json").is_file():  # no evaluation ran: the final model is the best we have
        from agents.checkpoints import copy_checkpoint

        copy_checkpoint(out, out / "best")

    steps_this_run = int(model.num_timesteps) - start_steps
    card = model_card(config, out / "best", command=command, training={
        "total_timesteps": int(model.num_timesteps),
        "timesteps_this_run": steps_this_run,
        "wall_time_s": round(run_time, 2),
        "total_wall_time_s": round(total_time, 2),
        "steps_per_s": round(steps_this_run / max(run_time, 1e-9), 1),
        "time_split": time_split.split() if steps_this_run else None,
        "threads": {"at_start": start_threads.as_dict(), **threads.report()},
        **({"teacher": teacher} if teacher is not None else {}),
        **({"warm_start": {**warm, "ppo_wall_time_s": round(ppo_time, 2)}} if warm is not None else {}),
        "n_envs": config["n_envs"],
        "vector": vector_kind(config),
        "rollout_worker": worker is not None,
        "n_workers": config["n_workers"] if vector_kind(config) == "subprocess" else 0,
        "seed": config["seed"],
        "resumed": bool(resume),
        "machine": _machine(),
        "versions": _versions(),
        "git_commit": git["commit"] if git else None,
        "git_uncommitted": git["uncommitted"] if git else None,  # files that differed from that commit
    })
    curve_file = out / "eval" / "evaluations.npz"
    if curve_file.is_file():  # the evaluation callback's history: [env steps, mean return, mean length (steps)]
        history = np.load(curve_file)
        card["training"]["eval_curve"] = [[int(t), round(float(np.mean(r)), 2), round(float(np.mean(n)), 1)] for t, r, n
                                          in zip(history["timesteps"], history["results"], history["ep_lengths"])]
    # the whole command: worker start-up, training, final evaluation (resumed runs: this part only)
    card["training"]["command_wall_time_s"] = round(time.perf_counter() - started, 2)
    write_model_card(out, card)
    return TrainingRun(card, model, train_env, out)


def warm_start_from_controller(config: dict[str, Any], model: Any, normalizer: Any, verbose: int = 1) -> dict[str, Any]:
    """Warm-start ``model`` (and ``normalizer``, its training ``VecNormalize``) from demonstrations of
    ``config["warm_start"]["controller"]`` (see :mod:`agents.behaviour_cloning`); the report for the card."""
    from agents.behaviour_cloning import warm_start
    from agents.demonstrations import record_demonstrations
    from agents.envs import make_vec_env
    from agents.residual import make_base_controller

    settings = config["warm_start"]
    name = settings["controller"]
    demo_venv = make_vec_env(config, int(settings["demo_envs"]), vector="batched")
    try:
        controller = make_base_controller(name, demo_venv, **base_controller_kwargs(config, name))
        first_seed = int(settings["seed"]) + int(config["seed"]) * int(settings["demo_envs"])
        demos = record_demonstrations(demo_venv, controller, int(settings["demo_steps"]), noise=float(settings["noise"]),
                                      seed=first_seed)
    finally:
        demo_venv.close()
    if verbose:
        print(f"warm start: {name} flew {demos.n_samples} env steps of demonstrations in {demos.wall_time_s:.1f} s",
              file=sys.stderr)
    cloning = warm_start(model, normalizer, demos, epochs=int(settings["epochs"]),
                         batch_size=int(settings["batch_size"]), learning_rate=float(settings["learning_rate"]),
                         seed=int(config["seed"]))
    if verbose:
        print(f"warm start: cloned in {cloning['wall_time_s']:.1f} s, RMS action error on held-out flights "
              f"{cloning.get('heldout_action_rmse', float('nan')):.4f}", file=sys.stderr)
    return {"controller": name, "demo_seeds": [first_seed, first_seed + int(settings["demo_envs"]) - 1],
            "demo_env_steps": demos.n_samples, "demo_wall_time_s": round(demos.wall_time_s, 2),
            "demo_steps_per_s": round(demos.n_samples / max(demos.wall_time_s, 1e-9), 1),
            "controller_failures": int(getattr(controller, "failures", 0)), "cloning": cloning}


def _last_evaluated(evaluation: Any) -> int:
    """The env step of ``evaluation``'s (an ``EvalCallback``'s) last evaluation, -1 before the first."""
    return int(evaluation.evaluations_timesteps[-1]) if evaluation.evaluations_timesteps else -1


def _evaluate_as_best(model: Any, train_env: Any, evaluation: SameEpisodesEval, folder: Path, info: dict[str, Any],
                      checks: np.ndarray, only_if_better: bool = False) -> float:
    """Evaluate ``model`` as ``evaluation`` (an ``EvalCallback``) would, on its episodes, record it in its history
    (and its file) and save it as the best checkpoint: always, or with ``only_if_better`` only if its mean
    return beats the best so far; its mean return."""
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import sync_envs_normalization

    from agents.checkpoints import save_checkpoint

    sync_envs_normalization(train_env, evaluation.eval_env)
    evaluation.rewind()
    returns, lengths = evaluate_policy(model, evaluation.eval_env, n_eval_episodes=evaluation.n_eval_episodes,
                                       deterministic=True, return_episode_rewards=True)
    assert isinstance(returns, list) and isinstance(lengths, list)  # per-episode lists with return_episode_rewards
    mean = float(np.mean(returns))
    evaluation.evaluations_timesteps.append(int(model.num_timesteps))
    evaluation.evaluations_results.append([float(r) for r in returns])
    evaluation.evaluations_length.append([int(n) for n in lengths])
    if evaluation.log_path is not None:  # as EvalCallback keeps its history file (it makes the folder only once learning starts)
        Path(evaluation.log_path).parent.mkdir(parents=True, exist_ok=True)
        np.savez(evaluation.log_path, timesteps=evaluation.evaluations_timesteps,
                 results=evaluation.evaluations_results, ep_lengths=evaluation.evaluations_length)
    better = mean > float(evaluation.best_mean_reward)
    evaluation.best_mean_reward = max(float(evaluation.best_mean_reward), mean)
    if better or not only_if_better:
        save_checkpoint(folder, model, train_env, {**info, "eval_mean_return": mean}, checks)
    return mean


def model_card(config: dict[str, Any], checkpoint: Path, *, command: str | None, training: dict[str, Any]) -> dict[str, Any]:
    """Evaluate ``checkpoint`` on the task's nominal settings and assemble the model card."""
    from agents.envs import env_kwargs
    from agents.evaluate import evaluate_agent
    from agents.policy import policy_factory

    kwargs = env_kwargs(config, randomize=False)
    seeds = range(int(config["card_eval"]["seed"]), int(config["card_eval"]["seed"]) + int(config["card_eval"]["episodes"]))
    metrics = evaluate_agent(policy_factory(checkpoint), config["env_id"], kwargs, seeds)
    info = json.loads((checkpoint / "policy.json").read_text())
    policy = config["policy"]
    mlp = "x".join(map(str, policy["net_arch"])) + (
        f", critic {'x'.join(map(str, policy['critic_arch']))}" if policy["critic_arch"] else "")
    return {
        "env_id": config["env_id"],
        "summary": (f"{config['teacher']['controller'].upper().replace('SCMPC', 'SC-MPC')} distilled DAgger-style into "
                    f"an MLP {mlp} (saved as a Stable-Baselines3 PPO "
                    "model; it learned from a teacher, not alone), flying the task directly."
                    if config.get("algo") == "dagger" else
                    f"PPO (Stable-Baselines3, MLP {mlp}) "
                    + (f"learning a residual correction on top of {config['residual']}" if config["residual"]
                       else "flying the task directly (collective thrust and body rates)")
                    + (f", warm-started by behaviour cloning of {config['warm_start']['controller']}"
                       if config["warm_start"]["controller"] else "") + "."),
        "command": command or "(trained through the Python API: agents.train.train)",
        "checkpoint": f"{checkpoint.name}/ at {info.get('num_timesteps')} timesteps " + (
            f"(best mean evaluation return {info['eval_mean_return']:.1f})"
            if np.isfinite(info.get("eval_mean_return", np.nan))
            else "(the final model: no evaluation ran during training)"),
        "residual": config["residual"],
        "randomize": {k: list(v) for k, v in config["randomize_ranges"].items()} if config["randomize"] else None,
        "conditions": config["env_kwargs"].get("conditions"),  # the flight conditions trained in (scaled per episode)
        "history": config.get("history"),
        "training": training,
        "evaluation": {
            "scenario": (f"controllers.evaluation.evaluate (the function of the comparison tables): {len(seeds)} "
                         f"episodes, seeds {seeds.start}..{seeds.stop - 1}, deterministic actions, "
                         f"gym.make({config['env_id']!r}, **{kwargs!r}) (task defaults: k_s 4.1 N/m, d_thr 0.132 m, "
                         "command noise on, unless set here)."),
            "env_kwargs": kwargs,
            "seeds": list(seeds),
            "metrics": metrics,
        },
        "config": config,
    }


def ship(run_dir: Path, task: str, residual: str | None = None, warm_start: str | None = None,
         teacher: str | None = None) -> Path:
    """Copy ``run_dir/best`` and the run's model card into ``agents/pretrained/<task>/``
    (``<task>_residual_<base>/`` for a residual agent, ``<task>_warm_start_<controller>/`` for one
    started from a controller's demonstrations, ``<task>_teacher_<controller>/`` for one distilled from a
    controller (``--algo dagger``), where ``policy_factory(variant=...)`` looks).

    A warm-started agent has its own folder: it learned from the controller it is compared with,
    so it never takes the place of the agent that learned the task alone (the comparison's PPO)."""
    from agents.checkpoints import copy_checkpoint
    from agents.learning_curve import LEARNING_CURVE_PNG
    from agents.policy import pretrained_path

    variant = (f"residual_{residual}" if residual else f"warm_start_{warm_start}" if warm_start
               else f"teacher_{teacher}" if teacher else "")
    target = pretrained_path(task, variant)
    copy_checkpoint(run_dir / "best", target)
    for name in ("model_card.json", "model_card.md", LEARNING_CURVE_PNG):
        if (run_dir / name).is_file():
            (target / name).write_bytes((run_dir / name).read_bytes())
        else:
            (target / name).unlink(missing_ok=True)  # no stale picture of another run
    return target
