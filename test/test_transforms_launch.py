"""An application's transformation graph, declared in its file and served while it runs."""

from __future__ import annotations

import json
import time
import urllib.request
from pathlib import Path

from conftest import start_launcher

APP = """<package name="frames">
  <transforms>
    <static parent="world" child="camera" xyz="0 0 1.5" rpy="0 0.5 0"/>
    <dynamic parent="world" child="bowl"/>
    <urdf file="package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"
          attach="world" xyz="0.2 0 0"/>
  </transforms>
</package>
"""


def wait_for_url(process, timeout: float = 30.0) -> str:
    deadline = time.monotonic() + timeout
    assert process.stdout is not None
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if "transformation graph served at" in line:
            return line.rsplit(" ", 1)[-1].strip()
    raise AssertionError("the launcher never printed the server's address")


def get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=5) as response:
        return json.load(response)


def test_declared_graph_with_baxter_is_served_while_running(coco_launch: Path, tmp_path: Path) -> None:
    app = tmp_path / "frames.xml"
    app.write_text(APP)
    process = start_launcher(coco_launch, str(app), "--duration", "20", "--transforms-server", "0")
    try:
        url = wait_for_url(process)
        frames = get(f"{url}/api/frames")
        names = frames["frames"] if isinstance(frames, dict) else frames
        assert {"world", "camera", "bowl", "base", "left_gripper", "right_gripper"} <= set(names)
        lookup = get(f"{url}/api/lookup?target=world&source=camera")
        assert lookup["translation"] == [0.0, 0.0, 1.5]
        # The URDF root is attached 0.2 m along x from the world: the Baxter base sits there.
        base = get(f"{url}/api/lookup?target=world&source=base")
        assert abs(base["translation"][0] - 0.2) < 1e-9
    finally:
        process.terminate()
        process.communicate(timeout=10)
    assert process.returncode == 0
