"""PyBullet, imported and connected quietly: the one place the project's modules get a PyBullet client from.

PyBullet's C code prints its build time on import and its arguments on connect; both are
silenced here. :func:`connect` gives a headless (``DIRECT``) or windowed (``GUI``) client.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
from collections.abc import Iterator

__all__ = ["pybullet", "BulletClient", "quiet_native_output", "connect"]


@contextlib.contextmanager
def quiet_native_output() -> Iterator[None]:
    """Silence what PyBullet's C code prints on import and connect (build time, argv)."""
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = [os.dup(1), os.dup(2)]
    except (OSError, ValueError):  # no real file descriptors (some notebook kernels): nothing to silence
        yield
        return
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
            os.dup2(devnull.fileno(), 2)
            yield
            ctypes.CDLL(None).fflush(None)  # C stdio buffers, or the text would appear at exit
    finally:
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)


with quiet_native_output():
    import pybullet
    from pybullet_utils.bullet_client import BulletClient



def connect(gui: bool = False) -> BulletClient:
    """A new PyBullet client: ``DIRECT`` (no display needed) or ``GUI``."""
    with quiet_native_output():
        return BulletClient(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
