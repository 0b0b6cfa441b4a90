"""The observation vector, element by element.

All quantities are SI and in the frame their name gives. ``float32``, 48 entries:

==================  =========  ============================================================
name                indices    meaning
==================  =========  ============================================================
p_world             0-2        position of the centre of mass (m)
v_world             3-5        velocity (m/s)
R_body_to_world     6-14       rotation matrix, row-major
omega_body          15-17      body rates (rad/s)
p_error             18-20      p_world - p_ref(t) (m)
v_error             21-23      v_world - v_ref(t) (m/s)
reference_preview   24-35      p_ref(t + k * 0.05 s) - p_ref(t) for k = 1..4 (m)
rotor_clearance     36-39      each rotor centre's distance to its nearest wall, capped at 1 m
wall_normal         40-42      outward normal of the wall nearest to any rotor (zeros if none)
previous_action     43-46      the normalised action of the previous step (zeros after reset)
time                47         seconds since reset
==================  =========  ============================================================

In a scene with bodies (:mod:`wall_env.bodies`) a body's surface counts as a wall: the
clearance is the distance to the nearest wall plane or body surface (PyBullet's query,
:mod:`wall_env.surfaces`), capped at the query's reach (``d_thr`` + 5 cm, see
:attr:`wall_env.config.EnvConfig.surface_reach`) instead of 1 m, and the normal is that
surface's.
"""

from __future__ import annotations

import numpy as np

__all__ = ["observation_bounds", "OBSERVATION_FIELDS", "OBSERVATION_SIZE", "PREVIEW_STEPS", "PREVIEW_DT", "CLEARANCE_CAP",
           "parse_observation"]

PREVIEW_STEPS = 4
PREVIEW_DT = 0.05  # s
CLEARANCE_CAP = 1.0  # m

# name, size, bound: the observation space is [-bound, bound] per entry (time: [0, bound],
# clearance: [-bound, CLEARANCE_CAP]); values beyond these mean the flight has gone wrong.
_LAYOUT = (
    ("p_world", 3, 1e3),
    ("v_world", 3, 1e2),
    ("R_body_to_world", 9, 1.0),
    ("omega_body", 3, 1e2),
    ("p_error", 3, 1e3),
    ("v_error", 3, 1e2),
    ("reference_preview", 3 * PREVIEW_STEPS, 1e2),
    ("rotor_clearance", 4, 1.0),
    ("wall_normal", 3, 1.0),
    ("previous_action", 4, 1.0),
    ("time", 1, 1e5),
)
OBSERVATION_FIELDS: dict[str, slice] = {}
_index = 0
for _name, _size, _ in _LAYOUT:
    OBSERVATION_FIELDS[_name] = slice(_index, _index + _size)
    _index += _size
OBSERVATION_SIZE = _index


def observation_bounds() -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of the observation space, float32."""
    high = np.concatenate([np.full(size, bound) for _, size, bound in _LAYOUT])
    low = -high
    low[OBSERVATION_FIELDS["time"]] = 0.0
    high[OBSERVATION_FIELDS["rotor_clearance"]] = CLEARANCE_CAP
    return low.astype(np.float32), high.astype(np.float32)


def parse_observation(observation: np.ndarray) -> dict[str, np.ndarray]:
    """Named views of one observation ``(48,)`` or a batch ``(n, 48)``, as float64.

    ``R_body_to_world`` comes back as ``(..., 3, 3)``, ``reference_preview`` as
    ``(..., 4, 3)`` and ``time`` as ``(...,)``.
    """
    obs = np.asarray(observation, dtype=float)
    if obs.shape[-1] != OBSERVATION_SIZE:
        raise ValueError(f"observation must have {OBSERVATION_SIZE} entries in its last axis, got shape {obs.shape}")
    out = {name: obs[..., s] for name, s in OBSERVATION_FIELDS.items()}
    out["R_body_to_world"] = out["R_body_to_world"].reshape(*obs.shape[:-1], 3, 3)
    out["reference_preview"] = out["reference_preview"].reshape(*obs.shape[:-1], PREVIEW_STEPS, 3)
    out["time"] = out["time"][..., 0]
    return out
