"""Workspace-level tests run the installed launchers the way a user does, from a built workspace."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

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


def run_launcher(script: Path, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """Run a launcher to completion from the workspace root, capturing its output."""
    return subprocess.run([str(script), *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, "PYTHONUNBUFFERED": "1"})


def start_launcher(script: Path, *args: str) -> subprocess.Popen[str]:
    """Start a launcher in the background (for signal tests)."""
    return subprocess.Popen([str(script), *args], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
