"""Set-up shared by every test: an SB3 algorithm a test builds without a logger of its own logs into this session's
temporary folder (``SB3_LOGDIR``), not into a new empty ``SB3-<time>`` folder in the system's temp dir per ``learn``."""

from __future__ import annotations

import os

import pytest


@pytest.fixture(autouse=True, scope="session")
def _sb3_logs_in_the_sessions_folder(tmp_path_factory):
    previous = os.environ.get("SB3_LOGDIR")
    os.environ["SB3_LOGDIR"] = str(tmp_path_factory.mktemp("sb3-logs"))
    yield
    if previous is None:
        os.environ.pop("SB3_LOGDIR", None)
    else:
        os.environ["SB3_LOGDIR"] = previous
