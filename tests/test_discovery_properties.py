"""Property-based checks of the flight-log reader and the importers' resampling (Hypothesis).

Whatever a log holds, reading it gives either a valid log (finite arrays of the right
shapes, strictly increasing time, unit quaternions) or a :class:`LogFormatError` whose
one-line message names the file and the column, key or line; never NaN, never an
exception from inside NumPy, SciPy or CasADi.
"""

from __future__ import annotations

import json
import math
import re
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from discovery.flight_log import REQUIRED_COLUMNS, LogFormatError, read_log
from discovery.importers.resample import Signal, common_clock, hold, interpolate, interpolate_attitude, valid_mask

EXAMPLES = settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
N_ROWS = 24
_ROTORS = [[0.0707, 0.0707, 0.0], [-0.0707, 0.0707, 0.0], [-0.0707, -0.0707, 0.0], [0.0707, -0.0707, 0.0]]
SIDECAR = {"vehicle": {"mass": 1.0, "rotor_positions": _ROTORS, "drag": [0.3, 0.3, 0.2]},
           "scene": {"walls": [{"point": [0, 0, 0], "normal": [1, 0, 0]}], "ground_z": 0.0, "ceiling_z": None},
           "gravity": 9.81}


def _base_table() -> list[list[str]]:
    rows = []
    for k in range(N_ROWS):
        values = dict.fromkeys(REQUIRED_COLUMNS, 0.0)
        values.update(t=0.01 * k, x=0.5, z=1.0, qw=1.0, thrust_cmd=9.81)
        rows.append([repr(values[c]) for c in REQUIRED_COLUMNS])
    return rows


cell_values = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", " ", "abc", "1e400", "-0", "nan", "inf", "1,5", "0x10", "\u00e9", "1 2", '"3"']),
    st.integers(-10**6, 10**6).map(str),
)
mutation = st.one_of(
    st.tuples(st.just("cell"), st.integers(0, N_ROWS - 1), st.integers(0, len(REQUIRED_COLUMNS) - 1), cell_values),
    st.tuples(st.just("drop_column"), st.integers(0, len(REQUIRED_COLUMNS) - 1)),
    st.tuples(st.just("rename_column"), st.integers(0, len(REQUIRED_COLUMNS) - 1),
              st.sampled_from(["t", "x", "T", "", "rotor_0", "ax", "extra"])),
    st.tuples(st.just("swap_rows"), st.integers(0, N_ROWS - 1), st.integers(0, N_ROWS - 1)),
    st.tuples(st.just("truncate_row"), st.integers(0, N_ROWS - 1)),
    st.tuples(st.just("drop_rows"), st.integers(0, N_ROWS)),
    st.tuples(st.just("separator"), st.sampled_from([";", "\t", "|"])),
    st.tuples(st.just("bom")),
    st.tuples(st.just("scale_time"), st.sampled_from([1e-6, 1e-3, 0.1, 10.0, -1.0])),
    st.tuples(st.just("quaternion"), st.integers(0, N_ROWS - 1), st.floats(-2, 2, allow_nan=False)),
)


def _render(mutations: list) -> bytes:
    header = list(REQUIRED_COLUMNS)
    rows = _base_table()
    separator, bom = ",", False
    for m in mutations:
        kind = m[0]
        if kind == "cell" and m[1] < len(rows) and m[2] < len(rows[m[1]]):
            rows[m[1]][m[2]] = m[3]
        elif kind == "drop_column" and m[1] < len(header):
            del header[m[1]]
            for r in rows:
                if m[1] < len(r):
                    del r[m[1]]
        elif kind == "rename_column" and m[1] < len(header):
            header[m[1]] = m[2]
        elif kind == "swap_rows" and m[1] < len(rows) and m[2] < len(rows):
            rows[m[1]], rows[m[2]] = rows[m[2]], rows[m[1]]
        elif kind == "truncate_row" and m[1] < len(rows):
            rows[m[1]] = rows[m[1]][:-1]
        elif kind == "drop_rows":
            rows = rows[: m[1]]
        elif kind == "separator":
            separator = m[1]
        elif kind == "bom":
            bom = True
        elif kind == "scale_time" and "t" in header:
            j = header.index("t")
            for r in rows:
                try:
                    r[j] = repr(float(r[j]) * m[1])
                except (ValueError, IndexError):
                    pass
        elif kind == "quaternion" and "qw" in header and m[1] < len(rows):
            j = header.index("qw")
            if j < len(rows[m[1]]):
                rows[m[1]][j] = repr(m[2])
    text = "\n".join(separator.join(r) for r in [header, *rows]) + "\n"
    return (b"\xef\xbb\xbf" if bom else b"") + text.encode("utf-8")


def _check_valid(log) -> None:
    n = log.n_samples
    assert n >= 20
    for name in ("p_world", "v_world", "omega_body", "omega_cmd_body"):
        value = getattr(log, name)
        assert value.shape == (n, 3) and np.all(np.isfinite(value)), name
    assert np.all(np.isfinite(log.thrust_cmd)) and np.all(np.isfinite(log.t))
    assert np.all(np.diff(log.t) > 0)
    assert np.allclose(np.linalg.norm(log.q_body_to_world, axis=1), 1.0)
    assert 45.0 <= log.rate_hz <= 1100.0


def _check_error(exc: LogFormatError, path: Path) -> None:
    message = str(exc)
    assert message.startswith(str(path)), message
    assert "\n" not in message
    assert re.search(r"column|key|line|row|sample|file|byte", message), message


@EXAMPLES
@given(st.lists(mutation, max_size=4))
def test_any_csv_content_reads_as_a_valid_log_or_a_named_error(mutations):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "flight.csv"
        path.write_bytes(_render(mutations))
        path.with_suffix(".json").write_text(json.dumps(SIDECAR))
        try:
            log = read_log(path)
        except LogFormatError as exc:
            _check_error(exc, path)
        else:
            _check_valid(log)


json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10**9, 10**9), st.floats(allow_nan=False, allow_infinity=False),
              st.text(max_size=5)),
    lambda children: st.one_of(st.lists(children, max_size=5), st.dictionaries(st.text(max_size=8), children,
                                                                                max_size=4)),
    max_leaves=12,
)
sidecar_paths = st.sampled_from([
    ("vehicle", "mass"), ("vehicle", "rotor_positions"), ("vehicle", "drag"), ("vehicle", "thrust_map"),
    ("vehicle",), ("scene", "walls"), ("scene", "ground_z"), ("scene", "ceiling_z"), ("scene",), ("gravity",),
    ("bogus",), ("scene", "walls", 0, "normal"), ("scene", "walls", 0, "point"), ("vehicle", "rotor_positions", 2),
])


@EXAMPLES
@given(st.lists(st.tuples(sidecar_paths, json_values), max_size=3), st.booleans())
def test_any_sidecar_content_reads_or_names_the_key(edits, delete):
    data = json.loads(json.dumps(SIDECAR))
    for path_keys, value in edits:
        node = data
        try:
            for key in path_keys[:-1]:
                node = node[key]
            if delete and isinstance(node, dict):
                node.pop(path_keys[-1], None)
            else:
                node[path_keys[-1]] = value
        except (KeyError, IndexError, TypeError):
            continue
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "flight.csv"
        path.write_bytes(_render([]))
        sidecar = path.with_suffix(".json")
        sidecar.write_text(json.dumps(data))
        try:
            log = read_log(path)
        except LogFormatError as exc:
            _check_error(exc, sidecar)
        else:
            _check_valid(log)
            assert math.isfinite(log.vehicle.mass) and log.vehicle.mass > 0
            assert all(np.isfinite(np.asarray(w.normal)).all() for w in log.scene.walls)


times = st.lists(st.one_of(st.floats(-10.0, 10.0), st.sampled_from([math.nan, math.inf, -math.inf])),
                 min_size=0, max_size=30)


@EXAMPLES
@given(times, st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=120),
       st.floats(50.0, 1000.0))
def test_resampling_gives_finite_values_or_a_clear_error(t, values, rate):
    n = len(t)
    v = np.resize(np.asarray(values + [0.0], dtype=float), n * 4).reshape(n, 4) if n else np.zeros((0, 4))
    signal = Signal("topic", np.asarray(t, dtype=float), v)
    try:
        clock = common_clock([signal], rate)
    except ValueError as exc:
        assert "'topic'" in str(exc)
        return
    assert np.all(np.isfinite(clock)) and np.all(np.diff(clock) > 0)
    ok = valid_mask(signal, clock)
    assert ok.shape == clock.shape
    assert np.all(np.isfinite(interpolate(signal, clock)))
    assert np.all(np.isfinite(hold(signal, clock)))
    try:
        q = interpolate_attitude(signal, clock)
    except ValueError as exc:
        assert "'topic'" in str(exc)
    else:
        assert np.all(np.isfinite(q)) and np.allclose(np.linalg.norm(q, axis=1), 1.0)
