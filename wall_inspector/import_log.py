"""``wall-inspector import-log``: a PX4 ULog or a ROS 2 bag as the project's flight log (CSV + JSON sidecar).

::

    wall-inspector import-log flight.ulg --vehicle vehicle.yaml --scene scene.yaml [--out flight.csv]
    wall-inspector import-log rosbag2_folder --vehicle vehicle.yaml --scene scene.yaml --topics topics.yaml

``--vehicle`` holds the sidecar's ``vehicle`` block (mass, rotor positions in the FLU
body frame, optional drag and thrust map), ``--scene`` its ``scene`` block (walls,
ground, ceiling in the ENU world frame of the log) and optionally ``gravity``;
``--topics`` is the ROS 2 topic map (:mod:`discovery.importers.ros2`). The default
``--out`` is ``<input name>.csv`` in the current folder. Existing files are not
replaced unless ``--overwrite``; the input files are only read. The import itself is
:func:`discovery.importers.import_log`; this module reads the options and prints what was read.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from discovery.flight_log import THRUST_MAP_KINDS, LogFormatError, csv_output_problem, write_log

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", metavar="FILE", help="a PX4 ULog (.ulg) or a ROS 2 bag (folder, .mcap or .db3)")
    parser.add_argument("--vehicle", required=True, help="YAML/JSON file with the nominal vehicle block")
    parser.add_argument("--scene", required=True, help="YAML/JSON file with the scene block (and optional gravity)")
    parser.add_argument("--topics", default=None, help="ROS 2 topic map (YAML); see discovery.importers.ros2")
    parser.add_argument("--out", default=None, help="CSV file to write (default <input name>.csv here)")
    parser.add_argument("--rate", type=float, default=None, help="clock of the written log in Hz (50 to 1000)")
    parser.add_argument("--thrust-map", choices=sorted(THRUST_MAP_KINDS), default=None,
                        help="thrust map to fit on hover when the vehicle file has none")
    parser.add_argument("--overwrite", action="store_true", help="replace existing output files")


def run(args: argparse.Namespace) -> int:
    from discovery.importers import import_log

    out = Path(args.out) if args.out else Path(Path(args.log.rstrip("/")).stem + ".csv")
    problem = csv_output_problem(out, args.overwrite)
    if problem is None and args.rate is not None and not 50.0 <= args.rate <= 1000.0:
        problem = f"--rate must be in [50, 1000] Hz, got {args.rate:g}"
    if problem is None and not Path(args.log).exists():
        problem = f"flight log {args.log} does not exist"
    if problem:
        print(f"import-log: {problem}", file=sys.stderr)
        return 2
    try:
        log, info = import_log(args.log, args.vehicle, args.scene, topics=args.topics, rate_hz=args.rate,
                               thrust_map_kind=args.thrust_map)
        log.source = str(out)
        csv_path, json_path = write_log(log, out, overwrite=args.overwrite)
    except (LogFormatError, ValueError, FileNotFoundError, FileExistsError) as exc:
        print(f"import-log: {exc}", file=sys.stderr)
        return 2
    gaps = len(log.segments()) - 1
    print(f"read {info['format']} {args.log}: {info['samples']} samples at {info['rate_hz']:g} Hz, "
          f"{log.duration:.2f} s, {gaps} gap(s); frames: {info['frames']}")
    for what, source in info["signals"].items():
        if source:
            print(f"  {what}: {source}")
    tm = info["thrust_map"]
    print(f"thrust map: {tm['kind']}, coefficient {tm['coefficient']:.4g} N ({tm['note']})")
    print(f"wrote {csv_path}\nwrote {json_path}")
    return 0
