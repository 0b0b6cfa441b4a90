"""Scenes with bodies: the scene file, and each rotor's local surfaces from PyBullet against the geometry's own numbers."""

import json

import numpy as np
import pytest

from wall_env import Scene, VehicleParams, Wall
from wall_env.bodies import Box, Cylinder, Mesh, Urdf
from wall_env.rotations import euler_xyz_to_quat_rows, quat_to_rotation_rows
from wall_env.scene import SURFACE_SIZE, SURFACE_SLOTS
from wall_env.surfaces import SurfaceQuery, surface_weight

DATA = "tests/data/scenes"
VEHICLE = VehicleParams()
LEVEL = np.array([[1.0, 0.0, 0.0, 0.0]])


def _slots(out: np.ndarray) -> np.ndarray:
    return out.reshape(len(out), 4, SURFACE_SLOTS, SURFACE_SIZE)


def _rotors(p, q):
    R = quat_to_rotation_rows(q)
    return p[:, None, :] + np.einsum("nij,kj->nki", R, VEHICLE.rotor_positions_array)


def test_a_scene_file_with_every_body_type_loads_writes_and_loads_again(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "plane.obj").write_text(open(f"{DATA}/plane_x0.obj").read())
    (tmp_path / "pole.urdf").write_text(open(f"{DATA}/pole.urdf").read())
    (tmp_path / "scene.yaml").write_text(
        "walls:\n  - {point: [0, 0, 0], normal: [2, 0, 0]}\nground_z: 0.0\nceiling_z: 3.0\nbodies:\n"
        "  - {type: box, size: [0.2, 1.0, 2.0], position: [1, 2, 1], rpy: [0, 0, 0.5]}\n"
        "  - {type: cylinder, radius: 0.4, length: 3.0, position: [4, 0, 1.5]}\n"
        "  - {type: mesh, file: meshes/plane.obj, scale: 0.5}\n"
        "  - {type: urdf, file: pole.urdf, position: [6, 0, 0]}\n")
    scene = Scene.from_file(tmp_path / "scene.yaml")
    assert scene.walls == (Wall((0, 0, 0), (1, 0, 0)),)  # the normal is made unit
    assert [type(b) for b in scene.bodies] == [Box, Cylinder, Mesh, Urdf]
    assert scene.bodies[2].file == str((tmp_path / "meshes" / "plane.obj").resolve())
    assert scene.bodies[2].scale == (0.5, 0.5, 0.5)
    assert scene.structure == (1, True, True, SURFACE_SLOTS)
    assert scene.vector_size == 8 + 4 * SURFACE_SLOTS * SURFACE_SIZE
    written = scene.to_file(tmp_path / "again.json")
    assert json.loads(written.read_text())["bodies"][2]["file"] == "meshes/plane.obj"  # relative to the file
    assert Scene.from_file(written) == scene
    assert Scene((Wall((0, 0, 0), (1, 0, 0)),)).structure == (1, True, False, 0)  # planes only: as before


@pytest.mark.parametrize("body, message", [
    ({"type": "sphere", "radius": 1}, "scene.bodies[0].type must be one of"),
    ({"type": "box", "size": [1, -1, 1]}, "box.size (m)"),
    ({"type": "box"}, "needs ['size']"),
    ({"type": "cylinder", "radius": 0.5, "length": 2, "height": 3}, "unknown key(s) ['height']"),
    ({"type": "mesh", "file": "nowhere.obj"}, "does not exist"),
    ({"type": "mesh", "file": "plane_x0.stl"}, "must end in .obj"),
    ({"type": "box", "size": [1, 1, 1], "position": [0, float("nan"), 0]}, "box.position (m) must be finite"),
])
def test_bad_bodies_are_named_with_what_is_allowed(tmp_path, body, message):
    with pytest.raises(ValueError, match=None) as error:
        Scene.from_dict({"bodies": [body]}, base=DATA)
    assert message in str(error.value)


def test_over_a_face_a_rotor_feels_the_face_exactly_and_past_an_edge_it_feels_the_edge():
    wall = Box((0.2, 2.0, 3.0), (-0.1, 0.0, 1.5))  # face x = 0, edge at y = 1
    query = SurfaceQuery(Scene((), 0.0, None, (wall,)), VEHICLE, reach=0.3)
    p = np.array([[0.15, 0.0, 1.5], [0.15, 1.05, 1.5]])
    out = np.zeros((2, 4 * SURFACE_SLOTS * SURFACE_SIZE))
    found = query.rotor_surfaces(p, np.repeat(LEVEL, 2, axis=0), out)
    rotors = _rotors(p, np.repeat(LEVEL, 2, axis=0))
    slots = _slots(out)
    # over the face: every rotor's distance is its x, along +x
    np.testing.assert_allclose(found.distance[0], rotors[0, :, 0], atol=1e-12)
    np.testing.assert_allclose(slots[0, :, 0, 3:6], np.tile([1.0, 0.0, 0.0], (4, 1)), atol=1e-12)
    assert np.all(slots[:, :, 1, 6] == 0.0)  # one box: no second surface
    # past the edge (rotors 1 and 2 at y = 1.05 + 0.0707): the distance to the edge and its direction
    for j in range(4):
        lateral = max(rotors[1, j, 1] - 1.0, 0.0)
        expected = np.hypot(rotors[1, j, 0], lateral)
        assert found.distance[1, j] == pytest.approx(expected, abs=1e-12)
        np.testing.assert_allclose(slots[1, j, 0, 3:6], np.array([rotors[1, j, 0], lateral, 0.0]) / expected,
                                   atol=1e-12)


def test_a_ledge_and_a_facade_both_pull_while_coplanar_boxes_pull_once():
    facade = Box((0.3, 4.0, 3.0), (-0.15, 0.0, 1.5))
    ledge = Box((0.15, 4.0, 0.1), (0.075, 0.0, 1.45))  # top at z = 1.5, front at x = 0.15
    left, right = Box((0.2, 1.0, 2.0), (-0.1, -0.5, 1.0)), Box((0.2, 1.0, 2.0), (-0.1, 0.5, 1.0))  # seam at y = 0
    p = np.array([[0.16, 1.0, 1.59]])
    corner = SurfaceQuery(Scene((), 0.0, None, (facade, ledge)), VEHICLE, reach=0.3)
    out = np.zeros((1, 4 * SURFACE_SLOTS * SURFACE_SIZE))
    corner.rotor_surfaces(p, LEVEL, out)
    slots = _slots(out)[0]
    rotors = _rotors(p, LEVEL)[0]
    for j in (1, 2):  # the rear rotors (x = 0.0893) are over the ledge and beside the facade
        faces = {tuple(np.round(slots[j, k, 3:6], 9)): slots[j, k] for k in range(2)}
        assert set(faces) == {(1.0, 0.0, 0.0), (0.0, 0.0, 1.0)}
        assert faces[(1.0, 0.0, 0.0)][6] == 1.0 and faces[(0.0, 0.0, 1.0)][6] == 1.0
        np.testing.assert_allclose(np.dot(faces[(0.0, 0.0, 1.0)][3:6], rotors[j] - faces[(0.0, 0.0, 1.0)][:3]),
                                   0.09, atol=1e-12)
    seam = SurfaceQuery(Scene((), 0.0, None, (left, right)), VEHICLE, reach=0.3)
    out = np.zeros((1, 4 * SURFACE_SLOTS * SURFACE_SIZE))
    found = seam.rotor_surfaces(np.array([[0.12, 0.0, 1.0]]), LEVEL, out)
    assert np.all(_slots(out)[0, :, 1, 6] == 0.0)
    np.testing.assert_allclose(found.distance[0], _rotors(np.array([[0.12, 0.0, 1.0]]), LEVEL)[0, :, 0], atol=1e-12)


def test_the_second_surfaces_weight_ramps_with_its_angle_and_its_distance_from_the_first_plane():
    angles = np.radians([0.0, 30.0, 45.0, 60.0, 90.0])
    np.testing.assert_allclose(surface_weight(np.cos(angles), np.full(5, 1.0)), [0.0, 0.0, 0.5, 1.0, 1.0],
                               atol=1e-12)
    np.testing.assert_allclose(surface_weight(np.cos(np.full(3, np.pi / 2)), np.array([0.0, 0.01, 0.05])),
                               [0.0, 0.5, 1.0])


def test_on_a_cylinder_each_rotor_reads_the_analytic_distance_and_normal():
    pier = Cylinder(0.5, 8.0, (0.0, 0.0, 4.0))
    query = SurfaceQuery(Scene((), 0.0, None, (pier,)), VEHICLE, reach=0.25)
    rng = np.random.default_rng(5)
    n = 300
    angle, radius = rng.uniform(0, 2 * np.pi, n), 0.5 + rng.uniform(0.12, 0.22, n)
    p = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), rng.uniform(1.0, 3.0, n)])
    q = euler_xyz_to_quat_rows(np.column_stack([rng.uniform(-0.2, 0.2, (n, 2)), rng.uniform(-3, 3, n)]))
    out = np.zeros((n, 4 * SURFACE_SLOTS * SURFACE_SIZE))
    found = query.rotor_surfaces(p, q, out)
    rotors = _rotors(p, q)
    distance = np.linalg.norm(rotors[:, :, :2], axis=2) - 0.5
    normal = np.concatenate([rotors[:, :, :2] / (distance[:, :, None] + 0.5), np.zeros((n, 4, 1))], axis=2)
    seen = np.isfinite(found.distance)
    assert seen.sum() > 0.7 * 4 * n and np.all(distance[~seen] > 0.25 - 1e-6) and np.all(distance[seen] < 0.25 + 1e-6)
    assert np.abs(found.distance - distance)[seen].max() < 2e-6  # PyBullet's GJK: a micrometre
    angle_error = np.arccos(np.clip(np.einsum("nkj,nkj->nk", found.normal, normal), -1, 1))[seen]
    assert angle_error.max() < 3e-3  # and a few milliradians of direction
    slots = _slots(out)
    plane_distance = np.einsum("nkj,nkj->nk", slots[:, :, 0, 3:6], rotors - slots[:, :, 0, 0:3])
    np.testing.assert_allclose(plane_distance[seen], found.distance[seen], atol=1e-12)  # the tangent plane's


def test_the_shipped_example_scene_loads_and_flies():
    import gymnasium as gym

    scene = Scene.from_file("docs/examples/building_scene.yaml")
    assert [type(b) for b in scene.bodies] == [Box, Box, Cylinder] and scene.bodies[1].rpy[2] == pytest.approx(np.pi / 6,
                                                                                                              abs=1e-4)
    env = gym.make("WallInspector/WallHover-v0", scene=scene, noise=False)
    env.reset(seed=0, options={"perturb_start": False})
    info = env.step(np.zeros(4, dtype=np.float32))[4]
    # the hover point faces the wall's face 0.16 m out, 1 m up (below its top edge): the near pair pulls
    assert info["rotor_suction_world"][:, 0].sum() < -0.3 and info["collisions"] == 0
    env.close()
