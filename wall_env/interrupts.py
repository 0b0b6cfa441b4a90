"""Ctrl-C that native code cannot lose.

A SIGINT that arrives while a native library holds the thread (CasADi building or generating
a function) reaches Python's handler inside that library's own call back into the
interpreter, and the library may swallow the ``KeyboardInterrupt`` it raises: the command
then runs to its end as if never interrupted. :func:`install` (the command line calls it)
makes SIGINT also set :data:`requested`, and the long loops call :func:`check` between
steps, which raises ``KeyboardInterrupt`` once one was asked for, whatever swallowed it.
A library may also turn the ``KeyboardInterrupt`` into an error of its own (CasADi's SWIG
layer, interrupted while it converts an argument, reports "Wrong number or type of
arguments"): :func:`is_interrupt` tells such an error, raised after a Ctrl-C, from a real one.
"""

from __future__ import annotations

import signal
import threading
from typing import Any

__all__ = ["requested", "install", "check", "is_interrupt"]

requested = threading.Event()


def _on_interrupt(signum: int, frame: Any) -> None:
    requested.set()
    raise KeyboardInterrupt


def install() -> None:
    """SIGINT sets :data:`requested` and raises ``KeyboardInterrupt`` (from the main thread only)."""
    if threading.current_thread() is threading.main_thread():
        requested.clear()
        signal.signal(signal.SIGINT, _on_interrupt)


def check() -> None:
    """Raise ``KeyboardInterrupt`` if Ctrl-C was pressed since :func:`install`, even if it was swallowed."""
    if requested.is_set():
        raise KeyboardInterrupt


def is_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is, or stands for, a Ctrl-C: a ``KeyboardInterrupt``, or any error raised once Ctrl-C was
    pressed since :func:`install` (native code that the signal interrupted may report it as another error)."""
    return isinstance(exc, KeyboardInterrupt) or (isinstance(exc, Exception) and requested.is_set())
