"""Each effect of the library against its equation, with numbers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.helpers import FACE_WALL, wrench
from wall_env.effects import EFFECTS, effects_from_spec, make_effect
from wall_env.scene import Scene, Wall
from wall_env.vehicle import GRAVITY, VehicleParams

VEHICLE = VehicleParams()
A = 0.1 / np.sqrt(2)  # rotor offset along body x and y in the X configuration
WALL_X0 = Scene((Wall((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),), ground_z=0.0)


# ----------------------------------------------------------------------------- wall suction
def test_two_rotors_at_32_mm_give_0_82_newton_toward_the_wall():
    # Facing the wall, rotors 0 and 3 sit A closer than the centre of mass.
    force, moment = wrench(make_effect("wall_suction"), WALL_X0, (A + 0.032, 0.0, 1.0), FACE_WALL)
    assert force == pytest.approx([-2 * 4.1 * (0.132 - 0.032), 0.0, 0.0], abs=1e-12)
    assert force[0] == pytest.approx(-0.82, abs=1e-12)
    # equal forces on the two near rotors: their yaw moments cancel and they act in the rotor plane
    assert moment == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)


@pytest.mark.parametrize("gap", [0.0, 1e-6, 0.05, 1.0])
def test_no_suction_at_and_beyond_the_threshold(gap):
    force, moment = wrench(make_effect("wall_suction"), WALL_X0, (A + 0.132 + gap, 0.0, 1.0), FACE_WALL)
    assert np.all(force == 0.0) and np.all(moment == 0.0)


def test_suction_is_linear_in_distance_inside_the_threshold():
    effect = make_effect("wall_suction", k_s=10.0, d_thr=0.1)
    for d in (0.01, 0.04, 0.07, 0.099):
        force, _ = wrench(effect, WALL_X0, (A + d, 0.0, 1.0), FACE_WALL)
        assert force[0] == pytest.approx(-2 * 10.0 * (0.1 - d), rel=1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_suction_acts_along_the_normal_of_a_wall_at_any_orientation(seed):
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    point = rng.uniform(-1, 1, 3)
    scene = Scene((Wall(tuple(point), tuple(normal)),), ground_z=None)
    R = Rotation.random(random_state=seed).as_matrix()
    # put rotor 0 at 5 cm from the wall; the others wherever the attitude puts them
    r0_world = point + 0.05 * normal + rng.uniform(-0.5, 0.5) * np.cross(normal, [0.3, 0.4, 0.5])
    p_world = r0_world - R @ VEHICLE.rotor_positions_array[0]
    k_s, d_thr = 6.0, 0.12
    force, moment = wrench(make_effect("wall_suction", k_s=k_s, d_thr=d_thr), scene, p_world, R)

    rotors_world = p_world + VEHICLE.rotor_positions_array @ R.T
    distances = (rotors_world - point) @ normal
    magnitudes = k_s * np.clip(d_thr - np.clip(distances, 0, None), 0, None)
    expected_force = -normal * magnitudes.sum()
    expected_moment = sum(
        np.cross(VEHICLE.rotor_positions_array[j], R.T @ (-normal * magnitudes[j])) for j in range(4)
    )
    assert magnitudes[0] == pytest.approx(k_s * 0.07)
    assert force == pytest.approx(expected_force, abs=1e-12)
    assert moment == pytest.approx(expected_moment, abs=1e-12)
    assert np.dot(force, normal) < 0  # toward the wall


def test_one_rotor_inside_gives_a_moment_the_lumped_model_lacks():
    # yawed 0.4 rad away from facing the wall: rotor 3 is nearest, rotor 0 beyond d_thr = 0.06
    R = Rotation.from_euler("z", np.pi + 0.4).as_matrix()
    r3_world = R @ VEHICLE.rotor_positions_array[3]
    p_world = np.array([0.03 - r3_world[0], 0.0, 1.0])  # rotor 3 at 3 cm
    force, moment = wrench(make_effect("wall_suction", d_thr=0.06), WALL_X0, p_world, R)
    assert force == pytest.approx([-4.1 * (0.06 - 0.03), 0, 0], abs=1e-12)
    expected = np.cross(VEHICLE.rotor_positions_array[3], R.T @ force)
    assert moment == pytest.approx(expected, abs=1e-12)
    assert abs(moment[2]) > 1e-3  # a yaw moment toward the wall, which Eq. 10's lumped force has not


def test_suction_pulls_toward_each_of_two_walls():
    corridor = Scene((Wall((0, -0.2, 0), (0, 1, 0)), Wall((0, 0.2, 0), (0, -1, 0))), ground_z=0.0)
    centred, _ = wrench(make_effect("wall_suction"), corridor, (0, 0, 1))
    assert centred == pytest.approx([0, 0, 0], abs=1e-12)  # equal and opposite
    left, _ = wrench(make_effect("wall_suction"), corridor, (0, 0.05, 1))
    # left rotors at 0.2 - 0.05 - A from the +y wall; right rotors 0.25 - A from the -y wall (outside)
    assert left[1] == pytest.approx(2 * 4.1 * (0.132 - (0.15 - A)), rel=1e-12)


def test_thrust_scaling_option_scales_with_rotor_thrust_relative_to_hover():
    hover = VEHICLE.hover_thrust / 4
    effect = make_effect("wall_suction", thrust_scaling=True)
    at_hover, _ = wrench(effect, WALL_X0, (A + 0.032, 0, 1), FACE_WALL, rotor_thrusts=[hover] * 4)
    doubled, _ = wrench(effect, WALL_X0, (A + 0.032, 0, 1), FACE_WALL, rotor_thrusts=[2 * hover] * 4)
    assert at_hover[0] == pytest.approx(-0.82, abs=1e-12)
    assert doubled[0] == pytest.approx(-1.64, abs=1e-12)
    plain, _ = wrench(make_effect("wall_suction"), WALL_X0, (A + 0.032, 0, 1), FACE_WALL, rotor_thrusts=[2 * hover] * 4)
    assert plain[0] == pytest.approx(-0.82, abs=1e-12)  # off by default


# ----------------------------------------------------------------------------- drag
def test_linear_drag_opposes_body_velocity_per_axis():
    R = Rotation.from_euler("xyz", [0.2, -0.3, 1.0]).as_matrix()
    v_world = np.array([1.0, -2.0, 0.5])
    D = np.array([0.3, 0.3, 0.2])
    force, moment = wrench(make_effect("linear_drag", D=D), WALL_X0, (2, 0, 1), R, v_world)
    assert force == pytest.approx(R @ (-D * (R.T @ v_world)), abs=1e-12)
    assert moment == pytest.approx([0, 0, 0])
    level, _ = wrench(make_effect("linear_drag"), WALL_X0, (2, 0, 1), np.eye(3), (2.0, 0, 0))
    assert level == pytest.approx([-0.6, 0, 0])  # 0.3 N s/m x 2 m/s (paper Eq. 4)


def test_quadratic_drag_grows_with_speed_squared():
    C = np.array([0.05, 0.1, 0.2])
    R = Rotation.from_euler("z", 0.7).as_matrix()
    v_world = np.array([3.0, 1.0, -2.0])
    force, _ = wrench(make_effect("quadratic_drag", C=C), WALL_X0, (2, 0, 1), R, v_world)
    v_body = R.T @ v_world
    assert force == pytest.approx(R @ (-C * np.abs(v_body) * v_body), abs=1e-12)


# ----------------------------------------------------------------------------- ground and ceiling
def test_ground_effect_follows_cheeseman_bennett_per_rotor():
    r = 0.06
    h = 0.05  # rotor centres 5 cm above the ground (level vehicle, rotors in the CoM plane)
    force, moment = wrench(make_effect("ground_effect", radius=r), WALL_X0, (2, 0, h))
    gain = 1 / (1 - (r / (4 * h)) ** 2)
    assert force == pytest.approx([0, 0, (gain - 1) * VEHICLE.hover_thrust], abs=1e-12)
    assert force[2] == pytest.approx(0.970, abs=1e-3)
    assert moment == pytest.approx([0, 0, 0], abs=1e-12)
    far, _ = wrench(make_effect("ground_effect", radius=r), WALL_X0, (2, 0, 2.0))
    assert far[2] == pytest.approx((1 / (1 - (r / 8) ** 2) - 1) * VEHICLE.hover_thrust)
    assert far[2] < 6e-4


def test_ground_effect_gain_is_capped_at_half_a_radius():
    r = 0.1
    force, _ = wrench(make_effect("ground_effect", radius=r), WALL_X0, (2, 0, 0.001))
    assert force[2] == pytest.approx((4 / 3 - 1) * VEHICLE.hover_thrust)


def test_ceiling_effect_pulls_up_near_a_ceiling_and_tilted_rotors_give_a_moment():
    scene = Scene((), ground_z=0.0, ceiling_z=2.0)
    r = 0.08
    R = Rotation.from_euler("y", 0.3).as_matrix()  # pitched: front rotors higher
    p_world = np.array([0, 0, 2.0 - 0.08])
    force, moment = wrench(make_effect("ceiling_effect", radius=r), scene, p_world, R)
    rotors = p_world + VEHICLE.rotor_positions_array @ R.T
    depth = np.maximum(2.0 - rotors[:, 2], r / 2)
    extra = (1 / (1 - (r / (4 * depth)) ** 2) - 1) * VEHICLE.hover_thrust / 4
    assert force == pytest.approx(R[:, 2] * extra.sum(), abs=1e-12)
    expected_moment = sum(np.cross(VEHICLE.rotor_positions_array[j], [0, 0, extra[j]]) for j in range(4))
    assert moment == pytest.approx(expected_moment, abs=1e-12)
    assert force[2] > 0 and abs(moment[1]) > 1e-4


def test_effects_without_their_surface_contribute_nothing():
    no_ceiling = Scene((), ground_z=0.0, ceiling_z=None)
    force, _ = wrench(make_effect("ceiling_effect"), no_ceiling, (0, 0, 1.0))
    assert np.all(force == 0)
    no_walls = Scene((), ground_z=None)
    force, _ = wrench(make_effect("wall_suction"), no_walls, (0, 0, 1.0))
    assert np.all(force == 0)


# ----------------------------------------------------------------------------- thrust and bias
def test_thrust_scale_changes_thrust_along_body_z():
    R = Rotation.from_euler("x", 0.2).as_matrix()
    force, _ = wrench(make_effect("thrust_scale", scale=0.9), WALL_X0, (2, 0, 1), R)
    assert force == pytest.approx(R[:, 2] * (-0.1) * VEHICLE.mass * GRAVITY, abs=1e-12)


def test_constant_force_is_the_same_everywhere():
    F = (0.3, -0.2, 0.1)
    for p in [(2, 0, 1), (0.1, 5, 3)]:
        force, moment = wrench(make_effect("constant_force", F=F), WALL_X0, p, Rotation.random(random_state=1).as_matrix())
        assert force == pytest.approx(F) and moment == pytest.approx([0, 0, 0])


# ----------------------------------------------------------------------------- library mechanics
def test_library_holds_the_seven_effects_with_units_and_ranges():
    assert sorted(EFFECTS) == sorted(
        ["wall_suction", "linear_drag", "quadratic_drag", "ground_effect", "ceiling_effect", "thrust_scale", "constant_force"]
    )
    for cls in EFFECTS.values():
        for p in cls.parameters:
            assert p.unit and p.low < p.high and p.description


@pytest.mark.parametrize(
    "name, values, message",
    [
        ("wall_suction", {"k_s": -1.0}, r"wall_suction\.k_s must be in \[0, 200\] N/m"),
        ("wall_suction", {"d_thr": 2.0}, r"wall_suction\.d_thr must be in \[0\.001, 1\] m"),
        ("linear_drag", {"D": [0.3, 0.3]}, r"linear_drag\.D must have 3 value"),
        ("ground_effect", {"radius": float("nan")}, r"ground_effect\.radius must be in"),
        ("wall_suction", {"thrust_scaling": "yes"}, r"wall_suction\.thrust_scaling must be a bool"),
        ("wall_suction", {"k": 1.0}, r"unknown argument\(s\) \['k'\]"),
        ("wind", {}, r"unknown effect 'wind'"),
    ],
)
def test_bad_parameters_are_rejected_with_name_and_range(name, values, message):
    with pytest.raises(ValueError, match=message):
        make_effect(name, **values)


def test_specifications_in_every_accepted_form_agree():
    from_dict = effects_from_spec({"wall_suction": {"k_s": 2.0}, "constant_force": {"F": [0.1, 0, 0]}})
    from_records = effects_from_spec([
        {"name": "wall_suction", "params": {"k_s": 2.0}},
        {"name": "constant_force", "params": {"F": [0.1, 0, 0]}},
    ])
    from_string = effects_from_spec("wall_suction:k_s=2.0; constant_force:F=0.1/0/0")
    assert from_dict == from_records == from_string
    assert from_dict[0].params_dict() == {"k_s": 2.0, "d_thr": 0.132}
    with pytest.raises(ValueError, match="must look like name=value"):
        effects_from_spec("wall_suction:k_s")
