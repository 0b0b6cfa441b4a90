"""Open-loop prediction error: replay the logged commands through a model and compare positions.

From the state logged at a window's start, the translational model (paper Eq. 5)

    m dv/dt = -m g e3 + T R e3 + F_M(p, R, v, omega, f)

is integrated over a fixed horizon (default 0.5 s) with the logged collective thrust
command held over each sample step, and ``F_M`` the :class:`~wall_env.aero.AeroModel`
force evaluated at the *predicted* position and velocity (so an effect that depends
on where the vehicle is, such as wall suction, acts where the model thinks the
vehicle is). The attitude follows the logged attitude (the body-rate loop is the
vehicle's and not part of the aerodynamic model; integrating the noisy rate commands
would add an attitude random walk common to every model). The error is the distance
between predicted and logged position at the end of the horizon; its RMS over all
windows is ``prediction_rms_m``.

Windows start every ``stride_s`` seconds and are evaluated with the model fitted
without the cross-validation fold of their start sample; a window that would leave
its fold's time block is not used, so every prediction is of data the model was
not fitted to. The start position and velocity are the logged ones smoothed over 0.5 s
(the 1 s window of the force residual would lag where the acceleration changes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from discovery.aero_eval import SampleStates
from discovery.residuals import FlightData, Segment
from wall_env.aero import AeroModel

__all__ = ["PredictionWindows", "windows", "predict", "prediction_pairs", "prediction_errors", "DEFAULT_HORIZON_S",
           "DEFAULT_STRIDE_S"]

DEFAULT_HORIZON_S = 0.5
DEFAULT_STRIDE_S = 0.1


@dataclass
class PredictionWindows:
    """Start indices of prediction windows in one segment, with their fold and length in samples."""

    segment: int
    starts: np.ndarray  # (w,) sample index of each start
    steps: int  # samples to the horizon
    fold: np.ndarray  # (w,) fold of each window


def windows(data: FlightData, horizon_s: float = DEFAULT_HORIZON_S,
            stride_s: float = DEFAULT_STRIDE_S) -> list[PredictionWindows]:
    """Prediction windows of every segment that stay inside one fold's time block."""
    out = []
    for index, seg in enumerate(data.segments):
        dt = float(np.median(np.diff(seg.t)))
        steps = int(round(horizon_s / dt))
        stride = max(1, int(round(stride_s / dt)))
        if seg.n <= steps + 1:
            continue
        starts = np.arange(0, seg.n - steps - 1, stride)
        same_fold = seg.fold[starts] == seg.fold[starts + steps]
        # a window may not straddle two blocks of the same fold either: check the time span
        contiguous = np.array([np.all(seg.fold[s:s + steps + 1] == seg.fold[s]) for s in starts], dtype=bool)
        keep = same_fold & contiguous
        if keep.any():
            out.append(PredictionWindows(index, starts[keep], steps, seg.fold[starts[keep]]))
    return out


def predict(seg: Segment, starts: np.ndarray, steps: int, model: AeroModel, rotor_positions_body: np.ndarray,
            theta: np.ndarray | None = None, thrust_map: np.ndarray | None = None) -> np.ndarray:
    """Predicted positions ``(w, 3)`` at ``steps`` samples after each start, replaying the logged thrust.

    ``theta``: the model's parameters, ``(param_size,)`` or one row per window (default: the model's own);
    ``thrust_map``: an affine thrust map ``(scale, offset)`` (or one row per window) applied to the replayed
    thrust (:mod:`discovery.thrust_map`).
    """
    theta = model.theta() if theta is None else np.asarray(theta, dtype=float)
    evaluator = seg.evaluator(model, rotor_positions_body) if model.effects else None
    m = seg.states.mass
    g = np.array([0.0, 0.0, seg.gravity])
    assert seg.p_start is not None and seg.v_start is not None, "segment without prediction starts"
    p = seg.p_start[starts].copy()
    v = seg.v_start[starts].copy()
    R_all, w_all, f_all = seg.states.R_body_to_world, seg.states.omega_body, seg.states.rotor_thrusts
    for j in range(steps):
        k = starts + j
        dt = (seg.t[k + 1] - seg.t[k])[:, None]
        z_body = 0.5 * (R_all[k, :, 2] + R_all[k + 1, :, 2])
        thrust = seg.thrust[k]
        if thrust_map is not None:
            scale, offset = np.atleast_2d(thrust_map).T
            thrust = scale * thrust + offset
        force = thrust[:, None] * z_body
        if evaluator is not None:
            states = SampleStates(p, R_all[k], v, w_all[k], f_all[k], m)
            force = force + evaluator.force(states, theta)
        a = force / m - g
        p = p + dt * v + 0.5 * dt**2 * a
        v = v + dt * a
    return p


def prediction_pairs(data: FlightData, model: AeroModel,
                     fold_theta: list[np.ndarray] | dict[int, list[np.ndarray]] | None = None,
                     horizon_s: float = DEFAULT_HORIZON_S, stride_s: float = DEFAULT_STRIDE_S,
                     thrust_maps: dict[int, list[np.ndarray]] | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Start, predicted and logged positions ``(w, 3)`` at the horizon of every held-out window.

    ``model`` gives the structure; ``fold_theta[k]`` its parameters fitted without fold
    ``k`` (default: the model's own parameters for every fold), or ``fold_theta[f][k]`` per
    flight ``f`` when flights have their own conditions; ``thrust_maps[f][k]`` an affine thrust
    map ``(scale, offset)`` per flight and fold.
    """
    starts, predicted, measured = [], [], []
    for w in windows(data, horizon_s, stride_s):
        seg = data.segments[w.segment]
        theta = None
        if fold_theta is not None and model.param_size:
            per_fold = fold_theta[seg.flight] if isinstance(fold_theta, dict) else fold_theta
            theta = np.stack([per_fold[k] for k in w.fold])
        thrust_map = None
        if thrust_maps is not None:
            thrust_map = np.stack([thrust_maps[seg.flight][k] for k in w.fold])
        predicted.append(predict(seg, w.starts, w.steps, model, data.rotor_positions_body, theta, thrust_map))
        assert seg.p_measured is not None, "segment without logged positions"
        measured.append(seg.p_measured[w.starts + w.steps])
        starts.append(seg.p_measured[w.starts])
    if not predicted:
        empty = np.zeros((0, 3))
        return empty, empty, empty
    return np.concatenate(starts), np.concatenate(predicted), np.concatenate(measured)


def prediction_errors(data: FlightData, model: AeroModel, fold_theta: list[np.ndarray] | None = None,
                      horizon_s: float = DEFAULT_HORIZON_S, stride_s: float = DEFAULT_STRIDE_S) -> np.ndarray:
    """Position errors (m) at the horizon of every held-out window (see :func:`prediction_pairs`)."""
    _, predicted, measured = prediction_pairs(data, model, fold_theta, horizon_s, stride_s)
    return np.linalg.norm(predicted - measured, axis=1)
