"""Frame conversions between PX4's conventions and the project's.

PX4 writes positions and velocities in a local NED world frame (x north, y east, z
down) and attitudes and body rates in an FRD body frame (x forward, y right, z down).
The project uses a z-up world frame and a z-up FLU body frame (x forward, y left, z
up); the importers choose ENU for the world (x east, y north, z up, the ROS REP 103
convention, so PX4 and ROS logs of one vehicle land in the same frame):

    p_enu = T_ned_to_enu p_ned,    T_ned_to_enu = [[0, 1, 0], [1, 0, 0], [0, 0, -1]]
    R_flu_to_enu = T_ned_to_enu R_frd_to_ned T_flu_to_frd,    T_flu_to_frd = diag(1, -1, -1)
    omega_flu = T_flu_to_frd omega_frd

Both ``T`` matrices are their own inverses. Quaternions are scalar first, ``[w, x, y, z]``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["T_NED_TO_ENU", "T_FLU_TO_FRD", "ned_to_enu", "frd_to_flu", "attitude_frd_ned_to_flu_enu"]

T_NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
T_FLU_TO_FRD = np.diag([1.0, -1.0, -1.0])


def ned_to_enu(vectors_ned: np.ndarray) -> np.ndarray:
    """World vectors ``(n, 3)`` (positions, velocities, accelerations) from NED to ENU."""
    return np.asarray(vectors_ned, dtype=float) @ T_NED_TO_ENU.T


def frd_to_flu(vectors_frd: np.ndarray) -> np.ndarray:
    """Body vectors ``(n, 3)`` (body rates, body forces) from FRD to FLU."""
    return np.asarray(vectors_frd, dtype=float) @ T_FLU_TO_FRD.T


def attitude_frd_ned_to_flu_enu(q_frd_to_ned: np.ndarray) -> np.ndarray:
    """Body-to-world quaternions ``(n, 4)`` [w, x, y, z]: PX4's FRD-to-NED to the project's FLU-to-ENU.

    The result is normalised and has a non-negative scalar part.
    """
    q = np.asarray(q_frd_to_ned, dtype=float).reshape(-1, 4)
    R_frd_to_ned = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    R_flu_to_enu = T_NED_TO_ENU @ R_frd_to_ned @ T_FLU_TO_FRD
    xyzw = Rotation.from_matrix(R_flu_to_enu).as_quat()
    wxyz = xyzw[:, [3, 0, 1, 2]]
    return wxyz * np.where(wxyz[:, :1] < 0, -1.0, 1.0)
