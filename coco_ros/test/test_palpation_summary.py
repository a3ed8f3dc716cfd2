"""PalpationSummary: the figures of a palpation run, from the samples, structures, frames and
residual that reach it; nulls where no data came."""

from __future__ import annotations

import json

import numpy as np
import pytest

from coco_core.application import Application
from coco_core.component import Component
from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_core.ports import OutputPort
from coco_core.stamps import Stamp, Stamped
from coco_mr_haptics.cloud import CloudStructure
from coco_mr_haptics.types import HapticSample
from coco_ros.palpation.summary import PalpationSummary, describe


class Sources(Component):
    samples = OutputPort(object)
    structures = OutputPort(object)
    frames = OutputPort(object)
    residual = OutputPort(float)
    display_latency = OutputPort(object)


def rig(tmp_path):
    app = Application("palpation_summary")
    sources = app.add(Sources("sources"))
    summary = app.add(PalpationSummary("summary", json=tmp_path / "summary.json"))
    for port in ("samples", "structures", "frames", "residual", "display_latency"):
        app.connect(f"sources.{port}", f"summary.{port}", ConnectionPolicy(BufferPolicy.BUFFER, size=10000))
    summary.configure()
    return sources, summary


def sample(time: float, contact: bool, depth: float = 0.0, force: float = 0.0) -> HapticSample:
    return HapticSample(time, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, force), contact,
                        "cloud" if contact else "", depth)


def test_the_figures_come_from_the_data(tmp_path):
    sources, summary = rig(tmp_path)
    # 1 kHz with one late cycle (3 ms), in contact over 100 intervals, 4 mm deepest, 2.5 N.
    times = np.concatenate([np.arange(0, 0.5, 1e-3), 0.502 + np.arange(0, 0.5, 1e-3)])
    for i, t in enumerate(times):
        touching = 200 < i <= 300
        sources.samples.write(sample(float(t), touching, 0.004 if i == 250 else 0.001 * touching, 2.5 * touching))
    for i in range(3):
        sources.structures.write(CloudStructure("grid", np.zeros((10 + i, 3)), build_seconds=0.01 * (i + 1), valid=10 + i))
    for seq in (1, 2, 5, 6):  # 3 and 4 never arrived
        sources.frames.write(Stamped("frame", Stamp(0.0, seq, "camera")))
    sources.residual.write(0.0012)
    summary.step()
    summary.stop()
    report = json.loads((tmp_path / "summary.json").read_text())
    haptics = report["haptics"]
    assert haptics["samples"] == 1000 and haptics["rate_hz"] == pytest.approx(999 / times[-1])
    assert haptics["period_error_ms"]["max"] == pytest.approx(2.0) and haptics["period_error_ms"]["median"] < 1e-6
    assert haptics["contact_time_s"] == pytest.approx(0.1) and haptics["max_penetration_mm"] == pytest.approx(4.0)
    assert haptics["max_force_n"] == pytest.approx(2.5)
    tree = report["kdtree"]
    assert tree["updates"] == 3 and tree["build_ms"]["median"] == pytest.approx(20.0, rel=0.005) and tree["points_median"] == 11
    stream = report["stream"]
    assert (stream["frames"], stream["dropped"]) == (4, 2)
    assert report["registration_residual_mm"] == pytest.approx(1.2)
    text = describe(report)
    assert "1000 samples" in text and "residual 1.20 mm" in text and "2 dropped" in text


def test_a_run_without_data_says_so(tmp_path):
    sources, summary = rig(tmp_path)
    summary.stop()
    report = json.loads((tmp_path / "summary.json").read_text())
    assert report["haptics"]["rate_hz"] is None and report["haptics"]["period_error_ms"]["p99"] is None
    assert report["kdtree"]["rate_hz"] is None and report["registration_residual_mm"] is None
    assert "NOT REGISTERED" in describe(report)


def test_its_size_does_not_grow_with_the_haptic_samples(tmp_path):
    """A 1 kHz loop sends 60,000 samples a minute: the summary keeps running figures and histograms,
    not a list of them (issue 23's growth in long runs)."""
    import tracemalloc

    sources, summary = rig(tmp_path)

    def run(start: int, count: int) -> None:
        for i in range(start, start + count):
            sources.samples.write(sample(i * 1e-3, i % 2 == 0, 0.001, 1.0))
            if i % 1000 == 999:
                summary.step()

    run(0, 2_000)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        run(2_000, 40_000)
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    summary.stop()
    assert grown < 100_000, f"{grown} bytes more after 40,000 samples"
    assert json.loads((tmp_path / "summary.json").read_text())["haptics"]["samples"] == 42_000


def test_the_latencies_are_split_by_the_steps_their_stamps_passed(tmp_path):
    """The camera's frames to the pixels (GLManager.latency) and to the structure built (the
    structure's origin): each step's time from the one before, medians and p99 by step."""
    sources, summary = rig(tmp_path)
    for i in range(100):
        way = Stamp(1.0, i, "camera").step("sent", 1.001).step("received", 1.021)
        frame = way.step("frame_start", 1.031).step("drawn", 1.131).step("read_back", 1.132)
        sources.display_latency.write(Stamped(0.132, frame))
        built = way.step("meshed", 1.025).step("built", 1.045)
        sources.structures.write(CloudStructure("grid", np.zeros((4, 3)), build_seconds=0.02, origin=built))
    summary.step()
    summary.stop()
    report = json.loads((tmp_path / "summary.json").read_text())
    display = report["display_steps_ms"]["camera"]
    assert list(display) == ["sent", "received", "frame_start", "drawn", "read_back"]
    for name, expected in zip(display, (1.0, 20.0, 10.0, 100.0, 1.0)):
        assert display[name]["median"] == pytest.approx(expected, rel=0.01), name
    tree = report["kdtree"]
    assert list(tree["steps_ms"]) == ["sent", "received", "meshed", "built"]
    assert tree["steps_ms"]["meshed"]["median"] == pytest.approx(4.0, rel=0.01)
    assert tree["latency_ms"]["median"] == pytest.approx(45.0, rel=0.01)
    text = describe(report)
    assert "sensor to touchable: median 45.0" in text and "drawn +100.0" in text, text


def test_each_steps_share_is_of_its_own_frames_path(tmp_path):
    """What bounds a path: the median over frames of step / that frame's whole path, not a share
    of the summed step medians (which add up to no frame's latency): half the frames spend 90 % of
    their path received, the other half 10 %, and the median share is a frame's, 0.9 or 0.1."""
    sources, summary = rig(tmp_path)
    for i in range(101):
        slow = i % 2 == 0  # 51 frames: 90 ms of 100 received; 50: 10 ms of 100
        way = Stamp(1.0, i, "camera").step("received", 1.090 if slow else 1.010).step("drawn", 1.100)
        sources.display_latency.write(Stamped(0.100, way))
    summary.step()
    summary.stop()
    report = json.loads((tmp_path / "summary.json").read_text())
    shares = report["display_step_shares"]["camera"]
    assert shares["received"] == pytest.approx(0.9, rel=0.01) and shares["drawn"] == pytest.approx(0.1, rel=0.01)


def test_the_cpu_of_every_process_of_the_application_is_reported_at_the_stop(tmp_path):
    """Here the summary runs in the launcher's own process (no process level): that one alone."""
    sources, summary = rig(tmp_path)
    summary.stop()
    report = json.loads((tmp_path / "summary.json").read_text())
    cpu = report["cpu"]
    assert list(cpu["cores"]) == ["launcher"] and cpu["cores"]["launcher"] > 0, cpu
    assert cpu["total_cores"] == cpu["cores"]["launcher"]
    assert "CPU (cores, CPU time / time lived): launcher " in describe(report)


def test_the_display_latency_is_reported_by_the_source_a_frame_showed_first(tmp_path):
    """GLManager stamps each frame that shows a new input with the oldest such input: the remote
    camera's frames (acquisition to pixels, the paper's sensor-to-display latency) and the hand's
    poses are reported apart."""
    sources, summary = rig(tmp_path)
    for i in range(100):
        sources.display_latency.write(Stamped(0.040 + 1e-4 * i, Stamp(0.0, i, "camera")))
        sources.display_latency.write(Stamped(0.010, Stamp(0.0, i, "/hand/pose")))
    summary.step()
    summary.stop()
    report = json.loads((tmp_path / "summary.json").read_text())["display_latency_ms"]
    assert set(report) == {"camera", "/hand/pose"}
    camera = report["camera"]
    assert camera["frames"] == 100 and camera["median"] == pytest.approx(44.9, rel=0.005)
    assert camera["max"] == pytest.approx(49.9)
    assert "display latency from camera: median 44.9" in describe(json.loads((tmp_path / "summary.json").read_text()))


def test_a_stream_that_stops_is_counted_as_a_stall_and_the_contact_after_it_reported(tmp_path):
    """Frames 33 ms apart for a second, one more 2 s later, then none until the stop (over 2 s
    later): two stalls (over the summary's 1 s), the longest gap at least 2 s; the contact the haptic
    loop rendered after the last frame (on the last structure) is reported apart. The frames'
    acquisition stamps and the samples' times are this host's perf_counter, as in the app."""
    import time

    sources, summary = rig(tmp_path)
    start = time.perf_counter() - 5.0
    stamps = [start + i / 30 for i in range(31)] + [start + 3.0]
    for seq, stamp in enumerate(stamps, 1):
        sources.frames.write(Stamped("frame", Stamp(stamp, seq, "camera")))
    for i in range(1000):  # in contact from 1.5 s to 3.5 s after the start, every 2 ms
        sources.samples.write(sample(start + 1.5 + 2e-3 * i, True, 0.002, 1.0))
    summary.step()
    summary.stop()
    report = json.loads((tmp_path / "summary.json").read_text())
    stream = report["stream"]
    assert stream["frames"] == 32 and stream["dropped"] == 0 and stream["stalls"] == 2, stream
    assert stream["longest_gap_s"] >= 2.0 and stream["silent_at_end_s"] >= 2.0 and stream["stall_s"] == 1.0
    assert report["haptics"]["contact_after_last_frame_s"] == pytest.approx(0.5, abs=3e-3)
    assert report["haptics"]["contact_time_s"] == pytest.approx(1.998)
    text = describe(report)
    assert "STREAM STALLED 2 times (no newer frame for over 1 s)" in text and "0.50 s of contact rendered after it" in text

