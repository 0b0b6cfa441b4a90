"""Careless input to fly, discover and the log reader: one clear line, exit code 2, checked before any work."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from discovery.flight_log import LogFormatError, read_log, sidecar_path
from wall_inspector.cli import main


@pytest.fixture(scope="module")
def wall_log(tmp_path_factory) -> Path:
    """A 12 s survey in the suction zone (suction flown)."""
    out = tmp_path_factory.mktemp("bad") / "wall.csv"
    assert main(["fly", "--scenario", "wall-survey", "--effects", "wall_suction:k_s=4.1,d_thr=0.132", "--seed", "5",
                 "--duration", "12", "--out", str(out)]) == 0
    return out


def _one_line(capsys, contains: str) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err
    assert contains in lines[0], lines[0]
    return lines[0]


# ---------------------------------------------------------------------- output paths, before any work
def test_discover_out_naming_an_existing_file_fails_first(tmp_path, capsys):
    existing = tmp_path / "results"
    existing.write_text("keep me")
    # the log does not even exist: the output is checked before anything is read
    assert main(["discover", str(tmp_path / "nowhere.csv"), "--out", str(existing)]) == 2
    _one_line(capsys, f"--out {existing} exists and is not a folder")
    assert existing.read_text() == "keep me"


@pytest.mark.parametrize("name, message", [("x.txt", "--out must be a .csv path"),
                                           ("existing.csv", "existing.csv exists; pass --overwrite")])
def test_fly_checks_its_output_path_before_flying(tmp_path, capsys, name, message):
    (tmp_path / "existing.csv").write_text("keep me")
    # an unknown effect would fail later, in the env; the path is checked first
    assert main(["fly", "--effects", "wind:F=1", "--out", str(tmp_path / name)]) == 2
    _one_line(capsys, message)
    assert (tmp_path / "existing.csv").read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["existing.csv"]


# ---------------------------------------------------------------------- options and short logs
@pytest.mark.parametrize("argv, message", [
    (["--window", "-1"], "--window must be in [0.02, 10] s, got -1.0"),
    (["--horizon", "1000"], "--horizon must be in [0.02, 10] s, got 1000.0"),
    (["--window", "nan"], "--window must be in [0.02, 10] s"),
])
def test_discover_rejects_bad_options_with_their_range(wall_log, tmp_path, capsys, argv, message):
    assert main(["discover", str(wall_log), "--out", str(tmp_path / "r"), *argv]) == 2
    _one_line(capsys, message)
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("samples", [30, 45])
def test_a_short_log_says_how_long_a_log_must_be(wall_log, tmp_path, capsys, samples):
    short = tmp_path / "short.csv"
    lines = wall_log.read_text().splitlines()
    short.write_text("\n".join(lines[: samples + 1]) + "\n")
    shutil.copy(sidecar_path(wall_log), sidecar_path(short))
    assert read_log(short).n_samples == samples  # a valid log
    assert main(["discover", str(short), "--out", str(tmp_path / "r")]) == 2
    line = _one_line(capsys, f"({samples} samples); discovery needs at least 4 s")
    assert "--window" in line and "--horizon" in line


def test_a_reversed_wall_normal_is_reported_as_a_sidecar_error(wall_log, tmp_path, capsys):
    flipped = tmp_path / "flipped.csv"
    shutil.copy(wall_log, flipped)
    sidecar = json.loads(sidecar_path(wall_log).read_text())
    wall = sidecar["scene"]["walls"][0]
    wall["normal"] = [-c for c in wall["normal"]]
    sidecar_path(flipped).write_text(json.dumps(sidecar))
    assert main(["discover", str(flipped), "--out", str(tmp_path / "r"), "--quiet", "--no-plots"]) == 0
    out = capsys.readouterr().out
    first = out.splitlines()[0]
    assert first.startswith("WARNING likely sidecar error: the rotors are behind wall 0")
    assert "flip the sign of scene.walls[0].normal" in first
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert any("flip the sign" in note for note in report["notes"])


# ---------------------------------------------------------------------- spreadsheet exports
def test_a_csv_with_a_byte_order_mark_reads_like_the_plain_file(wall_log, tmp_path):
    bom = tmp_path / "excel.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + wall_log.read_bytes())
    shutil.copy(sidecar_path(wall_log), sidecar_path(bom))
    plain, marked = read_log(wall_log), read_log(bom)
    assert marked.n_samples == plain.n_samples
    assert (marked.p_world == plain.p_world).all() and (marked.t == plain.t).all()
    # a sidecar saved with a byte-order mark reads too
    sidecar_path(bom).write_bytes(b"\xef\xbb\xbf" + sidecar_path(wall_log).read_bytes())
    assert read_log(bom).vehicle == plain.vehicle


def test_a_semicolon_separated_csv_is_told_about_the_separator(wall_log, tmp_path):
    semi = tmp_path / "semi.csv"
    semi.write_text(wall_log.read_text().replace(",", ";"))
    shutil.copy(sidecar_path(wall_log), sidecar_path(semi))
    with pytest.raises(LogFormatError, match=r"semi\.csv: line 1 \(header\): fields are separated by ';' "
                                             r"\(semicolon\); the flight-log format separates fields with ','"):
        read_log(semi)
