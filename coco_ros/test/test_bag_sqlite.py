"""rosbag2 SQLite storage (``.db3``): bags written by another rosbag2 implementation (rosbags) and the
single ``.db3`` that librealsense's own recorder writes, read by BagReader; damaged ones refused."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from coco_core.errors import BagError
from coco_ros.bag import BagReader

PACKAGE = Path(__file__).resolve().parents[1]
T0 = 1_700_000_000_000_000_000
COUNT = 200


@pytest.fixture(scope="module")
def db3_bag(tmp_path_factory) -> Path:
    """A rosbag2 folder (metadata.yaml + one .db3) of /chatter strings, written by rosbags."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    String = store.types["std_msgs/msg/String"]
    folder = tmp_path_factory.mktemp("sqlite") / "chatter"
    with Writer(folder, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        connection = writer.add_connection("/chatter", String.__msgtype__, typestore=store)
        for i in range(COUNT):
            writer.write(connection, T0 + i * 1_000_000, store.serialize_cdr(String(data=f"hello {i}"),
                                                                              String.__msgtype__))
    return folder


def test_a_db3_folder_and_its_file_alone_read_as_rosbag2_wrote_them(db3_bag: Path):
    [storage] = db3_bag.glob("*.db3")
    for path in (db3_bag, storage):
        with BagReader(path) as reader:
            assert reader.topics["/chatter"].type == "std_msgs/msg/String"
            assert reader.message_count == COUNT and (reader.start_time, reader.duration) == (T0, (COUNT - 1) * 1_000_000)
            messages = list(reader.messages())
            assert [m.message.data for m in messages] == [f"hello {i}" for i in range(COUNT)]
            assert [m.log_time for m in messages] == [T0 + i * 1_000_000 for i in range(COUNT)]
            assert [m.message.data for m in reader.messages(start=T0 + 10_000_000, end=T0 + 12_000_000)] == \
                ["hello 10", "hello 11"]
            assert not reader.errors


def damaged_copy(bag: Path, tmp_path: Path, damage) -> Path:
    """The bag folder with its .db3 file damaged by ``damage(bytes) -> bytes``."""
    copy = tmp_path / "damaged"
    copy.mkdir()
    for file in bag.iterdir():
        data = file.read_bytes()
        (copy / file.name).write_bytes(damage(data) if file.suffix == ".db3" else data)
    return copy


def replay(bag: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, ROS_DOMAIN_ID="71", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONPATH=os.pathsep.join([str(PACKAGE), str(PACKAGE.parent / "coco_core"),
                                           os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "coco_ros.replay.cli", str(bag), "--fast", "--delay", "0",
                           "--no-progress"], capture_output=True, text=True, timeout=60, env=env)


def test_coco_replay_publishes_a_db3_bag(db3_bag: Path):
    result = replay(db3_bag)
    assert result.returncode == 0, result.stderr
    assert f"{COUNT} messages published" in result.stderr + result.stdout


@pytest.mark.parametrize("damage", [
    pytest.param(lambda data: data[: len(data) // 2], id="cut in half"),
    pytest.param(lambda data: data[:len(data) // 8192 * 4096] + b"\xa5" * 4096 + data[len(data) // 8192 * 4096 + 4096:],
                 id="a page of messages overwritten"),
])
def test_a_damaged_db3_is_damaged_input_never_a_silent_exit_0(db3_bag: Path, tmp_path: Path, damage):
    bag = damaged_copy(db3_bag, tmp_path, damage)
    try:
        with BagReader(bag) as reader:
            list(reader.messages())
    except BagError as error:
        assert "damaged" in str(error) or "fewer messages" in str(error)
    else:
        pytest.fail("the damaged bag read as a sound one")
    result = replay(bag)
    assert result.returncode == 1, result.stderr
    assert "damaged" in result.stderr or "fewer messages" in result.stderr


def test_a_db3_that_is_not_sqlite_is_refused(tmp_path: Path):
    fake = tmp_path / "notes.db3"
    fake.write_text("these are notes\n")
    with pytest.raises(BagError, match=r"notes\.db3 at byte 0: not an SQLite database"):
        BagReader(fake)


def test_the_librealsense_recording_gives_the_peer_s_frames_without_pyrealsense2(tmp_path: Path):
    """The recording librealsense writes, read by the bag peer (BagReader, compressedDepth PNG, CameraInfo):
    the pixels, intrinsics and count the RealSense peer reads from it through librealsense."""
    pytest.importorskip("pyrealsense2", reason="librealsense writes the recording")
    from coco_mr_vision.realsense_peer import RealSenseRgbdPeer
    from coco_mr_vision.realsense_recording import SyntheticScene, frames_of, write_recording
    from coco_ros.vision.rgbd_bag import BagRgbdPeer

    scene = SyntheticScene()
    recording = write_recording(tmp_path / "plane.db3", scene)
    device = "/device_0/sensor_{}/{}_0/image/"
    bag_peer = BagRgbdPeer("bag", path=str(recording), color_topic=device.format(1, "Color") + "data/compressed",
                           depth_topic=device.format(0, "Depth") + "data/compressedDepth",
                           info_topic=device.format(1, "Color") + "camera_info", depth_scale=scene.depth_scale)
    with pytest.MonkeyPatch.context() as without:
        without.setitem(sys.modules, "pyrealsense2", None)  # importing it now fails: the bag path must not
        bag_frames = frames_of(bag_peer)
    rs_frames = frames_of(RealSenseRgbdPeer("rs", path=str(recording), realtime=False, align=False))
    assert len(bag_frames) == len(rs_frames) == scene.frames
    for index, (ours, theirs) in enumerate(zip(bag_frames, rs_frames)):
        assert np.array_equal(ours.depth.data, theirs.depth.data), index
        assert ours.color.format is theirs.color.format and np.array_equal(ours.color.data, theirs.color.data), index
        assert ours.depth_scale == theirs.depth_scale
    a, b = bag_frames[-1].intrinsics, rs_frames[-1].intrinsics
    assert (a.width, a.height, a.fx, a.fy, a.cx, a.cy) == (b.width, b.height, b.fx, b.fy, b.cx, b.cy)
    stamps = [f.stamp for f in bag_frames]
    # The recorder's arrival times: fed at the scene's rate, so never faster; later on a loaded machine.
    assert all(b > a for a, b in zip(stamps, stamps[1:])) and stamps[-1] - stamps[0] >= (scene.frames - 1.5) / scene.fps
