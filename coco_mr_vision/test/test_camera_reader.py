"""CameraReader on a real video file and image sequence made from the shared RGB-D photos; clear
errors for a missing device, a GStreamer pipeline this OpenCV cannot run, and missing files."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort  # noqa: E402
from coco_core.errors import CameraError  # noqa: E402
from coco_mr_vision.camera_reader import CameraReader, has_gstreamer, open_source  # noqa: E402
from coco_mr_vision.image import ImageFormat  # noqa: E402

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
REDWOOD = DATA / "rgbd" / "redwood"


@pytest.fixture(scope="module")
def photos() -> list[np.ndarray]:
    files = sorted((REDWOOD / "color").glob("*.jpg"))
    if not files:
        pytest.skip(f"{REDWOOD} is absent (the shared data sets are not beside this checkout)")
    return [cv2.imread(str(f), cv2.IMREAD_COLOR) for f in files]


class Sink(Component):
    image = InputPort(object)


def rig(reader: CameraReader):
    app = Application("camera")
    app.add(reader)
    sink = app.add(Sink("sink"))
    app.connect(reader.image, sink.image, ConnectionPolicy(BufferPolicy.BUFFER, size=100))
    reader.on_config()
    return sink


def drain(reader: CameraReader, sink: Sink, updates: int) -> list:
    for _ in range(updates):
        reader.on_update()
    return sink.image.read_all()


def test_image_sequence_in_order_converted_stamped_and_looped(tmp_path, photos):
    for index, photo in enumerate(photos):
        cv2.imwrite(str(tmp_path / f"frame_{index:03d}.png"), photo)
    reader = CameraReader("cam", source=str(tmp_path / "frame_*.png"), format="GRAY8", loop=True,
                          frame_id="head_camera", intrinsics=str(REDWOOD / "camera_primesense.json"))
    sink = rig(reader)
    got = drain(reader, sink, 5)
    assert [v.stamp.seq for v in got] == [1, 2, 3, 4, 5]
    assert {v.stamp.source for v in got} == {"cam"}
    first = got[0].value
    assert first.format is ImageFormat.GRAY8 and first.frame_id == "head_camera"
    assert first.intrinsics.fx == 525.0 and first.stamp == pytest.approx(time.time(), abs=60)
    for value, photo in zip(got, photos * 3):
        assert np.array_equal(value.value.data, cv2.cvtColor(photo, cv2.COLOR_BGR2GRAY))


def test_video_file_plays_once_then_ends(tmp_path, photos):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (640, 480))
    assert writer.isOpened()
    for photo in photos * 3:
        writer.write(photo)
    writer.release()
    reader = CameraReader("video", source=str(path), format="RGB8")
    sink = rig(reader)
    got = drain(reader, sink, 10)
    assert len(got) == 3 * len(photos) and reader.ended and reader.frames == len(got)
    decoded = got[0].value.data
    # MJPG is lossy: the first frame is the first photo within JPEG error.
    assert np.abs(decoded.astype(int) - photos[0][..., ::-1].astype(int)).mean() < 4


def test_file_timing_holds_a_frame_until_it_is_due(tmp_path, photos):
    for index in range(3):
        cv2.imwrite(str(tmp_path / f"{index}.png"), photos[0])
    reader = CameraReader("seq", source=str(tmp_path / "*.png"), timing="file", fps=2.0)
    sink = rig(reader)
    assert len(drain(reader, sink, 3)) == 1, "frames 2 and 3 are due 0.5 s and 1 s after the first"
    time.sleep(0.55)
    assert len(drain(reader, sink, 3)) == 1


def test_bad_sources_say_what_is_wrong(tmp_path):
    with pytest.raises(CameraError, match="cannot open camera device 57"):
        open_source("57")
    with pytest.raises(CameraError, match="matches no file"):
        open_source(str(tmp_path / "*.png"))
    with pytest.raises(CameraError, match="does not exist.*device index, a video file, an image glob"):
        open_source(str(tmp_path / "missing.mp4"))
    (tmp_path / "not_a_video.mp4").write_bytes(b"garbage" * 100)
    with pytest.raises(CameraError, match="cannot open .* as a video"):
        open_source(str(tmp_path / "not_a_video.mp4"))


@pytest.mark.skipif(has_gstreamer(), reason="this OpenCV has GStreamer: the error path does not apply")
def test_gstreamer_pipeline_without_gstreamer_is_a_clear_error():
    with pytest.raises(CameraError, match="built without GStreamer"):
        open_source("videotestsrc ! videoconvert ! appsink")


def test_intrinsics_that_are_no_regular_file_are_refused_naming_the_attribute(tmp_path):
    import os
    import signal

    from coco_core.errors import FileReadError

    # Setting the attribute refuses a FIFO (FileAttribute); here the file is swapped after it.
    fifo = tmp_path / "camera.json"
    fifo.write_text("{}")
    reader = CameraReader("cam", source=str(tmp_path / "frame_*.png"), intrinsics=str(fifo))
    fifo.unlink()
    os.mkfifo(fifo)
    signal.signal(signal.SIGALRM, lambda *_: pytest.fail("reading the intrinsics blocked"))
    signal.setitimer(signal.ITIMER_REAL, 10)
    try:
        with pytest.raises(FileReadError) as raised:
            reader.init()
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
    assert str(raised.value) == (f"attribute cam.intrinsics: intrinsics file {fifo} is a FIFO, not a regular "
                                 "file; expected a JSON file of camera intrinsics")


def test_an_unreadable_file_in_a_sequence_is_passed_over_and_counted(tmp_path, photos):
    """A truncated image among real ones: the files after it are still delivered, the bad one is
    counted (in the profile's refusals too) once per pass, and the reader goes on."""
    for index, photo in enumerate(photos):
        cv2.imwrite(str(tmp_path / f"frame_{2 * index:03d}.jpg"), photo)
    good = (tmp_path / "frame_000.jpg").read_bytes()
    (tmp_path / "frame_001.jpg").write_bytes(good[:200])  # cut off after the JPEG header
    reader = CameraReader("cam", source=str(tmp_path / "frame_*.jpg"))
    sink = rig(reader)
    got = drain(reader, sink, 5)
    assert len(got) == len(photos) and reader.ended
    assert np.abs(got[1].value.data.astype(int) - photos[1].astype(int)).mean() < 4, "the photo after the bad file"
    assert reader.skipped == 1 and reader.stats.refused == 1 and reader.stats.errors == 0
    looping = CameraReader("loop", source=str(tmp_path / "frame_*.jpg"), loop=True)
    sink = rig(looping)
    assert len(drain(looping, sink, 2 * len(photos))) == 2 * len(photos)
    assert looping.skipped == 2, "met again on the second pass"


def test_a_fifo_in_a_sequence_or_as_a_video_never_blocks(tmp_path, photos):
    """Files named by the source go through the bounded regular-file reader: a FIFO the glob matches
    is passed over and counted (OpenCV's imread blocked on it for ever), one named as a video is refused."""
    import os
    import signal

    cv2.imwrite(str(tmp_path / "frame_000.jpg"), photos[0])
    os.mkfifo(tmp_path / "frame_001.jpg")
    cv2.imwrite(str(tmp_path / "frame_002.jpg"), photos[1])
    signal.signal(signal.SIGALRM, lambda *_: pytest.fail("reading the source blocked"))
    signal.setitimer(signal.ITIMER_REAL, 10)
    try:
        reader = CameraReader("cam", source=str(tmp_path / "frame_*.jpg"))
        sink = rig(reader)
        assert len(drain(reader, sink, 4)) == 2 and reader.skipped == 1
        with pytest.raises(CameraError, match="is a FIFO, not a regular file"):
            open_source(str(tmp_path / "frame_001.jpg"))
        with pytest.raises(CameraError, match="is a character device, not a regular file"):
            open_source("/dev/zero")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
