"""``--ray [ADDRESS]``: run a command's flights or trials on Ray, on this machine or on a cluster.

``--ray`` alone starts an embedded Ray on this machine (``ray.init()``; ``--ray-cpus N``
limits it to N CPUs); ``--ray auto`` joins the cluster this machine belongs to (started
with ``ray start``) and ``--ray HOST:PORT`` (or ``ray://HOST:10001``) the one at that
address. Ray is an optional extra (``pip install "wall-inspector[ray]"``): nothing
imports it unless ``--ray`` is given.

Every machine of a cluster needs this package installed the same way (same Python and
versions): Ray ships the work (a flight, a trial) by reference to this package's
functions, not the code itself.

Ray runs its workers at nice 15 by default, which starves them on a machine busy with
other work; the embedded Ray runs them at the command's own priority (nice 0). On a
cluster that is ``ray start``'s business: ``RAY_worker_niceness=0 ray start ...``.

Resource hints: a flight task asks for :data:`CPUS_PER_FLIGHT` CPU (a flight is one
single-threaded process: env, controller, and PyTorch inference for PPO, which Ray
limits to one thread per CPU asked for), a tuning trial for ``--cpus-per-trial`` (1 by
default, for the same reason), so Ray never schedules more of them on a node than it
has CPUs.
"""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Callable, Iterator, Sequence
from typing import Any

LOCAL = "local"  # the value of a bare --ray: an embedded Ray on this machine
CPUS_PER_FLIGHT = 1.0
FLIGHT_RETRIES = 3  # a flight whose worker died is flown again from its start (flights are short)

INSTALL_HINT = 'pip install "wall-inspector[ray]"'


def add_arguments(parser: argparse.ArgumentParser, what: str) -> None:
    """``--ray [ADDRESS]`` and ``--ray-cpus N`` (``what``: the units Ray runs, e.g. "every flight is a Ray task")."""
    parser.add_argument("--ray", nargs="?", const=LOCAL, default=None, metavar="ADDRESS",
                        help=f"run on Ray ({what}): alone, an embedded Ray on this machine; 'auto' or HOST:PORT "
                             f"joins a running cluster (needs {INSTALL_HINT})")
    parser.add_argument("--ray-cpus", type=int, default=None, metavar="N",
                        help="CPUs of the embedded Ray of a bare --ray (default: all of this machine's)")


def check_arguments(args: argparse.Namespace) -> None:
    """``ValueError`` (a usage error) for ``--ray`` options that cannot work; before any work starts."""
    address, cpus = getattr(args, "ray", None), getattr(args, "ray_cpus", None)
    if cpus is not None:
        if address is None:
            raise ValueError("--ray-cpus needs --ray")
        if address != LOCAL:
            raise ValueError("--ray-cpus sets the CPUs of an embedded Ray (a bare --ray); a cluster has its own "
                             "(ray start --num-cpus)")
        if not 1 <= cpus <= 4096:
            raise ValueError(f"--ray-cpus must be in [1, 4096], got {cpus}")
    if address is not None:
        if not address.strip():
            raise ValueError("--ray takes no value (an embedded Ray), 'auto' or a cluster address HOST:PORT")
        try:
            import ray  # noqa: F401
        except ImportError:
            raise ValueError(f"--ray needs Ray: {INSTALL_HINT}") from None


@contextlib.contextmanager
def session(address: str, num_cpus: int | None = None) -> Iterator[Any]:
    """Connect to Ray for the body of the ``with``: an embedded Ray (``address`` :data:`LOCAL`, with
    ``num_cpus``) or the cluster at ``address``; disconnect afterwards (a cluster keeps running).

    If this process is already connected (``ray.init`` called by the caller), that connection is used
    and left open.
    """
    import ray

    if ray.is_initialized():
        yield ray
        return
    if address == LOCAL:
        # Ray starts its workers at nice 15 by default; an embedded Ray is this command's own work, so its
        # workers run at the command's priority, as the flights of a local run do
        ray.init(num_cpus=num_cpus, include_dashboard=False, log_to_driver=False, configure_logging=False,
                 _system_config={"worker_niceness": 0})
    else:
        ray.init(address=address, log_to_driver=False, configure_logging=False)
    try:
        yield ray
    finally:
        ray.shutdown()


def cluster_cpus() -> float:
    """CPUs of the connected Ray cluster (all nodes)."""
    import ray

    return float(ray.cluster_resources().get("CPU", 0.0))


# ---------------------------------------------------------------------- compare: one flight per task
def _timed_fly(flight: Any) -> tuple[Any, float]:
    """Fly one flight; return its record and the seconds the flight took on its worker."""
    import time

    from controllers.paper_tables import fly

    t0 = time.perf_counter()
    record = fly(flight)
    return record, time.perf_counter() - t0


class FlightExecutor:
    """A :data:`controllers.paper_tables.FlightExecutor` that flies every flight as a Ray task.

    The tasks are submitted at once and Ray runs as many as the cluster has CPUs for
    (``cpus_per_flight`` each); the records come back in the order of the flights, whatever
    order they finished in. ``seconds`` holds each flight's time on its worker (the same
    order), for estimates of other cluster sizes (``wall-inspector bench-ray --plan``).
    """

    def __init__(self, cpus_per_flight: float = CPUS_PER_FLIGHT):
        import ray

        self.remote = ray.remote(num_cpus=cpus_per_flight, max_retries=FLIGHT_RETRIES)(_timed_fly)
        self.seconds: list[float] = []

    def __call__(self, flights: Sequence[Any], on_flight: Callable[[], object]) -> list[Any]:
        import ray

        refs = [self.remote.remote(flight) for flight in flights]
        where = {ref: i for i, ref in enumerate(refs)}
        done_records: list[Any] = [None] * len(refs)
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    done_records[where[ref]] = ray.get(ref)
                    on_flight()
        except KeyboardInterrupt:
            for ref in pending:
                ray.cancel(ref, force=True)
            raise
        self.seconds += [float(seconds) for _, seconds in done_records]
        return [record for record, _ in done_records]


def flight_executor(cpus_per_flight: float = CPUS_PER_FLIGHT) -> FlightExecutor:
    """A :class:`FlightExecutor` on the connected Ray cluster."""
    return FlightExecutor(cpus_per_flight)
