"""A run folder belongs to one run: a lock taken when a command starts writing into it.

``train``, ``tune``, ``compare``, ``robustness``, ``discover`` and ``fly`` write several files
into one folder over minutes; two of them writing into the same folder at once would mix
their files (the second run's config beside the first run's model). :class:`RunLock` holds
an exclusive ``flock`` on a lock file of the folder for as long as the run lasts and writes
into it who holds it (command, process id, host, start time). The lock file lives in this
machine's cache (``$WALL_INSPECTOR_CACHE/locks/``, named by the folder's resolved path), not in
the folder, whose files stay the run's own; so the lock guards runs on one machine. A second run into the
folder finds the lock held and refuses with :class:`RunFolderBusy`, whose message names the
running one. The kernel releases the ``flock`` when the holding process ends, however it
ends (Ctrl-C, a crash, SIGKILL), so a lock left by a dead process is taken over at once, with
a ``stale_holder`` note of whom it belonged to.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
from pathlib import Path
from typing import Any

__all__ = ["RunLock", "RunFolderBusy", "lock_path"]


class RunFolderBusy(RuntimeError):
    """Another run holds the folder's lock."""


def lock_path(folder: str | Path) -> Path:
    """The lock file of run folder ``folder`` (in this machine's cache, one per resolved path)."""
    import hashlib

    from wall_env.codegen import cache_dir

    key = hashlib.sha256(str(Path(folder).resolve()).encode()).hexdigest()[:24]
    locks = cache_dir() / "locks"
    locks.mkdir(parents=True, exist_ok=True)
    return locks / f"{key}.lock"


class RunLock:
    """An exclusive lock on a run folder (created if missing); use as a context manager or call
    :meth:`acquire` and :meth:`release`."""

    def __init__(self, folder: str | Path, command: str):
        self.folder = Path(folder)
        self.command = command
        self.path = lock_path(self.folder)
        self.stale_holder: dict[str, Any] | None = None  # who held it before, if that process had died
        self._fd: int | None = None

    def acquire(self) -> RunLock:
        import fcntl

        if self._fd is not None:
            return self  # already held by this object (``with wall_inspector.cli.lock_run_folder(...)`` enters an acquired lock)
        self.folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = _read_holder(fd)
            os.close(fd)
            who = (f"'{holder.get('command', '?')}' (pid {holder.get('pid', '?')} on {holder.get('host', '?')}, "
                   f"started {holder.get('started', '?')})") if holder else "another run"
            raise RunFolderBusy(f"{self.folder} is in use by {who}; wait for it to end or choose another folder") from None
        previous = _read_holder(fd)
        if previous and previous.get("pid") != os.getpid():
            self.stale_holder = previous  # its process ended without releasing: the kernel released the flock
        record = {"command": self.command, "pid": os.getpid(), "host": socket.gethostname(),
                  "started": time.strftime("%Y-%m-%d %H:%M:%S")}
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(record) + "\n").encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is None:
            return
        import fcntl

        with contextlib.suppress(OSError):
            os.ftruncate(self._fd, 0)  # nobody holds it now
        fcntl.flock(self._fd, fcntl.LOCK_UN)
        os.close(self._fd)
        self._fd = None

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


def _read_holder(fd: int) -> dict[str, Any] | None:
    try:
        text = os.pread(fd, 4096, 0).decode(errors="replace").strip()
        data = json.loads(text) if text else None
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None
