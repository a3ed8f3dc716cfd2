"""RgbdCameraReader with each back-end peer on the shared RGB-D data: Redwood numbered folders, TUM
sequences (rgb.txt/depth.txt and association files) and the RealSense peer's error when no device
is present (the bag peer is coco_ros's: coco_ros/test/test_rgbd_bag_peer.py)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort  # noqa: E402
from coco_core.errors import CameraError, CocoError  # noqa: E402
from coco_mr_vision.image import ImageFormat  # noqa: E402
from coco_mr_vision.realsense_peer import RealSenseRgbdPeer  # noqa: E402
from coco_mr_vision.rgbd_peers import RedwoodRgbdPeer, TumRgbdPeer  # noqa: E402
from coco_mr_vision.rgbd_reader import RgbdCameraReader  # noqa: E402

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgbd"
REDWOOD, TUM = DATA / "redwood", DATA / "tum"


def needs(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared data sets are not beside this checkout)")
    return path


class Sink(Component):
    rgbd = InputPort(object)


def run(reader: RgbdCameraReader, updates: int) -> list:
    app = Application("rgbd")
    app.add(reader)
    sink = app.add(Sink("sink"))
    app.connect(reader.rgbd, sink.rgbd, ConnectionPolicy(BufferPolicy.BUFFER, size=100))
    for peer in reader.peers:
        peer.on_config()
    reader.on_config()
    for _ in range(updates):
        reader.on_update()
    return sink.rgbd.read_all()


def test_redwood_folder_in_order_with_its_json_intrinsics():
    needs(REDWOOD)
    got = run(RgbdCameraReader("rgbd", backend="redwood", path=str(REDWOOD)), 4)
    assert len(got) == 2, "two pairs, no loop: the reader stops after them"
    frame = got[0].value
    assert (frame.intrinsics.fx, frame.intrinsics.cx, frame.depth_scale) == (525.0, 319.5, 1000.0)
    raw = cv2.imread(str(REDWOOD / "depth" / "00001.png"), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(got[1].value.depth.data, raw)
    assert got[1].value.color.format is ImageFormat.BGR8
    assert [v.stamp.seq for v in got] == [1, 2]


def test_formats_asked_for_and_loop():
    needs(REDWOOD)
    reader = RgbdCameraReader("rgbd", backend="redwood", path=str(REDWOOD), loop=True,
                              color_format="RGBA8", depth_format="DEPTH32F")
    got = run(reader, 5)
    assert len(got) == 5
    frame = got[4].value
    assert frame.color.format is ImageFormat.RGBA8 and frame.depth.format is ImageFormat.DEPTH32F
    raw = cv2.imread(str(REDWOOD / "depth" / "00000.png"), cv2.IMREAD_UNCHANGED)
    valid = raw > 0
    assert np.allclose(frame.depth.data[valid], raw[valid] / 1000.0) and np.isnan(frame.depth.data[~valid]).all()


def tum_sequence(folder: Path, with_association: bool) -> Path:
    """The shared TUM pair laid out as a TUM sequence (rgb/, depth/, rgb.txt, depth.txt)."""
    (folder / "rgb").mkdir(parents=True)
    (folder / "depth").mkdir()
    times = [1305031102.175304, 1305031102.211214]
    depth_times = [1305031102.160407, 1305031102.226738]
    for t in times:
        shutil.copy(needs(TUM / "color.png"), folder / "rgb" / f"{t:.6f}.png")
    for t in depth_times:
        shutil.copy(TUM / "depth.png", folder / "depth" / f"{t:.6f}.png")
    (folder / "rgb.txt").write_text("# color images\n# file: 'x.bag'\n# timestamp filename\n" +
                                    "".join(f"{t:.6f} rgb/{t:.6f}.png\n" for t in times))
    (folder / "depth.txt").write_text("# depth maps\n# timestamp filename\n" +
                                      "".join(f"{t:.6f} depth/{t:.6f}.png\n" for t in depth_times))
    if with_association:
        (folder / "associations.txt").write_text(
            f"{times[1]:.6f} rgb/{times[1]:.6f}.png {depth_times[1]:.6f} depth/{depth_times[1]:.6f}.png\n")
    return folder


def test_tum_pairs_by_nearest_time_at_depth_scale_5000(tmp_path):
    folder = tum_sequence(tmp_path / "seq", with_association=False)
    got = run(RgbdCameraReader("tum", backend="tum", path=str(folder)), 3)
    assert len(got) == 2
    frame = got[0].value
    assert frame.depth_scale == 5000.0 and frame.stamp == pytest.approx(1305031102.175304)
    raw = cv2.imread(str(TUM / "depth.png"), cv2.IMREAD_UNCHANGED)
    metres = frame.depth_metres()
    assert np.nanmax(metres) == pytest.approx(raw.max() / 5000.0)


def test_tum_association_file_is_used_when_present(tmp_path):
    folder = tum_sequence(tmp_path / "seq", with_association=True)
    got = run(RgbdCameraReader("tum", backend="tum", path=str(folder)), 3)
    assert len(got) == 1 and got[0].value.stamp == pytest.approx(1305031102.211214)


def test_tum_damaged_text_file_names_file_and_line(tmp_path):
    folder = tum_sequence(tmp_path / "seq", with_association=False)
    (folder / "depth.txt").write_text("# depth\n1305031102.16 depth/a.png\nnot-a-time depth/b.png\n")
    reader = RgbdCameraReader("tum", backend="tum", path=str(folder))
    reader.init()
    with pytest.raises(CameraError, match=r"depth.txt:3: expected a time in seconds first"):
        reader.peers[0].on_config()


def test_a_declared_peer_with_its_own_attributes():
    needs(REDWOOD)
    reader = RgbdCameraReader("rgbd")
    reader.add_peer(RedwoodRgbdPeer("camera", path=str(REDWOOD), depth_scale=500.0, frame_id="head"))
    got = run(reader, 1)
    assert got[0].value.depth_scale == 500.0 and got[0].value.frame_id == "head"


def test_reader_without_a_peer_says_what_it_needs():
    with pytest.raises(CocoError, match="needs exactly one RGB-D peer.*tum, redwood, bag, realsense"):
        RgbdCameraReader("rgbd").init()


def test_realsense_without_a_device_is_a_clear_error():
    pytest.importorskip("pyrealsense2", reason="pyrealsense2 is in requirements.txt; without it the peer says so")
    peer = RealSenseRgbdPeer("realsense")
    with pytest.raises(CameraError, match="realsense: no Intel RealSense device is connected"):
        peer.on_config()


def test_backend_attribute_makes_its_peer_with_the_path():
    reader = RgbdCameraReader("r", backend="tum", path="x")
    reader.init()
    assert isinstance(reader.peers[0], TumRgbdPeer) and reader.peers[0].path == "x"
