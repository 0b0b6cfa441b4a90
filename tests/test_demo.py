"""The demo's pictured flight: SC-MPC (its default, tuned preset) tracks the paper's wall sweep without the swing."""

from __future__ import annotations

import numpy as np

from wall_inspector import demo


def test_the_pictured_sc_mpc_flight_tracks_the_wall_within_8_mm():
    log, frame = demo.fly(demo._policies()["SC-MPC"], seed=0, render=False)
    rmse = float(np.sqrt(np.mean((log["x"] - log["x_ref"]) ** 2)))
    assert frame is None and len(log["time"]) == 1700
    assert rmse <= 0.008 and not log["contact"].any()
