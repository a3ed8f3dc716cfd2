"""The TF bridge against plain rclpy nodes over real DDS, each side in its own process.

1. Ingesting: an external node (``data/tf_peer.py talker``) publishes /tf_static *before* the
   launcher starts, then /tf continuously; the launcher runs ``data/tf_ingest.xml`` and its probe
   writes what the transformation graph holds: the static edge with the value sent, the dynamic
   edge at the header stamps sent, and lookups across both.
2. Broadcasting: the launcher runs ``data/tf_baxter.xml`` (JointState -> ROSInterface ->
   TransformationInterface with the Baxter URDF -> TFBridge); an external node joining late
   (``tf_peer.py listener``) publishes the joint states and receives /tf and the latched
   /tf_static; the chain base -> left_gripper rebuilt from what it received matches Pinocchio's
   forward kinematics computed here, and the bridge dropped its own echoes instead of ingesting them.

Domains 60 and 61, discovery on localhost only.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from coco_core.interrupt import interrupt
from coco_core.transforms import se3

TESTS = Path(__file__).resolve().parent
DATA = TESTS / "data"
WORKSPACE = TESTS.parents[1]
LAUNCHER = WORKSPACE / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"
BAXTER_URDF = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"

pytestmark = pytest.mark.skipif(not LAUNCHER.exists(), reason="workspace not built (source scripts/setup.sh)")


def start(domain: int, cwd: Path, *command: str | Path) -> subprocess.Popen[str]:
    """A Python script in its own process on ``domain`` (localhost only), ``data/`` importable."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONUNBUFFERED="1")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(DATA), env.get("PYTHONPATH", "")]))
    return subprocess.Popen([sys.executable, *map(str, command)], cwd=cwd, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def wait_for(condition, timeout: float, *processes: subprocess.Popen[str]) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        if any(process.poll() is not None for process in processes):
            return condition()
        time.sleep(0.1)
    return condition()


def matrix(item: dict) -> np.ndarray:
    """4x4 of a transform the peer wrote (translation, quaternion x y z w)."""
    return se3.from_pose(item["translation"], item["rotation"])


def last_line(path: Path) -> dict | None:
    lines = path.read_text().splitlines() if path.exists() else []
    return json.loads(lines[-1]) if lines else None


# --- 1. /tf_static (latched, sent before the launcher started) and /tf into the graph ---------------

def test_external_tf_and_latched_tf_static_enter_the_graph(tmp_path: Path) -> None:
    spec = importlib.util.spec_from_file_location("tf_peer", DATA / "tf_peer.py")
    peer = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(peer)  # what the talker sends
    static_camera = peer.STATIC_CAMERA
    probe = tmp_path / "graph.jsonl"
    talker = start(60, tmp_path, DATA / "tf_peer.py", "talker")
    launcher = None
    try:
        assert wait_for(lambda: talker.stdout is not None, 5)
        assert talker.stdout.readline().strip() == "static sent"
        time.sleep(0.5)  # the static message is out before the launcher exists: only latching delivers it
        launcher = start(60, tmp_path, LAUNCHER, DATA / "tf_ingest.xml", f"probe:={probe}", "--duration", "60")

        def complete() -> bool:
            state = last_line(probe)
            return bool(state and len(state["edges"]) == 2 and state["lookups"])

        assert wait_for(complete, 20, launcher), "the graph never got both edges"
        time.sleep(0.5)  # a few more /tf samples
    finally:
        code, output = interrupt(launcher) if launcher is not None else (None, "")
        interrupt(talker)
    assert code == 0, output
    assert "TFBridge tf: broadcasting nothing yet; ingesting /tf and /tf_static with prefix 'ext/'" in output, output
    received = re.search(r"TFBridge tf: received (\d+) transforms \(ingested (\d+), echoes 0, rejected 0, "
                         r"malformed 0\); published 0 transforms on /tf and 0 messages on /tf_static", output)
    assert received and int(received.group(1)) == int(received.group(2)) >= 10, output

    state = last_line(probe)
    assert {"ext/world", "ext/camera", "ext/marker"} <= set(state["frames"])
    camera, marker = state["edges"]["ext/world->ext/camera"], state["edges"]["ext/world->ext/marker"]
    assert camera["kind"] == "static" and camera["stamp"] is None
    np.testing.assert_allclose(camera["transform"], matrix(static_camera), atol=1e-12)
    # The dynamic edge's newest sample carries the header stamp of the message that set it.
    assert marker["kind"] == "dynamic"
    n = round(marker["stamp"] - 1000.25)
    assert marker["stamp"] == pytest.approx(1000.25 + n, abs=1e-6) and n >= 5
    sent = {"translation": (0.01 * n, 0.0, 0.5), "rotation": (0.0, 0.0, np.sin(0.05 * n), np.cos(0.05 * n))}
    np.testing.assert_allclose(marker["transform"], matrix(sent), atol=1e-12)
    # Lookups walk the ingested edges like any others (each probe line is one state of the graph).
    lines = [json.loads(line) for line in probe.read_text().splitlines()]
    complete_lines = [line for line in lines if line["lookups"]]
    assert len(complete_lines) >= 5
    for line in complete_lines:
        value = np.array(line["lookups"]["ext/camera:ext/marker"])
        world_marker = np.array(line["edges"]["ext/world->ext/marker"]["transform"])
        np.testing.assert_allclose(value, se3.inverse(matrix(static_camera)) @ world_marker, atol=1e-12)


# --- 2. The Baxter in the graph, broadcast to a late-joining listener -------------------------------

LEFT_ARM = {"left_s0": 0.35, "left_s1": -0.6, "left_e0": 0.2, "left_e1": 1.1, "left_w0": -0.4,
            "left_w1": 0.9, "left_w2": 0.15, "head_pan": 0.25}


def pinocchio_base_to(frame: str, positions: dict[str, float]) -> np.ndarray:
    """``T_base_<frame>`` of the Baxter URDF by Pinocchio's forward kinematics, independent of CoCo."""
    import pinocchio as pin
    from coco_core.transforms.resources import resolve

    model = pin.buildModelFromUrdf(str(resolve(BAXTER_URDF)))
    data = model.createData()
    q = pin.neutral(model)
    for name, value in positions.items():
        q[model.joints[model.getJointId(name)].idx_q] = value
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[model.getFrameId("base")].actInv(data.oMf[model.getFrameId(frame)]).homogeneous


def chain(transforms: dict[str, dict], root: str, frame: str) -> np.ndarray:
    """``T_root_frame`` composed from tf transforms (child -> its transform from the parent)."""
    result = np.eye(4)
    while frame != root:
        assert frame in transforms, f"no transform to {frame} was received"
        item = transforms[frame]
        result = matrix(item) @ result
        frame = item["parent"]
    return result


def test_baxter_frames_reach_a_late_listener_matching_pinocchio(tmp_path: Path) -> None:
    output_json = tmp_path / "received.json"
    launcher = start(61, tmp_path, LAUNCHER, DATA / "tf_baxter.xml", "--duration", "60")
    listener = None
    try:
        # The static set goes out at the bridge's first update; the listener joins after that.
        started = time.monotonic()
        while time.monotonic() - started < 20 and launcher.poll() is None:
            line = launcher.stdout.readline()
            if "TFBridge tf: broadcasting" in line:
                break
        time.sleep(1.5)
        listener = start(61, tmp_path, DATA / "tf_peer.py", "listener", "--seconds", "3", "--output", output_json,
                         "--joints", *(f"{name}={value}" for name, value in LEFT_ARM.items()))
        listened = listener.communicate(timeout=30)[0]
        assert listener.returncode == 0, listened
    finally:
        code, output = interrupt(launcher)
        if listener is not None and listener.poll() is None:
            interrupt(listener)
    assert code == 0, output
    received = json.loads(output_json.read_text())

    # /tf_static: one latched message with every fixed joint, received although sent before we joined.
    assert len(received["tf_static"]) == 1, received["tf_static"]
    static = {item["child"]: item for item in received["tf_static"][0]}
    assert {"left_gripper", "right_gripper", "head_camera_link", "torso", "pedestal"} <= set(static)
    # /tf: what changed since the listener joined, i.e. the joints it set (the others went out before).
    moving = received["tf"]
    assert set(moving) == {"head", "left_upper_shoulder", "left_lower_shoulder", "left_upper_elbow",
                           "left_lower_elbow", "left_upper_forearm", "left_lower_forearm", "left_wrist"}
    assert not set(moving) & set(static)  # each frame has one publisher path
    now = received["wall_time"]
    for item in list(moving.values()) + list(static.values()):
        stamp = item["stamp"][0] + item["stamp"][1] * 1e-9
        assert abs(stamp - now) < 60, item  # the launcher's ROS clock (wall time here)

    # The frames, chained from what was received, are where Pinocchio puts them for these joints.
    transforms = {**static, **moving}
    for frame in ("left_gripper", "head"):
        np.testing.assert_allclose(chain(transforms, "base", frame), pinocchio_base_to(frame, LEFT_ARM),
                                   atol=1e-9, err_msg=frame)

    # The bridge got its own messages back (it also ingests) and dropped every one as an echo.
    counts = re.search(r"TFBridge tf: received (\d+) transforms \(ingested (\d+), echoes (\d+), rejected (\d+)",
                       output)
    assert counts, output
    assert int(counts.group(2)) == 0 and int(counts.group(4)) == 0
    assert int(counts.group(3)) == int(counts.group(1)) > 0
