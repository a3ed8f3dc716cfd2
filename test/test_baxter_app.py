"""The Baxter teleoperation replay app (config/baxter_teleop_replay.xml) on a generated session, run
through the installed coco-launch as a user does."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import pytest

from conftest import ROOT, run_launcher

APP = "config/baxter_teleop_replay.xml"


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """A 12 s session, written with the installed ``baxter-session`` script; its SessionInfo in-process."""
    from coco_ros.baxter.session import generate_session

    folder = tmp_path_factory.mktemp("baxter") / "session"
    script = ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "baxter-session"
    if script.exists():
        result = run_launcher(script, str(folder), "--quiet", timeout=120)
        assert result.returncode == 0, result.stderr
        info = generate_session(folder.parent / "info_only", duration=12.0)  # same seed: same layout and times
    else:
        info = generate_session(folder, duration=12.0)
    return folder, info


def test_teleop_app_replays_the_session(coco_launch: Path, session, tmp_path: Path) -> None:
    folder, info = session
    output = tmp_path / "teleop"
    result = run_launcher(coco_launch, APP, f"bag:={folder}", f"output:={output}",
                          f"time_origin:={info.start_ns / 1e9}", "--profile", "100", "--duration", "60", timeout=120)
    assert result.returncode == 0, result.stderr
    assert "bag" in result.stderr and "replayed" in result.stderr, result.stderr
    report = result.stdout
    assert "Profile of application 'baxter_teleop_replay'" in report, report
    for name in ("replay", "tf", "distance", "summary"):
        assert re.search(rf"^{name}\s", report, re.M), f"{name} missing from the profile:\n{report}"
    # The distance component reports its stamp-to-output latency (mean/max in ms), not "-".
    line = re.search(r"^distance\s.*$", report, re.M).group(0)
    assert re.search(r"[0-9.]+ / [0-9.]+\s*$", line), line

    with (output / "distance.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) > 500, f"only {len(rows)} distance samples in a 12 s session"
    assert all(0.0 <= float(r[c]) <= 1.0 for r in rows for c in ("r", "g", "b"))

    summary = json.loads((output / "summary.json").read_text())
    assert summary["samples"] == len(rows)
    phases = {name: (start, end) for name, start, end in info.phases}
    # The gripper reaches the bowl: within 2 cm first during the descent onto it, by the grasp at the latest.
    assert summary["min_distance"] < 0.02, summary
    assert summary["grasp_time"] is not None, summary
    assert phases["descend"][0] - 0.1 <= summary["grasp_time"] <= info.grasp_time + 0.1, (summary, info.phases)
    # The closest approach is while the gripper holds the bowl, from the grasp to the release.
    assert phases["grasp"][0] - 0.5 <= summary["min_distance_time"] <= info.release_time + 0.5, summary
    # After the release and retreat the gripper is away; the bowl was placed on its target.
    assert summary["final_distance"] > 0.05, summary
    assert summary["final_bowl_target_distance"] < 0.01, summary
