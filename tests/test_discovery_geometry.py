"""Discovery beside bodies: a sidecar scene with finite walls and meshes, and the residual drawn on the surface."""

import json
import shutil

import numpy as np
import pytest

from discovery import Discovery
from discovery.flight_log import LogFormatError, read_log
from discovery.fly import fly
from discovery.scenarios import FINITE_WALL_TOP
from discovery.surface_map import surface_coordinates
from wall_env.bodies import Box, Mesh


@pytest.fixture(scope="module")
def finite_wall_log(tmp_path_factory):
    """15 s of the survey across the top edge of a wall that ends 1.2 m up; the sidecar says so."""
    folder = tmp_path_factory.mktemp("finite_wall")
    fly(scenario="finite-wall-survey", effects="wall_suction:k_s=4.1,d_thr=0.132", seed=5, duration=15.0,
        out=folder / "flight.csv")
    return folder / "flight.csv"


def test_a_sidecar_scene_holds_bodies_with_meshes_read_beside_it(tmp_path, finite_wall_log):
    log = read_log(finite_wall_log)
    assert log.scene.walls == () and isinstance(log.scene.bodies[0], Box)
    assert log.scene.bodies[0].size == (0.2, 6.0, FINITE_WALL_TOP)
    shutil.copy(finite_wall_log, tmp_path / "mesh.csv")
    shutil.copy("tests/data/scenes/plane_x0.obj", tmp_path / "plane.obj")
    sidecar = json.loads(finite_wall_log.with_suffix(".json").read_text())
    sidecar["scene"]["bodies"] = [{"type": "mesh", "file": "plane.obj"}]
    (tmp_path / "mesh.json").write_text(json.dumps(sidecar, indent=2))
    mesh = read_log(tmp_path / "mesh.csv").scene.bodies[0]
    assert isinstance(mesh, Mesh) and mesh.file == str((tmp_path / "plane.obj").resolve())
    sidecar["scene"]["bodies"] = [{"type": "box", "size": [0.2, 6.0]}]
    (tmp_path / "mesh.json").write_text(json.dumps(sidecar, indent=2))
    with pytest.raises(LogFormatError, match=r"mesh.json: key 'scene.bodies\[0\]', line \d+: .*box.size \(m\) must "
                                             r"be 3 numbers"):
        read_log(tmp_path / "mesh.csv")


def test_discovery_along_a_finite_wall_that_the_scene_holds_recovers_the_suction(finite_wall_log):
    found = Discovery().fit(read_log(finite_wall_log))
    assert found.names_ == ["wall_suction"]
    suction = found.effects_[0].params_dict()
    assert suction["k_s"] == pytest.approx(4.1, rel=0.1) and suction["d_thr"] == pytest.approx(0.132, rel=0.1)


def test_the_residual_on_the_surface_shows_where_the_wall_ends(finite_wall_log, tmp_path):
    log = read_log(finite_wall_log)
    plane = json.loads(finite_wall_log.with_suffix(".json").read_text())
    plane["scene"] = {"walls": [{"point": [0, 0, 0], "normal": [1, 0, 0]}], "ground_z": 0.0, "ceiling_z": None}
    shutil.copy(finite_wall_log, tmp_path / "plane.csv")
    (tmp_path / "plane.json").write_text(json.dumps(plane))
    found = Discovery().fit(read_log(tmp_path / "plane.csv"))  # told an infinite plane
    segments = found.data_.segments
    along, height, normal, how = surface_coordinates([s.scene for s in segments], [s.states.p_world for s in segments])
    assert how == "flat" and np.allclose(normal, [1.0, 0.0, 0.0])
    np.testing.assert_allclose(along, found.data_.concat([s.states.p_world[:, 1] for s in segments]), atol=1e-9)
    pull = -(found.residual_before_ * normal).sum(axis=1)  # what the nominal model misses, toward the wall
    near = found.data_.concat([s.states.p_world[:, 0] for s in segments]) < 0.22  # near rotors within d_thr
    below = pull[near & (height < FINITE_WALL_TOP - 0.05)].mean()
    above = pull[near & (height > FINITE_WALL_TOP + 0.15)].mean()
    assert below > 0.2 and abs(above) < 0.2 * below  # the pull stops at the edge, as drawn on the surface
    from discovery.plots import plot_all

    written = plot_all(found, tmp_path / "plots")
    assert (tmp_path / "plots" / "residual_on_surface.png") in written
    assert log.scene.has_bodies  # the log itself said where the wall is
