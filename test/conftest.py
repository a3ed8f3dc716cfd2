"""Workspace-level tests run the installed launchers the way a user does, from a built workspace."""

from __future__ import annotations

import csv
import os
import re
import signal
import subprocess
import time
from pathlib import Path
from typing import Any, Callable

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def coco_launch() -> Path:
    """The installed ``coco-launch`` script, where ``ros2 run coco_core coco-launch`` finds it."""
    script = ROOT / "install" / "coco_core" / "lib" / "coco_core" / "coco-launch"
    if not script.exists():
        pytest.fail(f"{script} is missing: build the workspace first (scripts/setup.sh does)")
    return script


@pytest.fixture(scope="session")
def session():
    """A 12 s Baxter session, written with the installed ``baxter-session`` script, and its SessionInfo
    (generated in-process beside it: same seed, same layout and times), once per run of the test
    command (:func:`generated`): the app and view tests, in two pytest processes, only read it."""
    import pickle
    import tempfile

    from coco_ros.baxter.session import generate_session

    script = ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "baxter-session"
    if not script.exists():
        pytest.fail(f"{script} is missing: build the workspace first (scripts/setup.sh does)")

    def make(folder: Path) -> None:
        folder.mkdir(parents=True)
        writing = start_launcher(script, str(folder / "session"), "--quiet")
        try:
            with tempfile.TemporaryDirectory() as scratch:  # the info's own bag: only the info is kept
                info = generate_session(Path(scratch) / "info_only", duration=12.0)
            out, _ = writing.communicate(timeout=120)
        finally:
            writing.kill()
        assert writing.returncode == 0, out
        info.folder = folder / "session"
        (folder / "info.pickle").write_bytes(pickle.dumps(info))

    folder = generated("baxter_session", make)
    return folder / "session", pickle.loads((folder / "info.pickle").read_bytes())


TEST_INPUTS = ROOT / "build" / "test_inputs"
"""Inputs generated once per run of the test command and shared by its pytest processes (the suites
run side by side): ``scripts/run_tests.sh`` empties it at its start; each input's folder is named
after the workspace's build inputs too, so a run of pytest by hand never reads one that older code made."""
PALPATION_SECONDS = 4.5
"""The length of the shared palpation session (``palpation-session --duration``)."""


def generated(name: str, make: Callable[[Path], None]) -> Path:
    """The input ``name``, made by ``make(folder)`` the first time any pytest process of the run asks
    for it (an exclusive lock file keeps the others waiting, then they read what it made)."""
    import fcntl
    import hashlib
    import shutil

    stamp = ROOT / "build" / ".coco-build-inputs"
    version = hashlib.sha256(stamp.read_bytes() if stamp.exists() else b"").hexdigest()[:12]
    TEST_INPUTS.mkdir(parents=True, exist_ok=True)
    folder = TEST_INPUTS / f"{name}-{version}"
    with open(TEST_INPUTS / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not folder.exists():
            partial = folder.with_name(folder.name + ".partial")
            shutil.rmtree(partial, ignore_errors=True)
            make(partial)
            partial.rename(folder)  # complete or absent: a failed generation leaves no half input
    return folder


@pytest.fixture(scope="session")
def palpation_session() -> Path:
    """A 4.5 s remote palpation session written by the installed ``palpation-session`` script, once
    per run of the test command (:func:`generated`)."""
    script = ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "palpation-session"
    if not script.exists():
        pytest.fail(f"{script} is missing: build the workspace first (scripts/setup.sh does)")

    def make(folder: Path) -> None:
        result = run_launcher(script, str(folder), "--duration", str(PALPATION_SECONDS), "--quiet", timeout=180)
        assert result.returncode == 0, result.stderr

    return generated("palpation_session", make)


def run_launcher(script: Path, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """Run a launcher to completion from the workspace root, capturing its output."""
    return subprocess.run([str(script), *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, "PYTHONUNBUFFERED": "1"})


def start_launcher(script: Path, *args: str) -> subprocess.Popen[str]:
    """Start a launcher in the background (for signal tests)."""
    return subprocess.Popen([str(script), *args], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})


def activity_cycles(report: str, process: str, activity: str) -> int:
    """The cycles an activity ran, from the profile's activity table (``process activity schedule cycles ...``).

    Tests count what a run produced against this instead of against wall time: how many cycles a
    periodic activity gets depends on the machine's load, what each cycle must produce does not."""
    schedule = r"(?:periodic [0-9.]+ m?s|triggered(?:, at most every [0-9.]+ ms)?)"  # Schedule.describe()
    pattern = rf"^{re.escape(process)}\s+{re.escape(activity)}\s+{schedule}\s+(\d+)\s"
    match = re.search(pattern, report, re.M)
    assert match, f"no activity {activity} of process {process} in the profile:\n{report}"
    return int(match.group(1))


def connection_counters(report: str, connection: str) -> tuple[int, int, int]:
    """(written, read, dropped) of ``connection`` in the last profile of a launcher's output: its row
    is the process (when the application has several), the label, the policy, the four counters and
    the age of what the reader took (mean / max ms, or -)."""
    found = re.findall(rf"^(?:\S+\s+)?{re.escape(connection)}\s+.*?\s(\d+)\s+(\d+)\s+(\d+)\s+\d+\s+(?:-|\S+ / \S+)\s*$",
                       report, re.M)
    assert found, f"no connection {connection} in the profile:\n{report[-3000:]}"
    written, read, dropped = found[-1]
    return int(written), int(read), int(dropped)


DEMO_APP = "config/demo_pipeline.xml"


def read_rows(path: Path) -> list[dict[str, str]]:
    """The rows of a CSV file written by the demo's recorder."""
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def check_ctrl_c_stops_within_a_second_and_flushes(script: Path, tmp_path: Path) -> None:
    """Run the demo with a launcher, Ctrl-C it once it records, and check the clean, quick stop and
    that the recorder flushed complete rows (both launchers must behave alike)."""
    output = tmp_path / "signal.csv"
    process = start_launcher(script, DEMO_APP, f"output:={output}", "--duration", "60")
    try:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and (not output.exists() or len(read_rows(output)) < 20):
            time.sleep(0.1)
        assert output.exists(), "the application never started recording"
        process.send_signal(signal.SIGINT)
        out, _ = process.communicate(timeout=10)
    finally:
        process.kill()
    assert process.returncode == 0, out
    stopped = re.search(r"application demo_pipeline stopped ([0-9.]+) s after the request \(clean\)", out)
    assert stopped, out
    assert float(stopped.group(1)) < 1.0
    assert "received SIGINT" in out
    # The recorder's on_stop flushed: the file ends with a complete row.
    rows = read_rows(output)
    assert rows and all(len(row) == 5 and None not in row.values() for row in rows)


def damaged_copy(folder: Path, copy: Path, damage: Callable[[str, int, float, Any], Any | None]) -> dict[str, int]:
    """``folder``'s bag written again into ``copy``, each message through ``damage(topic, index in
    its topic, seconds into the bag, message)``: None leaves it out, the message (changed or not)
    is written; returns the messages written per topic."""
    from rclpy.serialization import serialize_message

    from coco_ros.bag import BagReader, BagWriter

    with BagReader(folder) as reader, BagWriter(copy) as writer:
        for name, info in reader.topics.items():
            writer.add_topic(name, info.type, info.offered_qos_profiles)
        index: dict[str, int] = {}
        for message in reader.messages():
            i = index[message.topic] = index.get(message.topic, -1) + 1
            changed = damage(message.topic, i, (message.log_time - reader.start_time) / 1e9, message.message)
            if changed is not None:
                writer.write(message.topic, serialize_message(changed), message.log_time, message.type,
                             publish_time_ns=message.publish_time)
        return writer.topic_counts()
