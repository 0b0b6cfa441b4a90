"""The simulator's state vector, entry by entry (one definition for the dynamics, the envs and the conditions).

``x`` (17 numbers): ``p_world`` (3, m), ``q_body_to_world`` (4, [w, x, y, z]),
``v_world`` (3, m/s), ``omega_body`` (3, rad/s), ``rotor_thrusts`` (4, N).
"""

from __future__ import annotations

__all__ = ["STATE_SIZE", "StateIndex"]

STATE_SIZE = 17


class StateIndex:
    """Slices of the simulator state vector."""

    p_world = slice(0, 3)
    q_body_to_world = slice(3, 7)
    v_world = slice(7, 10)
    omega_body = slice(10, 13)
    rotor_thrusts = slice(13, 17)
