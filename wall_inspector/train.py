"""``wall-inspector train``: the training command of :mod:`agents.train`, and ``--ray`` for several runs at once.

Without ``--ray`` this is :func:`agents.train.run` unchanged. With ``--ray [ADDRESS]``
each training run is a Ray Tune trial (:mod:`wall_inspector.train_on_ray`): one per seed
of ``--seeds 0-9``, one per point of the grid of ``--sweep SPACE.yaml``, or both crossed.
"""

from __future__ import annotations

import argparse

from agents import train as agents_train


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from wall_inspector import ray_backend

    agents_train.add_arguments(parser)
    ray_backend.add_arguments(parser, "each training run is a Ray Tune trial that resumes from its last checkpoint "
                                      "if its worker dies")
    parser.add_argument("--seeds", default=None, metavar="SEEDS",
                        help="with --ray: one run per seed, e.g. 0-9 or 0,3,7")
    parser.add_argument("--sweep", default=None, metavar="SPACE.yaml",
                        help="with --ray: one run per point of the grid in this YAML file (configuration keys as in "
                             "--set, each with a list of values), e.g. {ppo.learning_rate: [1.0e-4, 3.0e-4]}")
    parser.add_argument("--cpus-per-trial", type=float, default=None,
                        help="with --ray: CPUs Ray reserves for each run, and the most PyTorch threads it takes (default: "
                             "n_workers with --vector subprocess, else the more of torch_threads and rollout_torch_threads "
                             "when set, 1 when they are auto)")
    parser.add_argument("--max-failures", type=int, default=3,
                        help="with --ray: times a run is restarted from its last checkpoint after its worker died "
                             "(default 3)")


def run(args: argparse.Namespace) -> int:
    if args.ray is None:
        for flag, value in (("--seeds", args.seeds), ("--sweep", args.sweep), ("--ray-cpus", args.ray_cpus),
                            ("--cpus-per-trial", args.cpus_per_trial)):
            if value is not None:
                raise SystemExit(f"{flag} needs --ray (several runs as Ray Tune trials)")
        return agents_train.run(args)
    from wall_inspector import train_on_ray

    return train_on_ray.run(args)
