"""The demo pipeline (config/demo_pipeline.xml), the README's second example, run through the installed
``coco-launch``."""

from __future__ import annotations

import re
from pathlib import Path

from conftest import check_ctrl_c_stops_within_a_second_and_flushes, read_rows, run_launcher

APP = "config/demo_pipeline.xml"



def test_demo_runs_profiles_and_records(coco_launch: Path, tmp_path: Path) -> None:
    output = tmp_path / "signal.csv"
    result = run_launcher(coco_launch, APP, f"output:={output}", "--duration", "2.5", "--profile", "1")
    assert result.returncode == 0, result.stderr
    # The profile names every activity and component, with the period error of periodic ones.
    report = result.stdout
    assert "Profile of application 'demo_pipeline'" in report
    for name in ("acquisition", "filtering", "recording", "supervision (main)", "generator", "filter",
                 "recorder", "monitor (peer)", "supervisor"):
        assert name in report, f"{name} missing from the profile:\n{report}"
    assert re.search(r"generator\.sample -> filter\.sample\s+BUFFER/LOCKED\[64\]", report)
    # Every filtered sample was recorded, in order, with its latency; nothing lost at the stop.
    rows = read_rows(output)
    assert len(rows) > 150, f"only {len(rows)} rows in 2.5 s at 100 Hz"
    seqs = [int(row["seq"]) for row in rows]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    assert all(row["source"] == "generator" for row in rows)
    assert all(0.0 <= float(row["latency_ms"]) < 1000.0 for row in rows)
    # The supervisor's cross-activity operation calls came back (main activity runs at 1 Hz).
    assert "supervisor: filter.set_window -> previous value 8" in result.stderr


def test_ctrl_c_stops_within_a_second_and_flushes(coco_launch: Path, tmp_path: Path) -> None:
    check_ctrl_c_stops_within_a_second_and_flushes(coco_launch, tmp_path)


def test_arguments_override_defaults(coco_launch: Path, tmp_path: Path) -> None:
    output = tmp_path / "fast.csv"
    result = run_launcher(coco_launch, APP, f"output:={output}", "rate_ms:=5", "window:=3",
                          "--duration", "1.5", "--profile", "10")
    assert result.returncode == 0, result.stderr
    assert re.search(r"acquisition\s+periodic 5 ms", result.stdout)
    assert "filter.set_window -> previous value 3" in result.stderr
