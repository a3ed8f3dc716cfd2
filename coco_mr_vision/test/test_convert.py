"""Format conversions: every pair against OpenCV's own result on a real photo, round trips, depth
scaling, one conversion per image however many ask, and the ImageConverter component."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort, OutputPort  # noqa: E402
from coco_core.errors import CocoError, ConversionError  # noqa: E402
from coco_core.stamps import Stamp, Stamped  # noqa: E402
from coco_mr_vision.convert import conversion_path, convert, convert_array  # noqa: E402
from coco_mr_vision.converter import ImageConverter  # noqa: E402
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat  # noqa: E402

F = ImageFormat
DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
REDWOOD = DATA / "rgbd" / "redwood"
COLOUR = [F.GRAY8, F.GRAY16, F.RGB8, F.BGR8, F.RGBA8, F.BGRA8, F.YUYV, F.I420]
NAMES = {F.GRAY8: "GRAY", F.RGB8: "RGB", F.BGR8: "BGR", F.RGBA8: "RGBA", F.BGRA8: "BGRA"}


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    path = REDWOOD / "color" / "00000.jpg"
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared data sets are not beside this checkout)")
    return cv2.imread(str(path), cv2.IMREAD_COLOR)


def opencv_reference(bgr: np.ndarray, image_format: ImageFormat) -> np.ndarray:
    """The photo in ``image_format``, computed here with OpenCV calls written out by hand."""
    codes = {F.BGR8: None, F.RGB8: cv2.COLOR_BGR2RGB, F.RGBA8: cv2.COLOR_BGR2RGBA, F.BGRA8: cv2.COLOR_BGR2BGRA,
             F.GRAY8: cv2.COLOR_BGR2GRAY, F.YUYV: cv2.COLOR_BGR2YUV_YUYV, F.I420: cv2.COLOR_BGR2YUV_I420}
    if image_format is F.GRAY16:
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.uint16) * 257
    code = codes[image_format]
    return bgr.copy() if code is None else cv2.cvtColor(bgr, code)


def test_a_single_opencv_call_gives_exactly_opencvs_result(photo):
    checked = 0
    for source, target in itertools.permutations(NAMES, 2):
        a, b = NAMES[source], NAMES[target]
        data = opencv_reference(photo, source)
        code = getattr(cv2, f"COLOR_{a}2{b}", None)
        if code is None:
            continue
        assert conversion_path(source, target) == (source, target)
        assert np.array_equal(convert_array(data, source, target), cv2.cvtColor(data, code)), (source, target)
        checked += 1
    for rgb in (F.RGB8, F.BGR8, F.RGBA8, F.BGRA8):
        data = opencv_reference(photo, rgb)
        for yuv, suffix in ((F.YUYV, "YUYV"), (F.I420, "I420")):
            expected = cv2.cvtColor(data, getattr(cv2, f"COLOR_{NAMES[rgb]}2YUV_{suffix}"))
            assert np.array_equal(convert_array(data, rgb, yuv), expected)
            packed = opencv_reference(photo, yuv)
            back = cv2.cvtColor(packed, getattr(cv2, f"COLOR_YUV2{NAMES[rgb]}_{suffix}"))
            assert np.array_equal(convert_array(packed, yuv, rgb), back)
            checked += 2
    assert checked >= 20 + 16


def test_chained_conversions_go_through_bgr_and_match_the_chain_by_hand(photo):
    assert conversion_path(F.GRAY8, F.I420) == (F.GRAY8, F.BGR8, F.I420)
    assert conversion_path(F.YUYV, F.I420) == (F.YUYV, F.BGR8, F.I420)
    grey = opencv_reference(photo, F.GRAY8)
    expected = cv2.cvtColor(cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR), cv2.COLOR_BGR2YUV_I420)
    assert np.array_equal(convert_array(grey, F.GRAY8, F.I420), expected)
    yuyv = opencv_reference(photo, F.YUYV)
    expected = cv2.cvtColor(cv2.cvtColor(yuyv, cv2.COLOR_YUV2BGR_YUYV), cv2.COLOR_BGR2YUV_I420)
    assert np.array_equal(convert_array(yuyv, F.YUYV, F.I420), expected)


@pytest.mark.parametrize("source, target", list(itertools.permutations(COLOUR, 2)),
                         ids=lambda f: f.name)
def test_every_pair_round_trips(photo, source, target):
    data = opencv_reference(photo, source)
    image = Image(data, source, 2.5, "camera")
    there = convert(image, target)
    assert there.format is target and there.size == image.size
    assert (there.stamp, there.frame_id) == (2.5, "camera")
    back = convert(there, source).data.astype(np.int32)
    error = np.abs(back - data.astype(np.int32))
    if source is F.GRAY16:
        error //= 257  # GRAY16 goes through 8 bits: the low byte is lost by design
    lossy = {F.YUYV, F.I420, F.GRAY8, F.GRAY16}
    if source in (F.GRAY8, F.GRAY16) and target in (F.YUYV, F.I420):
        # OpenCV's YUV is limited range (Y in 16..235) and its YUV -> GRAY takes the Y plane as it
        # is, as every camera driver does: grey comes back with that range, not as it went in.
        grey = data >> 8 if source is F.GRAY16 else data
        limited = 16 + grey.astype(np.float64) * 219 / 255
        back = back // 257 if source is F.GRAY16 else back
        assert np.abs(back - limited).max() <= 1.5
        return
    if source in lossy or target in lossy:
        # Chroma subsampling and limited-range YUV lose a little on a real photo; grey loses colour.
        if target in (F.GRAY8, F.GRAY16) and source not in (F.GRAY8, F.GRAY16):
            return
        assert error.mean() < 3.0 and np.percentile(error, 99) < 40, (error.mean(), np.percentile(error, 99))
    else:
        assert error.max() == 0


def test_depth_converts_between_millimetres_and_metres():
    millimetres = np.array([[0, 1, 1000], [1500, 65535, 2]], np.uint16)
    metres = convert_array(millimetres, F.DEPTH16, F.DEPTH32F)
    assert metres.dtype == np.float32 and np.isnan(metres[0, 0])
    assert np.allclose(metres[~np.isnan(metres)], [0.001, 1.0, 1.5, 65.535, 0.002])
    assert np.array_equal(convert_array(metres, F.DEPTH32F, F.DEPTH16), millimetres)
    tum = convert_array(np.array([[5000, 0]], np.uint16), F.DEPTH16, F.DEPTH32F, depth_scale=5000)
    assert tum[0, 0] == 1.0 and np.isnan(tum[0, 1])
    far = np.array([[70.0, -1.0, np.inf, 0.0005]], np.float32)
    assert convert_array(far, F.DEPTH32F, F.DEPTH16).tolist() == [[0, 0, 0, 0]], \
        "depth that 16 bits cannot hold is unknown (0), never wrapped"


def test_depth_and_colour_do_not_mix():
    with pytest.raises(ConversionError, match="DEPTH16 to RGB8: depth converts only to depth"):
        convert_array(np.zeros((2, 2), np.uint16), F.DEPTH16, F.RGB8)
    with pytest.raises(ConversionError, match="GRAY8 to DEPTH32F"):
        convert(Image(np.zeros((2, 2), np.uint8), F.GRAY8), "depth32f")


def test_conversion_errors_are_coco_errors_and_value_errors() -> None:
    with pytest.raises(ConversionError, match="depth_scale") as caught:
        convert_array(np.zeros((2, 2), np.uint16), F.DEPTH16, F.DEPTH32F, depth_scale=0)
    assert isinstance(caught.value, CocoError) and isinstance(caught.value, ValueError)


def test_intrinsics_travel_and_a_format_is_converted_once(photo):
    intrinsics = CameraIntrinsics(640, 480, 525, 525, 319.5, 239.5, distortion=(0.1, -0.2, 0, 0, 0.05))
    image = Image(opencv_reference(photo, F.YUYV), F.YUYV, 1.0, "cam", intrinsics)
    grey = image.to("gray8")
    assert grey.intrinsics is intrinsics and grey.format is F.GRAY8
    assert image.to(F.GRAY8) is grey, "a second reader gets the conversion already made"
    assert image.to(F.YUYV) is image
    assert np.array_equal(grey.data, cv2.cvtColor(image.data, cv2.COLOR_YUV2GRAY_YUYV))


class Camera(Component):
    image = OutputPort(object)


class Reader(Component):
    image = InputPort(object)


def test_image_converter_component_converts_once_for_every_reader_and_keeps_stamps(photo):
    app = Application("convert")
    camera = app.add(Camera("camera"))
    converter = app.add(ImageConverter("to_grey", format="GRAY8"))
    readers = [app.add(Reader(f"reader{i}")) for i in range(2)]
    buffered = ConnectionPolicy(BufferPolicy.BUFFER, size=4)
    app.connect("camera.image", "to_grey.image", buffered)
    for reader in readers:
        app.connect("to_grey.converted", f"{reader.name}.image", buffered)
    stamp = Stamp(12.0, 7, "camera")
    camera.image.write(Stamped(Image(opencv_reference(photo, F.I420), F.I420, 3.0), stamp))
    camera.image.write(Image(opencv_reference(photo, F.BGR8), F.BGR8))
    converter.on_update()
    first = [reader.image.read()[1] for reader in readers]
    assert first[0] is first[1] and first[0].stamp is stamp
    assert first[0].value.format is F.GRAY8 and first[0].value.stamp == 3.0
    second = readers[0].image.read()[1]
    assert isinstance(second, Image) and second.format is F.GRAY8
    assert np.array_equal(second.data, cv2.cvtColor(photo, cv2.COLOR_BGR2GRAY))
