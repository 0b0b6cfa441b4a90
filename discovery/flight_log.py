"""The flight-log format (a public contract): a CSV of samples and a JSON sidecar, read, checked and written.

A log is two files with the same base name, ``flight.csv`` and ``flight.json``.

The CSV file has a header row and one row per sample:

=====================  ========  =====================================================
column                 unit      meaning
=====================  ========  =====================================================
``t``                  s         time, strictly increasing
``x, y, z``            m         position of the centre of mass, world frame, z up
``vx, vy, vz``         m/s       velocity, world frame
``qw, qx, qy, qz``     -         unit quaternion, body to world (scalar first)
``wx, wy, wz``         rad/s     measured body rates
``thrust_cmd``         N         collective thrust command
``wx_cmd .. wz_cmd``   rad/s     body-rate commands
``ax, ay, az``         m/s^2     optional: measured world-frame acceleration (all three or none)
``rotor_0 .. rotor_3`` N         optional: per-rotor thrust (all four or none)
=====================  ========  =====================================================

The command on a row is the one applied from that row's time until the next row's, and
so are the rotor thrusts (what the rotors produced over that step).
Other columns are allowed and ignored. Without ``ax, ay, az`` the acceleration is
derived from the velocity by a smoothing differentiator
(:mod:`discovery.differentiation`). With them, the instant each sample stands for (centred
on its row, the mean over the step before it, or the row's instant under its command) is
read from the log (:func:`discovery.residuals.accelerometer_steps`). Sample rates from
50 Hz to 1 kHz are supported; a gap longer than :data:`GAP_FACTOR` median sample periods
(more than two samples missing) splits the log into segments that are processed separately.

The JSON file::

    {"vehicle": {"mass": kg, "rotor_positions": [[x, y, z] x 4] (m, body frame),
                 "drag": [dx, dy, dz] (N s/m, optional, zero if absent),
                 "thrust_map": {"kind", "coefficient", "source"} (optional, see ThrustMap),
                 "motor_time_constant": s (optional, zero if absent)},
     "scene": {"walls": [{"point": [x, y, z], "normal": [nx, ny, nz]}, ...],
               "ground_z": number or null, "ceiling_z": number or null,
               "bodies": [{"type": "box", "size": [...], "position": [...]}, ...] (optional)},
     "gravity": 9.81}

``bodies`` (optional) holds the finite structures the flight was near: boxes, cylinders,
OBJ meshes and URDF models in the scene-file form of :mod:`wall_env.bodies` (a wall that
ends, a facade, a pier); a mesh's or URDF's ``file`` is read relative to the sidecar's
folder. Effects then read each rotor's distance to them from PyBullet, as the simulator does.

The vehicle block is the nominal model the user believes in; nothing in it says what
is missing. ``thrust_map`` records how an imported log's normalised commands became the
thrust in newtons (:mod:`discovery.importers`); it is information, the CSV's thrust is
already in newtons. ``motor_time_constant`` is the first-order lag of the thrust the rotors
produce behind the logged thrust (:mod:`wall_env.motor_lag`), when it is known: discovery
then takes the lagged thrust as what acted, and otherwise looks for a lag itself.

The CSV is UTF-8 (a byte-order mark, as spreadsheets write, is dropped) with ``,``
between fields; a header separated by ``;``, tabs or ``|`` is rejected with a message
that names the separator. ``gravity`` is optional (9.81 m/s^2 if absent); every other key shown is
required, and any other key is rejected.

:func:`read_log` rejects a malformed log with a :class:`LogFormatError` whose message
names the file, the column or key, and the row (or line); it only ever opens the
user's files for reading. :func:`write_log` writes both files.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from dataclasses import dataclass, field
from dataclasses import fields as dataclass_fields
from pathlib import Path
from typing import Any

import numpy as np

from wall_env.bodies import body_from_dict
from wall_env.motor_lag import MAX_TIME_CONSTANT
from wall_env.scene import Scene, Wall
from wall_env.vehicle import GRAVITY, VehicleParams

__all__ = [
    "REQUIRED_COLUMNS",
    "ACCELERATION_COLUMNS",
    "ROTOR_COLUMNS",
    "GAP_FACTOR",
    "QUATERNION_TOLERANCE",
    "MIN_RATE_HZ",
    "MAX_RATE_HZ",
    "LogFormatError",
    "THRUST_MAP_KINDS",
    "ThrustMap",
    "NominalVehicle",
    "FlightLog",
    "read_log",
    "write_log",
    "sidecar_path",
    "scenario_path",
    "file_sha256",
    "parse_sidecar",
    "csv_output_problem",
    "read_vehicle_and_scene",
]

REQUIRED_COLUMNS = (
    "t", "x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "wx", "wy", "wz",
    "thrust_cmd", "wx_cmd", "wy_cmd", "wz_cmd",
)
ACCELERATION_COLUMNS = ("ax", "ay", "az")
ROTOR_COLUMNS = ("rotor_0", "rotor_1", "rotor_2", "rotor_3")
GAP_FACTOR = 3.0  # a time step this many median periods long splits the log into segments
QUATERNION_TOLERANCE = 0.01  # | |q| - 1 | above this is "far from unit norm"
MIN_RATE_HZ = 50.0
MAX_RATE_HZ = 1000.0
_RATE_SLACK = 0.1  # accept median rates within 10 % outside the supported range (clock jitter)
MIN_SAMPLES = 20


class LogFormatError(ValueError):
    """A flight log that does not follow the format; the message names file, column or key, and row."""


THRUST_MAP_KINDS = {
    "collective": "collective thrust (N) = coefficient x normalised collective thrust command (0..1)",
    "motor_command": "rotor thrust (N) = coefficient x normalised motor command (0..1)",
    "motor_command_squared": "rotor thrust (N) = coefficient x normalised motor command squared "
                             "(command proportional to rotor speed)",
}


@dataclass(frozen=True)
class ThrustMap:
    """How a log's normalised commands become thrust in newtons (part of the nominal model).

    ``kind`` is one of :data:`THRUST_MAP_KINDS`; ``source`` says where the coefficient
    comes from (``given``, ``fitted on hover segments``, a parameter of the log).
    """

    kind: str
    coefficient: float
    source: str = "given"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "coefficient": self.coefficient, "source": self.source}


@dataclass(frozen=True)
class NominalVehicle:
    """The vehicle block: what the user believes about the vehicle (SI, body frame)."""

    mass: float  # kg
    rotor_positions: tuple[tuple[float, float, float], ...]  # m, 4 x 3, body frame
    drag: tuple[float, float, float] = (0.0, 0.0, 0.0)  # N s/m, body-frame linear drag (paper Eq. 4)
    thrust_map: ThrustMap | None = field(default=None, compare=False)  # how commands became newtons (import)
    motor_time_constant: float = 0.0  # s, first-order lag of the produced thrust behind the logged one (0: none)
    #: the vehicle block's keys that gave a value (the others took their defaults)
    given: frozenset[str] = field(default=frozenset({"mass", "rotor_positions", "drag"}), compare=False)

    @property
    def rotor_positions_array(self) -> np.ndarray:
        return np.asarray(self.rotor_positions, dtype=float)

    def to_vehicle_params(self) -> VehicleParams:
        """The simulator's vehicle with these fields and defaults for the rest.

        The collective thrust limit keeps the default 27 N unless the weight needs more,
        in which case it is set to twice the weight (the log says nothing about it).
        """
        thrust_max = 27.0 if self.mass * GRAVITY < 27.0 / 1.2 else 2.0 * self.mass * GRAVITY
        return VehicleParams(mass=self.mass, arm_length=self.arm_length, rotor_positions=self.rotor_positions,
                             drag=self.drag, thrust_max=thrust_max, motor_time_constant=self.motor_time_constant)

    @property
    def arm_length(self) -> float:
        """The rotors' mean horizontal distance from the centre of mass (m)."""
        return float(np.mean(np.linalg.norm(self.rotor_positions_array[:, :2], axis=1)))

    def vehicle_fields(self, motor_lag_found: bool = False) -> dict[str, str]:
        """Where each field of :meth:`to_vehicle_params`' vehicle came from: the vehicle block (``given``), derived
        from it, found by discovery, or the paper vehicle's default (the log says nothing about it)."""
        default = "defaulted: the paper's 1 kg ducted vehicle (the log says nothing about it)"
        out = {f.name: default for f in dataclass_fields(VehicleParams)}
        out["mass"] = "given"
        out["rotor_positions"] = "given"
        out["arm_length"] = "derived: the rotors' mean horizontal distance from the centre of mass"
        out["drag"] = "given" if "drag" in self.given else "defaulted: 0 (the vehicle block gives no drag)"
        out["thrust_max"] = ("defaulted: 27 N" if self.mass * GRAVITY < 27.0 / 1.2 else
                             "derived: twice the weight (the default 27 N would not lift it)")
        out["motor_time_constant"] = ("given" if "motor_time_constant" in self.given else
                                      "found: the motor lag discovery fitted" if motor_lag_found else
                                      "defaulted: 0 (no lag given or found)")
        return out

    @classmethod
    def from_vehicle_params(cls, vehicle: VehicleParams) -> NominalVehicle:
        rotors: Any = tuple(tuple(float(c) for c in r) for r in vehicle.rotor_positions)
        drag: Any = tuple(float(c) for c in vehicle.drag)
        return cls(float(vehicle.mass), rotors, drag, motor_time_constant=float(vehicle.motor_time_constant))

    def to_dict(self) -> dict[str, Any]:
        data = {"mass": self.mass, "rotor_positions": [list(r) for r in self.rotor_positions], "drag": list(self.drag)}
        if self.thrust_map is not None:
            data["thrust_map"] = self.thrust_map.to_dict()
        if self.motor_time_constant > 0:
            data["motor_time_constant"] = self.motor_time_constant
        return data


@dataclass
class FlightLog:
    """One flight log in memory. Arrays have one row per sample; frames are in the names."""

    t: np.ndarray  # (n,) s
    p_world: np.ndarray  # (n, 3) m
    v_world: np.ndarray  # (n, 3) m/s
    q_body_to_world: np.ndarray  # (n, 4) [w, x, y, z], unit
    omega_body: np.ndarray  # (n, 3) rad/s, measured
    thrust_cmd: np.ndarray  # (n,) N
    omega_cmd_body: np.ndarray  # (n, 3) rad/s
    vehicle: NominalVehicle
    scene: Scene
    gravity: float = GRAVITY
    a_world: np.ndarray | None = None  # (n, 3) m/s^2, measured, optional
    rotor_thrusts: np.ndarray | None = None  # (n, 4) N, optional
    source: str = "<memory>"
    extra_columns: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.t)
        for name in ("p_world", "v_world", "omega_body", "omega_cmd_body"):
            _check_shape(self, name, (n, 3))
        _check_shape(self, "q_body_to_world", (n, 4))
        _check_shape(self, "thrust_cmd", (n,))
        if self.a_world is not None:
            _check_shape(self, "a_world", (n, 3))
        if self.rotor_thrusts is not None:
            _check_shape(self, "rotor_thrusts", (n, 4))

    @property
    def n_samples(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def rate_hz(self) -> float:
        """Median sample rate."""
        return float(1.0 / np.median(np.diff(self.t)))

    @property
    def R_body_to_world(self) -> np.ndarray:
        """Rotation matrices ``(n, 3, 3)`` of the (normalised) quaternions."""
        return quaternions_to_matrices(self.q_body_to_world)

    @property
    def total_thrust(self) -> np.ndarray:
        """``(n,)`` N: the rotors' logged thrusts summed where the log has them, else the commanded thrust."""
        return self.rotor_thrusts.sum(axis=1) if self.rotor_thrusts is not None else self.thrust_cmd

    def free_acceleration(self, direction: np.ndarray) -> np.ndarray:
        """``(n,)`` m/s^2: the acceleration the thrust and gravity alone give along the unit vector ``direction``
        (world); what the log's vehicle would do with nothing else acting on it."""
        return (self.total_thrust * (self.R_body_to_world[:, :, 2] @ direction) / self.vehicle.mass
                - self.gravity * direction[2])

    def segments(self) -> list[slice]:
        """Contiguous stretches without gaps longer than :data:`GAP_FACTOR` median periods, counted in whole periods:
        a step of exactly three (two samples dropped) came out a rounding error longer and split a 250 Hz log with
        one sample in twenty dropped into 36 pieces, whose ends left a quadratic drag 11 % off."""
        dt = np.diff(self.t)
        breaks = np.flatnonzero(dt > (GAP_FACTOR + 0.5) * np.median(dt)) + 1
        edges = [0, *breaks.tolist(), self.n_samples]
        return [slice(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]

    def sidecar(self, relative_to: str | Path | None = None) -> dict[str, Any]:
        """The JSON sidecar as a dictionary; mesh and URDF files of the scene's bodies relative to folder
        ``relative_to`` where they lie below it."""
        return {"vehicle": self.vehicle.to_dict(), "scene": self.scene.to_dict(relative_to), "gravity": self.gravity}

    def select(self, index: slice | np.ndarray) -> FlightLog:
        """The samples ``index`` as a new log (same vehicle and scene)."""
        take = lambda a: None if a is None else a[index]  # noqa: E731
        return FlightLog(self.t[index], self.p_world[index], self.v_world[index], self.q_body_to_world[index],
                         self.omega_body[index], self.thrust_cmd[index], self.omega_cmd_body[index], self.vehicle,
                         self.scene, self.gravity, take(self.a_world), take(self.rotor_thrusts), self.source,
                         {k: v[index] for k, v in self.extra_columns.items()})


def _check_shape(log: FlightLog, name: str, shape: tuple[int, ...]) -> None:
    value = np.asarray(getattr(log, name), dtype=float)
    if value.shape != shape:
        raise ValueError(f"FlightLog.{name} must have shape {shape}, got {value.shape}")
    setattr(log, name, value)


def quaternions_to_matrices(q: np.ndarray) -> np.ndarray:
    """``R_body_to_world`` ``(n, 3, 3)`` of quaternions ``(n, 4)`` [w, x, y, z], normalised first
    (a log's quaternions are unit only to its precision); :func:`wall_env.rotations.quat_to_rotation_rows`."""
    from wall_env.rotations import quat_to_rotation_rows

    q = np.asarray(q, dtype=float)
    return quat_to_rotation_rows(q / np.linalg.norm(q, axis=1, keepdims=True))


def sidecar_path(csv_path: str | Path) -> Path:
    """The JSON file beside a CSV log (same base name)."""
    return Path(csv_path).with_suffix(".json")


def scenario_path(csv_path: str | Path) -> Path:
    """Where ``wall-inspector fly`` writes the ground truth of a simulated log: ``<name>.scenario.json``."""
    path = Path(csv_path)
    return path.with_name(path.stem + ".scenario.json")


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes: ``wall-inspector fly`` records its log's in the scenario file, and the
    closed-loop check compares it before it calls that world the log's ground truth."""
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# ====================================================================== reading
def read_log(path: str | Path) -> FlightLog:
    """Read and check a log (the CSV path; the JSON sidecar is found beside it).

    Raises :class:`LogFormatError` for a malformed log and ``FileNotFoundError`` for a
    missing file; both messages name the file. The files are opened read-only.
    """
    csv_path = Path(path)
    if not csv_path.is_file():
        raise FileNotFoundError(f"flight log {csv_path} does not exist")
    json_path = sidecar_path(csv_path)
    if json_path == csv_path:
        raise LogFormatError(f"{csv_path}: a flight log is a .csv file with a .json sidecar of the same base name")
    if not json_path.is_file():
        raise FileNotFoundError(f"{csv_path}: its JSON sidecar {json_path} does not exist")
    vehicle, scene, gravity = _read_sidecar(json_path)
    columns = _read_columns(csv_path)
    return _assemble(csv_path, columns, vehicle, scene, gravity)


def _read_text(path: Path) -> str:
    """The file's text; a UTF-8 byte-order mark (as spreadsheet exports write) is dropped."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:  # read-only
            return handle.read()
    except UnicodeDecodeError as exc:
        raise LogFormatError(f"{path}: byte {exc.start} is not UTF-8 text; a flight log is a UTF-8 "
                             "(or ASCII) CSV file") from None


def _separator_hint(path: Path, header_line: str) -> None:
    """Reject a header that uses another field separator than ',' with a message that says so."""
    if "," in header_line:
        return
    for separator, name in ((";", "';' (semicolon)"), ("\t", "a tab"), ("|", "'|'")):
        if separator in header_line and "t" in (h.strip() for h in header_line.split(separator)):
            raise LogFormatError(f"{path}: line 1 (header): fields are separated by {name}; the flight-log "
                                 "format separates fields with ',' (in a spreadsheet, export as CSV with "
                                 "comma as the separator and '.' as the decimal mark)")


def _read_columns(path: Path) -> dict[str, np.ndarray]:
    text = _read_text(path)
    if "\x00" in text:
        raise LogFormatError(f"{path}: contains NUL characters; a flight log is a text CSV file")
    _separator_hint(path, text.split("\n", 1)[0])
    reader = csv.reader(io.StringIO(text))
    try:
        header = next(reader)
    except StopIteration:
        raise LogFormatError(
            f"{path}: the file is empty; expected a header row with columns {list(REQUIRED_COLUMNS)}") from None
    except csv.Error as exc:
        raise LogFormatError(f"{path}: line 1 (header): not a readable CSV row ({exc})") from None
    header = [h.strip() for h in header]
    duplicates = sorted({h for h in header if header.count(h) > 1})
    if duplicates:
        raise LogFormatError(f"{path}: line 1 (header): column(s) {duplicates} appear more than once")
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise LogFormatError(f"{path}: line 1 (header): missing required column(s) {missing}; "
                             f"required: {list(REQUIRED_COLUMNS)}")
    for group in (ACCELERATION_COLUMNS, ROTOR_COLUMNS):
        present = [c for c in group if c in header]
        if present and len(present) != len(group):
            absent = [c for c in group if c not in header]
            raise LogFormatError(f"{path}: line 1 (header): optional columns {list(group)} come all together; "
                                 f"has {present} but not column(s) {absent}")
    rows: list[tuple[int, list[str]]] = []
    try:
        numbered = list(enumerate(reader, start=2))
    except csv.Error as exc:
        raise LogFormatError(f"{path}: line {reader.line_num}: not a readable CSV row ({exc})") from None
    for line_number, row in numbered:
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(row) != len(header):
            raise LogFormatError(f"{path}: line {line_number} (sample {len(rows) + 1}) has {len(row)} fields, "
                                 f"the header has {len(header)}")
        rows.append((line_number, row))
    if len(rows) < MIN_SAMPLES:
        raise LogFormatError(f"{path}: {len(rows)} sample row(s); a log needs at least {MIN_SAMPLES}")
    wanted = [c for c in (*REQUIRED_COLUMNS, *ACCELERATION_COLUMNS, *ROTOR_COLUMNS) if c in header]
    others = [c for c in header if c not in wanted]
    columns: dict[str, np.ndarray] = {}
    for name in wanted + others:
        j = header.index(name)
        cells = [row[j].strip() for _, row in rows]
        try:
            values = np.asarray(cells, dtype=float)
        except ValueError:
            if name in others:  # an ignored column need not be numeric
                continue
            i = next(i for i, cell in enumerate(cells) if not _is_number(cell))
            raise LogFormatError(f"{path}: line {rows[i][0]} (sample {i + 1}), column '{name}': "
                                 f"{cells[i]!r} is not a number") from None
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size and name not in others:
            i = int(bad[0])
            raise LogFormatError(f"{path}: line {rows[i][0]} (sample {i + 1}), column '{name}': "
                                 f"value {cells[i]!r} is not finite (NaN or inf)")
        columns[name] = values
    columns["_line"] = np.array([line for line, _ in rows])
    return columns


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _assemble(path: Path, c: dict[str, np.ndarray], vehicle: NominalVehicle, scene: Scene, gravity: float) -> FlightLog:
    lines = c["_line"]
    t = c["t"]
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise LogFormatError(f"{path}: line {lines[i]} (sample {i + 1}), column 't': time {t[i]:.9g} s does not "
                             f"increase (previous sample {t[i - 1]:.9g} s); time must be strictly increasing")
    rate = 1.0 / float(np.median(dt))
    if not MIN_RATE_HZ * (1 - _RATE_SLACK) <= rate <= MAX_RATE_HZ * (1 + _RATE_SLACK):
        raise LogFormatError(f"{path}: column 't': median sample rate {rate:.1f} Hz is outside the supported "
                             f"{MIN_RATE_HZ:g} Hz to {MAX_RATE_HZ:g} Hz")
    q = np.column_stack([c[k] for k in ("qw", "qx", "qy", "qz")])
    with np.errstate(over="ignore"):  # a huge component gives norm inf, rejected below
        norms = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(~(np.abs(norms - 1.0) <= QUATERNION_TOLERANCE))
    if bad.size:
        i = int(bad[0])
        raise LogFormatError(f"{path}: line {lines[i]} (sample {i + 1}), columns 'qw, qx, qy, qz': quaternion norm "
                             f"{norms[i]:.4f} is far from 1 (tolerance {QUATERNION_TOLERANCE})")
    stack = lambda names: np.column_stack([c[k] for k in names])  # noqa: E731
    rotor = stack(ROTOR_COLUMNS) if "rotor_0" in c else None
    if rotor is not None and np.any(rotor < 0):
        i = int(np.flatnonzero(np.any(rotor < 0, axis=1))[0])
        j = int(np.flatnonzero(rotor[i] < 0)[0])
        raise LogFormatError(f"{path}: line {lines[i]} (sample {i + 1}), column '{ROTOR_COLUMNS[j]}': "
                             f"a rotor thrust cannot be negative ({rotor[i, j]:.9g} N)")
    known = set(REQUIRED_COLUMNS) | set(ACCELERATION_COLUMNS) | set(ROTOR_COLUMNS) | {"_line"}
    return FlightLog(
        t=t,
        p_world=stack(("x", "y", "z")),
        v_world=stack(("vx", "vy", "vz")),
        q_body_to_world=q / norms[:, None],
        omega_body=stack(("wx", "wy", "wz")),
        thrust_cmd=c["thrust_cmd"],
        omega_cmd_body=stack(("wx_cmd", "wy_cmd", "wz_cmd")),
        vehicle=vehicle,
        scene=scene,
        gravity=gravity,
        a_world=stack(ACCELERATION_COLUMNS) if "ax" in c else None,
        rotor_thrusts=rotor,
        source=str(path),
        extra_columns={k: v for k, v in c.items() if k not in known},
    )


# ---------------------------------------------------------------------- the JSON sidecar
_SCHEMA_TOP = {"vehicle": True, "scene": True, "gravity": False}  # key -> required
_SCHEMA_VEHICLE = {"mass": True, "rotor_positions": True, "drag": False, "thrust_map": False,
                   "motor_time_constant": False}
_SCHEMA_THRUST_MAP = {"kind": True, "coefficient": True, "source": False}
_SCHEMA_SCENE = {"walls": True, "ground_z": True, "ceiling_z": True, "bodies": False}
_SCHEMA_WALL = {"point": True, "normal": True}


class _Sidecar:
    """Checks of the JSON document, with messages naming the file, the key and its line."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.lines = text.splitlines()

    def _line_of(self, key: str) -> str:
        needle = f'"{key.split(".")[-1].split("[")[0]}"'
        for number, line in enumerate(self.lines, start=1):
            if needle in line:
                return f", line {number}"
        return ""

    def fail(self, key: str, message: str) -> LogFormatError:
        shown = key if key.isprintable() else repr(key)[1:-1]  # a key with a line break stays on one line
        return LogFormatError(f"{self.path}: key '{shown}'{self._line_of(key)}: {message}")

    def mapping(self, key: str, value: Any, schema: dict[str, bool]) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(key, f"must be a JSON object, got {_type_name(value)}")
        for name in value:
            if name not in schema:
                raise self.fail(f"{key}.{name}" if key else name,
                                f"unknown key; allowed in {key or 'the top level'}: {sorted(schema)}")
        for name, required in schema.items():
            if required and name not in value:
                raise self.fail(f"{key}.{name}" if key else name, "required key is missing")
        return value

    def number(self, key: str, value: Any, low: float = -math.inf, high: float = math.inf,
               allow_null: bool = False) -> Any:  # a float, or None if allowed
        if value is None and allow_null:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            expected = "a number or null" if allow_null else "a number"
            raise self.fail(key, f"must be {expected}, got {_type_name(value)} {value!r}")
        if not math.isfinite(value) or not low <= value <= high:
            raise self.fail(key, f"must be a finite number in [{low:g}, {high:g}], got {value!r}")
        return float(value)

    def vector(self, key: str, value: Any, size: int, low: float = -math.inf) -> Any:  # a tuple of size floats
        if not isinstance(value, list) or len(value) != size:
            raise self.fail(key, f"must be a list of {size} numbers, got {_type_name(value)} {value!r}")
        return tuple(self.number(f"{key}[{i}]", v, low=low) for i, v in enumerate(value))


def _type_name(value: Any) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "a boolean", type(None): "null",
            int: "a number", float: "a number"}.get(type(value), type(value).__name__)


def _read_sidecar(path: Path) -> tuple[NominalVehicle, Scene, float]:
    text = _read_text(path)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise LogFormatError(f"{path}: line {exc.lineno}: not valid JSON ({exc.msg})") from None
    return parse_sidecar(path, text, data)


def read_vehicle_and_scene(vehicle_path: str | Path, scene_path: str | Path) -> tuple[NominalVehicle, Scene, float]:
    """The nominal vehicle and the scene from two YAML (or JSON) files, checked like a sidecar's blocks.

    The vehicle file holds the sidecar's ``vehicle`` block (``mass``, ``rotor_positions``,
    optional ``drag`` and ``thrust_map``); the scene file the ``scene`` block (``walls``,
    ``ground_z``, ``ceiling_z``) and optionally ``gravity``. Importers use them for logs
    that carry neither (PX4 ULog, ROS 2 bags).
    """
    from wall_env.validation import read_mapping

    vehicle = read_mapping(vehicle_path, "vehicle file")
    scene = read_mapping(scene_path, "scene file")
    gravity = scene.pop("gravity", None)
    data: dict[str, Any] = {"vehicle": vehicle, "scene": scene}
    if gravity is not None:
        data["gravity"] = gravity
    text = Path(vehicle_path).read_text() + "\n" + Path(scene_path).read_text()
    return parse_sidecar(Path(f"{vehicle_path} + {scene_path}"), text, data)


def parse_sidecar(path: Path, text: str, data: Any) -> tuple[NominalVehicle, Scene, float]:
    """Check a parsed sidecar document (``text`` only serves line numbers in messages)."""
    check = _Sidecar(path, text)
    check.mapping("", data, _SCHEMA_TOP)
    vehicle_data = check.mapping("vehicle", data["vehicle"], _SCHEMA_VEHICLE)
    mass = check.number("vehicle.mass", vehicle_data["mass"], low=1e-3, high=100.0)
    rotors = vehicle_data["rotor_positions"]
    if not isinstance(rotors, list) or len(rotors) != 4:
        raise check.fail("vehicle.rotor_positions", f"must be a list of 4 [x, y, z] points, got {rotors!r}")
    rotor_positions = tuple(check.vector(f"vehicle.rotor_positions[{j}]", r, 3) for j, r in enumerate(rotors))
    drag = (check.vector("vehicle.drag", vehicle_data["drag"], 3, low=0.0) if "drag" in vehicle_data
            else (0.0, 0.0, 0.0))
    scene_data = check.mapping("scene", data["scene"], _SCHEMA_SCENE)
    walls_data = scene_data["walls"]
    if not isinstance(walls_data, list):
        raise check.fail("scene.walls", f"must be a list of walls, got {_type_name(walls_data)}")
    walls = []
    for k, wall in enumerate(walls_data):
        wall = check.mapping(f"scene.walls[{k}]", wall, _SCHEMA_WALL)
        point = check.vector(f"scene.walls[{k}].point", wall["point"], 3)
        normal = check.vector(f"scene.walls[{k}].normal", wall["normal"], 3)
        if np.linalg.norm(normal) < 1e-9:
            raise check.fail(f"scene.walls[{k}].normal", "must be a non-zero vector")
        walls.append(Wall(point, normal))
    ground_z = check.number("scene.ground_z", scene_data["ground_z"], -1e4, 1e4, allow_null=True)
    ceiling_z = check.number("scene.ceiling_z", scene_data["ceiling_z"], -1e4, 1e4, allow_null=True)
    if ground_z is not None and ceiling_z is not None and ceiling_z <= ground_z:
        raise check.fail("scene.ceiling_z", f"must be above scene.ground_z = {ground_z}, got {ceiling_z}")
    bodies_data = scene_data.get("bodies", [])
    if not isinstance(bodies_data, list):
        raise check.fail("scene.bodies", f"must be a list of bodies, got {_type_name(bodies_data)}")
    bodies = []
    for k, body in enumerate(bodies_data):
        try:
            bodies.append(body_from_dict(body, base=path.parent, where=f"scene.bodies[{k}]"))
        except ValueError as exc:
            raise check.fail(f"scene.bodies[{k}]", str(exc)) from None
    gravity = check.number("gravity", data["gravity"], 0.1, 100.0) if "gravity" in data else GRAVITY
    thrust_map = None
    if "thrust_map" in vehicle_data:
        tm = check.mapping("vehicle.thrust_map", vehicle_data["thrust_map"], _SCHEMA_THRUST_MAP)
        kind = tm["kind"]
        if kind not in THRUST_MAP_KINDS:
            raise check.fail("vehicle.thrust_map.kind", f"must be one of {list(THRUST_MAP_KINDS)}, got {kind!r}")
        coefficient = check.number("vehicle.thrust_map.coefficient", tm["coefficient"], 1e-9, 1e9)
        source = tm.get("source", "given")
        if not isinstance(source, str):
            raise check.fail("vehicle.thrust_map.source", f"must be a string, got {_type_name(source)}")
        thrust_map = ThrustMap(kind, coefficient, source)
    motor_time_constant = (check.number("vehicle.motor_time_constant", vehicle_data["motor_time_constant"], 0.0,
                                        MAX_TIME_CONSTANT) if "motor_time_constant" in vehicle_data else 0.0)
    vehicle = NominalVehicle(mass, rotor_positions, drag, thrust_map, motor_time_constant,
                             frozenset(k for k in vehicle_data if k in _SCHEMA_VEHICLE))
    try:
        vehicle.to_vehicle_params()
    except ValueError as exc:
        raise check.fail("vehicle", str(exc)) from None
    return vehicle, Scene(tuple(walls), ground_z, ceiling_z, tuple(bodies)), gravity


# ====================================================================== writing
def csv_output_problem(out: str | Path, overwrite: bool = False, extra: tuple[Path, ...] = ()) -> str | None:
    """Why a log cannot be written to ``out`` (one line naming the option), or None; checked before any work.

    ``extra``: other files the command writes beside the log.
    """
    path = Path(out)
    if path.suffix.lower() != ".csv":
        return f"--out must be a .csv path (the JSON sidecar goes beside it), got {path}"
    if path.is_dir():
        return f"--out {path} is a folder; give a .csv file path"
    if not overwrite:
        for target in (path, sidecar_path(path), *extra):
            if target.exists():
                return f"{target} exists; pass --overwrite to replace it or choose another --out"
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        return f"--out {path}: cannot create or write into {parent}"
    return None


def write_log(log: FlightLog, path: str | Path, *, overwrite: bool = False, precision: int = 9) -> tuple[Path, Path]:
    """Write ``log`` as ``path`` (CSV) and its JSON sidecar; returns both paths.

    Refuses to replace existing files unless ``overwrite``.
    """
    csv_path = Path(path)
    if csv_path.suffix.lower() != ".csv":
        raise ValueError(f"a flight log is written to a .csv path, got {csv_path}")
    json_path = sidecar_path(csv_path)
    if not overwrite:
        for target in (csv_path, json_path):
            if target.exists():
                raise FileExistsError(f"{target} exists; pass overwrite=True (or --overwrite) to replace it")
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    columns = [log.t[:, None], log.p_world, log.v_world, log.q_body_to_world, log.omega_body, log.thrust_cmd[:, None],
               log.omega_cmd_body]
    header = list(REQUIRED_COLUMNS)
    if log.a_world is not None:
        columns.append(log.a_world)
        header += ACCELERATION_COLUMNS
    if log.rotor_thrusts is not None:
        columns.append(log.rotor_thrusts)
        header += ROTOR_COLUMNS
    table = np.hstack(columns)
    with open(csv_path, "w", newline="") as handle:
        handle.write(",".join(header) + "\n")
        np.savetxt(handle, table, delimiter=",", fmt=f"%.{precision}g")
    json_path.write_text(json.dumps(log.sidecar(relative_to=json_path.parent), indent=2) + "\n")
    return csv_path, json_path
