"""What discovery leaves out before fitting: samples something other than the thrust holds up, on the ground or at
the ceiling."""

from __future__ import annotations

import numpy as np

from discovery.coverage import CONTACT_HEIGHT, at_ceiling, ground_contact, resting_on_ground
from discovery.flight_log import FlightLog, NominalVehicle
from wall_env.scene import Scene
from wall_env.vehicle import VehicleParams

RATE_HZ = 100.0
MASS = 1.3
G = 9.81
WEIGHT = MASS * G
LOW_START_S = 2.0  # the thrust drops to 40 % of the weight here


def _thrust(t: np.ndarray, low_s: float, stop: bool) -> np.ndarray:
    """The weight, then 40 % of it for ``low_s``, then (with ``stop``) 160 % of it as long to stop a descent."""
    thrust = np.full(t.shape, WEIGHT)
    thrust[(t >= LOW_START_S) & (t < LOW_START_S + low_s)] = 0.4 * WEIGHT
    if stop:
        thrust[(t >= LOW_START_S + low_s) & (t < LOW_START_S + 2 * low_s)] = 1.6 * WEIGHT
    return thrust


def _log(t: np.ndarray, thrust: np.ndarray, v_z: np.ndarray, p_z: np.ndarray, scene: Scene | None = None
         ) -> FlightLog:
    n = len(t)
    vehicle = NominalVehicle.from_vehicle_params(VehicleParams(mass=MASS))
    p = np.column_stack([np.full(n, 1.0), np.zeros(n), p_z])
    v = np.column_stack([np.zeros(n), np.zeros(n), v_z])
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return FlightLog(t=t, p_world=p, v_world=v, q_body_to_world=q, omega_body=np.zeros((n, 3)), thrust_cmd=thrust,
                     omega_cmd_body=np.zeros((n, 3)), vehicle=vehicle, scene=scene or Scene((), 0.0, None),
                     gravity=G)


def test_a_quick_descent_on_low_thrust_is_flight_and_low_thrust_on_a_stand_is_held_up():
    t = np.arange(int(5.0 * RATE_HZ)) / RATE_HZ
    thrust = _thrust(t, 0.25, stop=True)
    a_z = thrust / MASS - G  # level attitude: the thrust's own vertical acceleration, held over each step
    v_z = np.concatenate([[0.0], np.cumsum(a_z[:-1] / RATE_HZ)])
    p_z = 1.5 + np.concatenate([[0.0], np.cumsum((v_z[:-1] + v_z[1:]) / 2 / RATE_HZ)])
    assert v_z.min() < -1.4  # falling at 0.6 g for a quarter second: 1.47 m/s down
    assert np.allclose(v_z[-1], 0.0, atol=1e-9)  # and stopped again
    in_air = resting_on_ground(_log(t, thrust, v_z, p_z))
    assert not in_air.any(), f"{in_air.sum()} samples of a free descent taken as held up"
    thrust = _thrust(t, 1.0, stop=False)  # a second at 40 % of the weight, not moving: a stand carries the rest
    on_a_stand = resting_on_ground(_log(t, thrust, np.zeros_like(t), np.full_like(t, 1.5)))
    assert np.array_equal(on_a_stand, thrust < 0.5 * WEIGHT)  # every low-thrust sample, and nothing else


def test_a_vehicle_hanging_at_the_ceiling_is_told_from_one_on_the_ground_and_let_go_once_it_drops_away():
    """Drawn up by its own ceiling effect, a vehicle can hang under the ceiling on 40 % of its weight. Those samples
    are held up at the ceiling, not on the ground, and the stretch next to them is extended only while the vehicle
    stays within CONTACT_HEIGHT *below* the height it hung at (the old rule, "no higher than the rest", held every
    sample of the drop away from the ceiling while the thrust was below the weight)."""
    ceiling_z, hang_z = 2.0, 1.998  # the rotors (in the body plane) 2 mm under the ceiling
    t = np.arange(int(6.0 * RATE_HZ)) / RATE_HZ
    thrust = np.where(t < 2.0, 0.4 * WEIGHT, np.where(t < 4.0, 0.8 * WEIGHT, WEIGHT))
    # hanging until 3 s (on 80 % of the weight from 2 s, still held), then falling at 0.2 g until 4 s, then steady
    fall = np.clip(t - 3.0, 0.0, 1.0)  # s of falling
    v_z = -0.2 * G * fall
    p_z = hang_z - 0.1 * G * fall ** 2 - 0.2 * G * np.clip(t - 4.0, 0.0, None)
    scene = Scene((), 0.0, ceiling_z)
    log = _log(t, thrust, v_z, p_z, scene)
    resting, contact = ground_contact(log)
    assert np.array_equal(resting, t < 2.0)  # the 40 % of the weight, and nothing else
    assert at_ceiling(log)[resting | contact].all()
    dropped = hang_z - p_z > CONTACT_HEIGHT  # 3 cm below the hang: 0.175 s into the fall
    first_dropped = float(t[np.argmax(dropped)])
    assert 3.17 < first_dropped < 3.19
    assert np.array_equal(contact, (t >= 2.0) & ~dropped & (t < 4.0))
    # the same rest 2 mm above the ground, under the same ceiling: on the ground
    on_ground = _log(t, thrust, np.zeros_like(t), np.full_like(t, 0.002), scene)
    resting, contact = ground_contact(on_ground)
    assert np.array_equal(resting, t < 2.0)
    assert not at_ceiling(on_ground)[resting | contact].any()
