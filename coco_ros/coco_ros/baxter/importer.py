"""Baxter SDK ``joint_recorder`` CSV -> a bag with ``/robot/joint_states`` as a real Baxter publishes.

joint_recorder (baxter_examples) writes one header line ``time,left_s0,...,left_gripper,right_s0,
...,right_gripper`` and one row per sample: ``time`` in seconds, arm angles in rad, the gripper
position in percent (0 closed .. 100 open).

Each row becomes one ``sensor_msgs/JointState`` on ``/robot/joint_states``:

- ``name``: :data:`~.joints.BAXTER_JOINT_NAMES` (the real Baxter order, then the finger joints);
  joints the CSV lacks (``head_nod``, ``head_pan``, ``torso_t0``, an absent arm) are 0.
- ``position``: the CSV's angles; the grippers mapped to their finger joints
  (:func:`~.joints.gripper_to_fingers`).
- ``velocity``: finite differences of the positions (central inside, one-sided at the ends; 0 for
  joints the CSV lacks), as a real Baxter publishes velocities too. ``effort`` is left empty (the
  recording has none).
- ``header.stamp`` and the bag's log time: ``start_stamp`` + the row's ``time`` column (the column
  is not shifted: joint_recorder's first row is usually a few seconds in).
"""

from __future__ import annotations

import argparse
import math
import sys
import time as _time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from coco_core.errors import CocoError, RecordingError

from .joints import ARM_JOINTS, BAXTER_JOINT_NAMES, FINGER_JOINTS, GRIPPER_COLUMNS, gripper_to_fingers

TOPIC = "/robot/joint_states"
FRAME_ID = ""  # a real Baxter's /robot/joint_states header has an empty frame_id

KNOWN_COLUMNS = tuple(ARM_JOINTS["left"]) + ("left_gripper",) + tuple(ARM_JOINTS["right"]) + ("right_gripper",)
"""The columns joint_recorder writes after ``time`` (with both arms and grippers)."""


@dataclass(frozen=True)
class Recording:
    """A parsed joint_recorder file: times (s) and the positions of BAXTER_JOINT_NAMES per row."""

    path: Path
    columns: tuple[str, ...]
    times: list[float]
    positions: list[list[float]]

    def __len__(self) -> int:
        return len(self.times)


def read_recording(csv_path: str | Path) -> Recording:
    """Parse a joint_recorder CSV; :class:`RecordingError` names the file, line and expectation."""
    path = Path(csv_path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise RecordingError(f"{path}: cannot read the recording: {error}") from None
    lines = text.splitlines()
    header_index = next((i for i, line in enumerate(lines) if line.strip()), None)
    expected = "time," + ",".join(KNOWN_COLUMNS)
    if header_index is None:
        raise RecordingError(f"{path}:1: empty file; expected a joint_recorder header line '{expected}'")
    columns = tuple(c.strip() for c in lines[header_index].split(","))
    where = f"{path}:{header_index + 1}"
    if not columns or columns[0] != "time":
        raise RecordingError(f"{where}: expected a joint_recorder header starting with 'time', like '{expected}'; "
                             f"got {lines[header_index][:80]!r}")
    unknown = [c for c in columns[1:] if c not in KNOWN_COLUMNS]
    if unknown:
        raise RecordingError(f"{where}: unknown column(s) {', '.join(map(repr, unknown))}; expected columns "
                             f"among: time, {', '.join(KNOWN_COLUMNS)}")
    duplicates = sorted({c for c in columns if columns.count(c) > 1})
    if duplicates:
        raise RecordingError(f"{where}: duplicate column(s) {', '.join(duplicates)}")
    if len(columns) == 1:
        raise RecordingError(f"{where}: only a 'time' column; expected joint columns such as {KNOWN_COLUMNS[0]}")

    index = {name: i for i, name in enumerate(BAXTER_JOINT_NAMES)}
    # For each CSV column after time: (index of the driven joint, index of the mimic joint or -1, is_gripper)
    targets: list[tuple[int, int, bool]] = []
    for column in columns[1:]:
        side = GRIPPER_COLUMNS.get(column)
        if side is None:
            targets.append((index[column], -1, False))
        else:
            driven_joint, mimic_joint = FINGER_JOINTS[side]
            targets.append((index[driven_joint], index[mimic_joint], True))

    times: list[float] = []
    positions: list[list[float]] = []
    width = len(columns)
    for number in range(header_index + 1, len(lines)):
        line = lines[number].strip()
        if not line:
            continue
        where = f"{path}:{number + 1}"
        fields = line.split(",")
        if len(fields) != width:
            raise RecordingError(f"{where}: expected {width} comma-separated values ({', '.join(columns)}), "
                                 f"got {len(fields)}")
        try:
            values = [float(field) for field in fields]
        except ValueError:
            bad = next(f for f in fields if not _is_float(f))
            column = columns[fields.index(bad)]
            raise RecordingError(f"{where}: column {column!r}: expected a number, got {bad.strip()!r}") from None
        for column, value in zip(columns, values):
            if not math.isfinite(value):
                raise RecordingError(f"{where}: column {column!r}: expected a finite number, got {value}")
        if values[0] < 0 or (times and values[0] <= times[-1]):
            previous = f" (previous row: {times[-1]})" if times else ""
            raise RecordingError(f"{where}: column 'time': expected increasing seconds >= 0, got {values[0]}{previous}")
        row = [0.0] * len(BAXTER_JOINT_NAMES)
        for (driven, mimic, gripper), value in zip(targets, values[1:]):
            if gripper:
                if not -1.0 <= value <= 101.0:
                    raise RecordingError(f"{where}: gripper column: expected percent 0..100, got {value}")
                row[driven], row[mimic] = gripper_to_fingers(value)
            else:
                row[driven] = value
        times.append(values[0])
        positions.append(row)
    if not times:
        raise RecordingError(f"{path}:{header_index + 2}: no data rows after the header")
    return Recording(path, columns, times, positions)


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def finite_difference_velocities(times: Sequence[float], positions: Sequence[Sequence[float]]) -> list[list[float]]:
    """Central differences inside, one-sided at both ends (all zeros for a single row)."""
    count = len(times)
    if count < 2:
        return [[0.0] * len(row) for row in positions]
    result = []
    for i in range(count):
        a, b = max(i - 1, 0), min(i + 1, count - 1)
        dt = times[b] - times[a]
        result.append([(pb - pa) / dt for pa, pb in zip(positions[a], positions[b])])
    return result


def joint_state(stamp_ns: int, names: Sequence[str], positions: Sequence[float], velocities: Sequence[float] = ()):
    """A sensor_msgs/JointState with the given stamp (ns since the epoch)."""
    from sensor_msgs.msg import JointState

    message = JointState()
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    message.header.frame_id = FRAME_ID
    message.name = list(names)
    message.position = [float(v) for v in positions]
    message.velocity = [float(v) for v in velocities]
    return message


def import_recording(
    csv_path: str | Path,
    bag_folder: str | Path,
    start_stamp: int | float | None = None,
    *,
    progress: Callable[[int], None] | None = None,
) -> int:
    """Write the joint_recorder file ``csv_path`` as a new bag folder ``bag_folder``.

    ``start_stamp``: the epoch time the recording's time 0 maps to, in ns (int) or s (float);
    default: now. ``progress`` is called with the number of rows written since the last call.
    Returns the number of messages written (one per row).
    """
    from ..bag import BagWriter

    recording = read_recording(csv_path)
    if start_stamp is None:
        start_ns = _time.time_ns()
    elif isinstance(start_stamp, float):
        start_ns = int(round(start_stamp * 1e9))
    else:
        start_ns = int(start_stamp)
    velocities = finite_difference_velocities(recording.times, recording.positions)
    with BagWriter(bag_folder) as writer:
        for i, (t, row) in enumerate(zip(recording.times, recording.positions)):
            stamp = start_ns + int(round(t * 1e9))
            writer.write(TOPIC, joint_state(stamp, BAXTER_JOINT_NAMES, row, velocities[i]), stamp)
            if progress is not None and (i % 100 == 99 or i == len(recording) - 1):
                progress(100 if i % 100 == 99 else i % 100 + 1)
    return len(recording)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="baxter-import",
        description="Convert a Baxter SDK joint_recorder CSV into a rosbag2 (MCAP) bag with /robot/joint_states "
                    "in a real Baxter's joint order.",
    )
    parser.add_argument("csv", help="the joint_recorder file (e.g. shake_hand.dat)")
    parser.add_argument("bag", help="the bag folder to create (must not exist or be empty)")
    parser.add_argument("--start", type=float, default=None,
                        help="epoch seconds that the recording's time 0 maps to (default: now)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    from tqdm import tqdm

    try:
        rows = len(read_recording(args.csv))
        with tqdm(total=rows, unit="msg", desc="baxter-import", disable=args.quiet) as bar:
            count = import_recording(args.csv, args.bag, args.start, progress=bar.update)
    except CocoError as error:
        print(f"baxter-import: {error}", file=sys.stderr)
        return 1
    if not args.quiet:
        print(f"wrote {count} messages on {TOPIC} to {args.bag}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
