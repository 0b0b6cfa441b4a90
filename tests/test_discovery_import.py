"""Log import: PX4 ULog and ROS 2 bags become the project's flight log, in its frames and units."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from discovery.flight_log import LogFormatError, quaternions_to_matrices, read_log, read_vehicle_and_scene
from discovery.importers import import_log
from discovery.importers.frames import attitude_frd_ned_to_flu_enu, frd_to_flu, ned_to_enu
from discovery.importers.thrust_map import apply_thrust_map, fit_thrust_map
from wall_inspector.cli import main

PX4 = Path(__file__).parent / "data" / "px4"
SITL = PX4 / "sitl_takeoff_hover_land.ulg"
GROUND = PX4 / "auav_x21_on_ground.ulg"


@pytest.fixture
def vehicle_and_scene(tmp_path):
    vehicle = tmp_path / "vehicle.yaml"
    vehicle.write_text("mass: 1.5\nrotor_positions: [[0.17, -0.17, 0], [-0.17, 0.17, 0], [0.17, 0.17, 0], "
                       "[-0.17, -0.17, 0]]\n")
    scene = tmp_path / "scene.yaml"
    scene.write_text("walls: []\nground_z: -0.5\nceiling_z: null\n")
    return vehicle, scene


# ---------------------------------------------------------------------- frames
def test_ned_frd_become_enu_flu_with_numbers():
    # velocity 1 m/s north, 2 m/s east, 3 m/s up is (2, 1, 3) in ENU
    assert ned_to_enu(np.array([[1.0, 2.0, -3.0]])) == pytest.approx(np.array([[2.0, 1.0, 3.0]]))
    # roll, pitch, yaw rates in FRD: the FLU rates flip y and z
    assert frd_to_flu(np.array([[0.1, 0.2, 0.3]])) == pytest.approx(np.array([[0.1, -0.2, -0.3]]))
    # PX4 attitude: heading east (yaw 90 deg) with the nose 10 deg up (pitch +10 deg in FRD/NED)
    pitch = math.radians(10.0)
    q_xyzw = Rotation.from_euler("ZYX", [90.0, 10.0, 0.0], degrees=True).as_quat()
    q_frd_to_ned = np.array([[q_xyzw[3], *q_xyzw[:3]]])
    q = attitude_frd_ned_to_flu_enu(q_frd_to_ned)
    R = quaternions_to_matrices(q)[0]
    # the nose (body x) points east and up; body y (left) points north; body z (up) leans back, west
    assert R[:, 0] == pytest.approx([math.cos(pitch), 0.0, math.sin(pitch)], abs=1e-12)
    assert R[:, 1] == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)
    assert R[:, 2] == pytest.approx([-math.sin(pitch), 0.0, math.cos(pitch)], abs=1e-12)
    # level and facing north in PX4 is yaw +90 deg about the ENU z axis
    level_north = attitude_frd_ned_to_flu_enu(np.array([[1.0, 0.0, 0.0, 0.0]]))
    assert level_north[0] == pytest.approx([math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)])


def test_thrust_map_is_fitted_on_hover_samples():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 20.0, 0.01)
    n = len(t)
    mass, g, k = 1.2, 9.81, 6.5
    p = np.zeros((n, 3))
    p[:, 2] = np.where(t < 2.0, 0.0, 1.0)  # on the ground for 2 s, then hovering at 1 m
    v = rng.normal(0.0, 0.02, (n, 3))
    R = np.repeat(np.eye(3)[None], n, axis=0)
    hover_u = mass * g / (4 * k)
    u = np.clip(hover_u + rng.normal(0.0, 0.002, (n, 4)), 0, 1)
    u[t < 2.0] = 0.1  # idling on the ground: not hover
    fit = fit_thrust_map(t, p, v, R, u, "motor_command", mass, g)
    assert fit.thrust_map.coefficient == pytest.approx(k, rel=0.01)
    assert fit.hover_s == pytest.approx(18.0, abs=0.6)
    assert apply_thrust_map(fit.thrust_map, np.full((1, 4), hover_u)).sum() == pytest.approx(mass * g, rel=0.01)
    # too little hover: no map, and the note says why
    short = fit_thrust_map(t[:250], p[:250], v[:250], R[:250], u[:250], "motor_command", mass, g)
    assert short.thrust_map is None and "needs at least 1 s" in short.note
    # a command that does not carry the weight (half the steady samples at twice the command): no map
    erratic = u.copy()
    erratic[(t >= 2.0) & (np.arange(n) % 2 == 0)] *= 2.0
    bad = fit_thrust_map(t, p, v, R, erratic, "motor_command", mass, g)
    assert bad.thrust_map is None and bad.relative_rms > 0.1 and "at most 10 %" in bad.note


def test_pwm_limits_px4_leaves_unset_fall_back_to_the_shared_ones(vehicle_and_scene, monkeypatch):
    """PX4 writes -1 for a channel's PWM limit it leaves to PWM_MIN/PWM_MAX (seen in pyulog's sample_log_small.ulg)."""
    import pyulog

    class UnsetChannelLimits(pyulog.ULog):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            for j in range(1, 9):
                self.initial_parameters[f"PWM_MAIN_MIN{j}"] = -1
                self.initial_parameters[f"PWM_MAIN_MAX{j}"] = -1
            self.initial_parameters["PWM_MAIN_MIN2"] = 1100
            outputs = next(d for d in self.data_list if d.name == "actuator_outputs" and d.multi_id == 0).data
            outputs["output[0]"][:] = 1075 + 0.5 * (1950 - 1075)  # half way on each channel's own range
            outputs["output[1]"][:] = 1100 + 0.5 * (1950 - 1100)

    monkeypatch.setattr(pyulog, "ULog", UnsetChannelLimits)
    log, info = import_log(GROUND, *vehicle_and_scene)
    # the log's PWM_MIN/PWM_MAX are 1075/1950 us; channel 2 has its own minimum
    assert info["signals"]["motor_commands"] == "actuator_outputs.output[0..3] (PWM 1075..1950, 1100..1950 us)"
    commands = log.rotor_thrusts[:, :2] / log.vehicle.thrust_map.coefficient
    assert np.allclose(commands, 0.5, atol=1e-6)


# ---------------------------------------------------------------------- PX4
def test_px4_simulated_flight_imports_in_project_frames(vehicle_and_scene):
    log, info = import_log(SITL, *vehicle_and_scene)
    assert info["signals"]["collective_command"] == "vehicle_thrust_setpoint.xyz[2]"
    assert info["signals"]["motor_commands"] == "actuator_motors.control[0..3]"
    assert log.rate_hz == pytest.approx(50.0, rel=1e-3)
    assert log.duration == pytest.approx(30.6, abs=0.5)
    # PX4's z is down: the take-off to about 2.1 m is a climb in +z here
    assert log.p_world[:, 2].max() == pytest.approx(2.16, abs=0.05)
    climbing = np.argmax(log.v_world[:, 2])
    assert log.v_world[climbing, 2] > 0.9
    # the vehicle faces north (PX4 yaw ~0): body x along world +y (ENU)
    R = log.R_body_to_world
    assert np.median(R[:, 1, 0]) == pytest.approx(1.0, abs=0.01)
    # no hover long enough to fit, so the thrust map comes from MPC_THR_HOVER = 0.5: k = m g / (4 * 0.5)
    assert log.vehicle.thrust_map.kind == "motor_command"
    assert log.vehicle.thrust_map.coefficient == pytest.approx(1.5 * 9.81 / 2.0)
    assert "MPC_THR_HOVER" in log.vehicle.thrust_map.source
    assert log.rotor_thrusts is not None and np.all(log.rotor_thrusts >= 0)


def test_px4_real_log_with_older_topics_and_dropouts(vehicle_and_scene):
    log, info = import_log(GROUND, *vehicle_and_scene)
    assert info["signals"]["collective_command"] == "vehicle_rates_setpoint.thrust"
    assert info["signals"]["body_rates"] == "vehicle_attitude.rollspeed,pitchspeed,yawspeed"
    assert info["signals"]["motor_commands"].startswith("actuator_outputs.output[0..3]")
    assert info["dropped_in_gaps"] > 0
    assert len(log.segments()) >= 4  # the logging dropouts stay gaps
    assert 50.0 <= log.rate_hz <= 1000.0
    assert np.allclose(np.linalg.norm(log.q_body_to_world, axis=1), 1.0)


def test_import_log_command_writes_a_log_the_reader_reads(vehicle_and_scene, tmp_path, capsys):
    vehicle, scene = vehicle_and_scene
    out = tmp_path / "sitl.csv"
    assert main(["import-log", str(SITL), "--vehicle", str(vehicle), "--scene", str(scene), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "thrust map: motor_command" in printed and f"wrote {out}" in printed
    log = read_log(out)
    assert log.rotor_thrusts is not None
    assert json.loads(out.with_suffix(".json").read_text())["vehicle"]["thrust_map"]["kind"] == "motor_command"
    # the same again refuses to replace the files, before any work
    assert main(["import-log", str(SITL), "--vehicle", str(vehicle), "--scene", str(scene), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exists; pass --overwrite" in err[0]


@pytest.mark.parametrize("ulog, expect", [
    (SITL, "thrust carries less than 50 % of the weight"),
    (GROUND, "found nothing: the logs hold no airborne flight to fit"),
])
def test_discover_runs_on_px4_logs_and_says_what_limits_it(ulog, expect, vehicle_and_scene, tmp_path, capsys):
    vehicle, scene = vehicle_and_scene
    code = main(["discover", str(ulog), "--vehicle", str(vehicle), "--scene", str(scene), "--out",
                 str(tmp_path / "r"), "--quiet", "--no-plots"])
    out = capsys.readouterr().out
    assert code == 0
    assert expect in out
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["limits"], "the report says what the flight cannot determine"
    assert all(limit["manoeuvre"] for limit in report["limits"])
    assert "cannot determine wall_suction" in out or "nothing to fit" in out
    if ulog == GROUND:  # on the ground from start to end: the report says which stretch was left out, and why
        (left,) = report["left_out"]
        assert left["reason"] == "held up" and left["seconds"] > 0.99 * report["details"]["logs"][0]["duration_s"]


def test_px4_spin_up_and_touchdown_are_ground_contact_not_aerodynamics(vehicle_and_scene, tmp_path):
    """In the SITL log the rotors spin up on the ground (thrust 54-87 % of the weight) and the vehicle touches down
    while the state estimate drifts 0.45 m below its take-off height; both passed the held-up filter and came out
    as a 2.05 N residual 'depending on thrust'. They are ground contact, left out with the reason."""
    vehicle, scene = vehicle_and_scene
    assert main(["discover", str(SITL), "--vehicle", str(vehicle), "--scene", str(scene), "--out",
                 str(tmp_path / "r"), "--quiet", "--no-plots"]) == 0
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    contact = [r for r in report["left_out"] if r["reason"] == "ground contact"]
    intervals = [interval for r in contact for interval in r["time_intervals"]]
    assert len(intervals) == 2  # the spin-up before take-off and the touchdown
    spin_up, touchdown = sorted(intervals)
    assert 16.5 < spin_up[0] < spin_up[1] < 19.0 and 25.0 < touchdown[0] < touchdown[1] < 28.0
    assert not any(e["name"] == "ground_effect" for e in report["effects"])
    left = report["unexplained"]
    assert left is None or (left["force_rms_N"] < 1.0 and left["where"].get("regressor") != "thrust")


def test_discover_asks_for_vehicle_and_scene_for_a_ulog(tmp_path, capsys):
    assert main(["discover", str(SITL), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--vehicle VEHICLE.yaml --scene SCENE.yaml" in err[0]


def test_topics_stamped_before_the_log_starts_are_left_out(vehicle_and_scene, monkeypatch):
    """A land detector or motor topic whose only samples predate the log's start (seen in pyulog's
    sample_appended_multiple.ulg) is left out instead of crashing the import."""
    import pyulog

    def stale(*names):
        class StaleStamps(pyulog.ULog):
            def __init__(self, *args, **kwargs):
                super().__init__(*args, **kwargs)
                for d in self.data_list:
                    if d.name in names:
                        for key in ("timestamp", "timestamp_sample"):
                            if key in d.data:
                                d.data[key] = np.full_like(d.data[key], self.start_timestamp // 2)
        return StaleStamps

    monkeypatch.setattr(pyulog, "ULog", stale("vehicle_land_detected", "actuator_motors"))
    _, info = import_log(SITL, *vehicle_and_scene)
    assert info["signals"]["motor_commands"].startswith("actuator_outputs.output[0..3]")  # the older topic
    monkeypatch.setattr(pyulog, "ULog", stale("vehicle_land_detected", "actuator_motors", "actuator_outputs"))
    log, info = import_log(SITL, *vehicle_and_scene)
    assert info["signals"]["motor_commands"] is None
    # no motor commands: the collective map from MPC_THR_HOVER = 0.5, k = m g / 0.5
    assert log.vehicle.thrust_map.kind == "collective"
    assert log.vehicle.thrust_map.coefficient == pytest.approx(1.5 * 9.81 / 0.5)
    assert log.rotor_thrusts is None and np.all(np.isfinite(log.thrust_cmd))


def test_holding_a_signal_without_samples_names_it():
    from discovery.importers.resample import Signal, hold

    with pytest.raises(ValueError, match="'landed' has no usable samples"):
        hold(Signal("landed", np.zeros(0), np.zeros((0, 1))), np.linspace(0.0, 1.0, 5))


def test_a_damaged_ulog_is_a_clear_error(vehicle_and_scene, tmp_path):
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(b"ULog\x01\x12garbage" * 10)
    with pytest.raises(LogFormatError, match="bad.ulg"):
        import_log(bad, *vehicle_and_scene)


# ---------------------------------------------------------------------- ROS 2
def _write_bag(path: Path, rate_hz: float = 100.0, duration: float = 6.0) -> dict:
    """A bag with odometry (ENU, body-frame twist), a Float64 thrust and Vector3Stamped rate commands.

    Read in NED/FRD (``frame: ned``), the same numbers are a vehicle at yaw 30 deg east of north whose
    FRD body twist is (0.5, -0.2, 0.1) m/s: ``truth["v_world_if_ned"]`` is its ENU world velocity."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    yaw = math.radians(30.0)
    q_xyzw = Rotation.from_euler("z", yaw).as_quat()
    v_body = np.array([0.5, -0.2, 0.1])
    v_world = Rotation.from_euler("z", yaw).apply(v_body)
    v_ned = Rotation.from_euler("z", yaw).apply(v_body)  # the same rotation, read as FRD to NED
    truth = {"v_world": v_world, "yaw": yaw, "thrust": 9.5, "rates": [0.01, -0.02, 0.03],
             "v_world_if_ned": [v_ned[1], v_ned[0], -v_ned[2]]}
    with Writer(path, version=9) as writer:
        odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        thrust = writer.add_connection("/thrust", "std_msgs/msg/Float64", typestore=ts)
        rates = writer.add_connection("/rates_setpoint", "geometry_msgs/msg/Vector3Stamped", typestore=ts)
        for i in range(int(duration * rate_hz)):
            t = 10.0 + i / rate_hz
            ns = int(round(t * 1e9))
            stamp = T["builtin_interfaces/msg/Time"](sec=int(t), nanosec=ns % 1_000_000_000)
            header = T["std_msgs/msg/Header"](stamp=stamp, frame_id="world")
            p = np.array([1.0, 2.0, 1.5]) + v_world * (t - 10.0)
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                orientation=T["geometry_msgs/msg/Quaternion"](x=q_xyzw[0], y=q_xyzw[1], z=q_xyzw[2], w=q_xyzw[3]))
            twist = T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=v_body[0], y=v_body[1],
                                                                                       z=v_body[2]),
                                                 angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0))
            msg = T["nav_msgs/msg/Odometry"](
                header=header, child_frame_id="body",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))
            writer.write(odom, ns, ts.serialize_cdr(msg, msg.__msgtype__))
            if i % 2 == 0:  # commands at half the rate
                f = T["std_msgs/msg/Float64"](data=truth["thrust"])
                writer.write(thrust, ns, ts.serialize_cdr(f, f.__msgtype__))
                r = T["geometry_msgs/msg/Vector3Stamped"](header=header, vector=T["geometry_msgs/msg/Vector3"](
                    x=truth["rates"][0], y=truth["rates"][1], z=truth["rates"][2]))
                writer.write(rates, ns, ts.serialize_cdr(r, r.__msgtype__))
    return truth


def test_ros2_bag_imports_with_the_default_topic_map(vehicle_and_scene, tmp_path):
    bag = tmp_path / "bag"
    truth = _write_bag(bag)
    log, info = import_log(bag, *vehicle_and_scene)
    assert info["format"] == "ROS 2 bag"
    assert log.rate_hz == pytest.approx(100.0, rel=1e-3)
    assert log.duration == pytest.approx(5.98, abs=0.03)
    # the body-frame twist becomes the world velocity
    assert log.v_world.mean(axis=0) == pytest.approx(truth["v_world"], abs=1e-9)
    assert log.p_world[0] == pytest.approx([1.0, 2.0, 1.5], abs=1e-9)
    assert log.thrust_cmd == pytest.approx(np.full(log.n_samples, truth["thrust"]))
    assert log.omega_cmd_body.mean(axis=0) == pytest.approx(truth["rates"])
    yaw = np.arctan2(log.R_body_to_world[:, 1, 0], log.R_body_to_world[:, 0, 0])
    assert yaw == pytest.approx(np.full(log.n_samples, truth["yaw"]))


_PX4_MSGS = {  # the fields of px4_msgs this import reads (PX4's uXRCE-DDS bridge)
    "px4_msgs/msg/VehicleOdometry": "uint64 timestamp\nuint64 timestamp_sample\nuint8 pose_frame\n"
                                    "float32[3] position\nfloat32[4] q\nuint8 velocity_frame\nfloat32[3] velocity\n"
                                    "float32[3] angular_velocity\n",
    "px4_msgs/msg/VehicleThrustSetpoint": "uint64 timestamp\nuint64 timestamp_sample\nfloat32[3] xyz\n",
    "px4_msgs/msg/VehicleRatesSetpoint": "uint64 timestamp\nfloat32 roll\nfloat32 pitch\nfloat32 yaw\n"
                                         "float32[3] thrust_body\nbool reset_integral\n",
}


def _write_px4_bag(path: Path, rate_hz: float = 100.0, duration: float = 8.0, storage: str = "mcap") -> dict:
    """An MCAP bag of px4_msgs (NED/FRD, body-frame velocity, normalised thrust) as PX4's ROS 2 bridge writes:
    1 s on the ground with the rotors stopped, then drifting at 0.2 m/s along body x, 1.5 m up, heading 30 deg
    east of north, hovering on half thrust. Receive times jitter by up to 4 ms; PX4's sample times do not."""
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.writer import StoragePlugin
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    for name, text in _PX4_MSGS.items():
        ts.register(get_types_from_msg(text, name))
    T = ts.types
    yaw = math.radians(30.0)
    q = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)], dtype=np.float32)  # FRD to NED, w first
    v_body = np.array([0.2, 0.0, 0.0])
    v_ned = np.array([0.2 * math.cos(yaw), 0.2 * math.sin(yaw), 0.0])
    rng = np.random.default_rng(5)
    f32 = np.float32
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        odom = writer.add_connection("/fmu/out/vehicle_odometry", "px4_msgs/msg/VehicleOdometry", typestore=ts)
        thrust = writer.add_connection("/fmu/out/vehicle_thrust_setpoint", "px4_msgs/msg/VehicleThrustSetpoint",
                                       typestore=ts)
        rates = writer.add_connection("/fmu/out/vehicle_rates_setpoint", "px4_msgs/msg/VehicleRatesSetpoint",
                                      typestore=ts)
        for i in range(int(duration * rate_hz)):
            t = 20.0 + i / rate_hz
            us = int(round(t * 1e6))
            receive_ns = int(round(1e9 * (1000.0 + t + rng.uniform(0.0, 0.004))))
            flying = t >= 21.0
            p_ned = np.array([0.0, 0.0, -1.5]) + v_ned * (t - 21.0) if flying else np.zeros(3)
            msg = T["px4_msgs/msg/VehicleOdometry"](
                timestamp=us + 300, timestamp_sample=us, pose_frame=1, position=p_ned.astype(f32), q=q,
                velocity_frame=3, velocity=(v_body if flying else np.zeros(3)).astype(f32),
                angular_velocity=np.zeros(3, dtype=f32))
            writer.write(odom, receive_ns, ts.serialize_cdr(msg, msg.__msgtype__))
            if i % 2 == 0:
                command = np.array([0.0, 0.0, -0.5 if flying else 0.0], dtype=f32)
                f = T["px4_msgs/msg/VehicleThrustSetpoint"](timestamp=us + 300, timestamp_sample=us, xyz=command)
                writer.write(thrust, receive_ns, ts.serialize_cdr(f, f.__msgtype__))
                r = T["px4_msgs/msg/VehicleRatesSetpoint"](timestamp=us, roll=0.01, pitch=-0.02, yaw=0.03,
                                                           thrust_body=command, reset_integral=False)
                writer.write(rates, receive_ns, ts.serialize_cdr(r, r.__msgtype__))
    return {"v_enu": [v_ned[1], v_ned[0], 0.0], "heading_enu": math.radians(60.0)}


def test_ros2_px4_msgs_bag_imports_with_only_the_topics(vehicle_and_scene, tmp_path):
    bag = tmp_path / "px4bag"
    truth = _write_px4_bag(bag)
    topics = {"odometry": "/fmu/out/vehicle_odometry", "thrust": "/fmu/out/vehicle_thrust_setpoint",
              "rates_setpoint": "/fmu/out/vehicle_rates_setpoint"}
    log, info = import_log(bag, *vehicle_and_scene, topics=topics)
    assert info["frames"] == "NED world / FRD body converted to ENU world / FLU body"
    # PX4's sample clock, not the jittering receive times: exactly 100 Hz, no gaps
    assert log.rate_hz == pytest.approx(100.0, rel=1e-6) and len(log.segments()) == 1
    flying = log.t >= 1.0 + 0.6  # past the take-off step and the acceleration window
    # the body-frame (FRD) velocity becomes the ENU world velocity; NED z -1.5 m is 1.5 m up
    assert log.v_world[flying].mean(axis=0) == pytest.approx(truth["v_enu"], abs=1e-6)
    assert log.p_world[flying, 2] == pytest.approx(np.full(flying.sum(), 1.5), abs=1e-6)
    heading = np.arctan2(log.R_body_to_world[:, 1, 0], log.R_body_to_world[:, 0, 0])
    assert heading == pytest.approx(np.full(log.n_samples, truth["heading_enu"]), abs=1e-6)
    # FRD rate commands in FLU: y and z change sign
    assert log.omega_cmd_body[flying].mean(axis=0) == pytest.approx([0.01, 0.02, -0.03], abs=1e-6)
    # -xyz[2] is the normalised collective; hover on 0.5 holds 1.5 kg: k = m g / 0.5
    assert log.vehicle.thrust_map.kind == "collective"
    assert log.vehicle.thrust_map.coefficient == pytest.approx(1.5 * 9.81 / 0.5, rel=1e-3)
    assert log.thrust_cmd[flying] == pytest.approx(np.full(flying.sum(), 1.5 * 9.81), rel=1e-3)


def test_a_bag_without_the_definitions_of_its_custom_types_says_so(vehicle_and_scene, tmp_path):
    """Humble's SQLite3 bags carry no message definitions: px4_msgs cannot be decoded from them."""
    import sqlite3

    bag = tmp_path / "px4bag"
    _write_px4_bag(bag, duration=1.0, storage="sqlite3")
    with sqlite3.connect(next(bag.glob("*.db3"))) as db:
        db.execute("DELETE FROM message_definitions")
    topics = {"odometry": "/fmu/out/vehicle_odometry", "thrust": "/fmu/out/vehicle_thrust_setpoint",
              "rates_setpoint": "/fmu/out/vehicle_rates_setpoint"}
    with pytest.raises(LogFormatError, match=r"'px4_msgs/msg/VehicleOdometry'.*does not carry their definitions"):
        import_log(bag, *vehicle_and_scene, topics=topics)


def test_ros2_topic_map_fields_take_indices_lists_and_scales(vehicle_and_scene, tmp_path):
    bag = tmp_path / "px4bag"
    _write_px4_bag(bag, duration=4.0)
    topics = {"odometry": "/fmu/out/vehicle_odometry",
              "thrust": {"topic": "/fmu/out/vehicle_rates_setpoint", "field": "thrust_body[2]", "scale": -1.0},
              "rates_setpoint": {"topic": "/fmu/out/vehicle_rates_setpoint", "field": ["roll", "yaw", "pitch"]},
              "thrust_unit": "normalised"}
    log, _ = import_log(bag, *vehicle_and_scene, topics=topics)
    flying = log.t >= 1.6
    # (roll, yaw, pitch) in FRD, (0.01, 0.03, -0.02), is (0.01, -0.03, 0.02) in FLU
    assert log.omega_cmd_body[flying].mean(axis=0) == pytest.approx([0.01, -0.03, 0.02], abs=1e-6)
    assert log.vehicle.thrust_map.coefficient == pytest.approx(1.5 * 9.81 / 0.5, rel=1e-3)
    with pytest.raises(LogFormatError, match="VehicleOdometry is in PX4's NED/FRD frames; set frame: ned"):
        import_log(bag, *vehicle_and_scene, topics={**topics, "frame": "enu"})
    for bad, match in [({"field": "xyz[7]"}, "has no index 7"), ({"field": "x-y"}, "is not a name or name"),
                       ({"scale": 0}, r"thrust.scale must be a finite non-zero number")]:
        entry = {"topic": "/fmu/out/vehicle_thrust_setpoint", **bad}
        with pytest.raises((LogFormatError, ValueError), match=match):
            import_log(bag, *vehicle_and_scene, topics={**topics, "thrust": entry})


def test_ros2_odometry_in_ned_with_a_body_twist_becomes_the_enu_world_velocity(vehicle_and_scene, tmp_path):
    """A body-frame twist in FRD turns into FLU before the attitude rotates it into the world."""
    bag = tmp_path / "bag"
    truth = _write_bag(bag, duration=1.0)
    log, _ = import_log(bag, *vehicle_and_scene,
                        topics={"odometry": "/odom", "thrust": "/thrust", "rates_setpoint": "/rates_setpoint",
                                "frame": "ned"})
    assert log.v_world.mean(axis=0) == pytest.approx(truth["v_world_if_ned"], abs=1e-9)


def test_ros2_topic_map_errors_name_the_key(vehicle_and_scene, tmp_path):
    bag = tmp_path / "bag"
    _write_bag(bag, duration=1.0)
    topics = tmp_path / "topics.yaml"
    topics.write_text("odometry: /odom\nthrust: /missing\nrates_setpoint: /rates_setpoint\n")
    with pytest.raises(LogFormatError, match=r"topic\(s\) \['/missing'\] named in the topic map are not in the bag"):
        import_log(bag, *vehicle_and_scene, topics=topics)
    topics.write_text("odometry: /odom\nthrust: /thrust\nrates_setpoint: /rates_setpoint\nframe: up\n")
    with pytest.raises(ValueError, match=r"frame must be one of \['enu', 'ned'\]"):
        import_log(bag, *vehicle_and_scene, topics=topics)


def test_vehicle_and_scene_files_are_checked_like_a_sidecar(tmp_path):
    vehicle = tmp_path / "vehicle.yaml"
    vehicle.write_text("mass: -1\nrotor_positions: [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]\n")
    scene = tmp_path / "scene.yaml"
    scene.write_text("walls: []\nground_z: 0\nceiling_z: null\n")
    with pytest.raises(LogFormatError, match=r"key 'vehicle.mass'.*must be a finite number in \[0.001, 100\]"):
        read_vehicle_and_scene(vehicle, scene)


def test_discover_takes_a_bag_directly(vehicle_and_scene, tmp_path, capsys):
    bag = tmp_path / "bag"
    _write_bag(bag)
    vehicle, scene = vehicle_and_scene
    code = main(["discover", str(bag), "--vehicle", str(vehicle), "--scene", str(scene), "--out", str(tmp_path / "r"),
                 "--quiet", "--no-plots"])
    assert code == 0, capsys.readouterr().err
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["details"]["logs"][0]["file"] == str(bag)
    # 9.5 N of logged thrust holds 1.5 kg (14.7 N) at constant velocity: the thrust is 1.549 times what is logged
    assert [e["name"] for e in report["effects"]] == ["thrust_scale"]
    assert report["effects"][0]["params"]["scale"] == pytest.approx(1.5 * 9.81 / 9.5, rel=1e-3)
    # at constant thrust that is indistinguishable from a steady vertical force, and the report says so
    limits = {tuple(limit["effects"]): limit for limit in report["limits"]}
    assert "climb and descend" in limits[("thrust_scale", "constant_force")]["manoeuvre"]
