"""Figure 2: one uint8 RGB frame through the pooled channel, against a copying port and an rclpy topic.

Per frame size:
- *pooled*: ``PooledOutputPort.acquire`` -> fill a few bytes in place -> ``write``; the reader's
  ``read()`` returns the slot, which it ``release()``s. Nothing is copied, whatever the size.
- *copy DATA*: a DATA/LOCKED connection; the writer writes ``frame.copy()`` (it must keep its buffer),
  the reader reads the copy.
- *rclpy Image*: publish a sensor_msgs/Image (rgb8) and ``spin_once`` until the callback has fired.
Goal: the pooled cost does not depend on the frame size, while copies grow with it.

    PYTHONPATH=coco_core .venv/bin/python bench/bench_pool.py [--json PATH] [--no-plot]
"""

from __future__ import annotations

from typing import Any

import _report
from _ros import Loopback, RosContext  # sets ROS_DOMAIN_ID before rclpy is imported
from _table import Table, fmt_ratio, fmt_time_ns, verdict
from _timing import Loop, Samples, measure

import numpy as np
from sensor_msgs.msg import Image

from coco_core.application import Application
from coco_core.component import Component
from coco_core.policy import NEW_DATA, BufferPolicy, ConnectionPolicy
from coco_core.pool import Slot
from coco_core.ports import InputPort, OutputPort, PooledOutputPort

SIZES = [(160, 120), (640, 480), (1920, 1080)]
CONSTANT = 1.5
"""The pooled cost counts as constant when the largest frame costs at most this much more than the smallest."""
POOLED, COPY, ROS = "pooled", "copy DATA", "rclpy Image"


class PooledCamera(Component):
    image = PooledOutputPort(slots=4)


class PooledViewer(Component):
    image = InputPort(Slot)


class CopyCamera(Component):
    image = OutputPort(np.ndarray)


class CopyViewer(Component):
    image = InputPort(np.ndarray)


def pooled_loop(out: PooledOutputPort, inp: InputPort, shape: tuple[int, ...]) -> Loop:
    acquire, write, read = out.acquire, out.write, inp.read

    def loop(n: int) -> None:
        for i in range(n):
            slot = acquire(shape)
            slot.array[0, 0] = i & 255
            write(slot)
            _, got = read()
            got.release()

    return loop


def copy_loop(out: OutputPort, inp: InputPort, frame: np.ndarray) -> Loop:
    write, read = out.write, inp.read

    def loop(n: int) -> None:
        for i in range(n):
            frame[0, 0] = i & 255
            write(frame.copy())
            read()

    return loop


def ros_loop(ros: Loopback, msg: Image) -> Loop:
    data = msg.data

    def loop(n: int) -> None:
        for i in range(n):
            data[0] = i & 255
            ros.rounds(msg, 1)

    return loop


def label(variant: str, size: tuple[int, int]) -> str:
    return f"{variant} {size[0]}x{size[1]}"


def build_coco(app: Application, size: tuple[int, int]) -> dict[str, Loop]:
    """The pooled and the copying pair for one frame size, checked once before timing."""
    width, height = size
    shape = (height, width, 3)
    tag = f"{width}x{height}"
    camera, viewer = app.add(PooledCamera(f"pool_cam_{tag}")), app.add(PooledViewer(f"pool_view_{tag}"))
    app.connect(camera.image, viewer.image, ConnectionPolicy(BufferPolicy.POOL))
    slot = camera.image.acquire(shape)
    slot.array[:] = 42
    camera.image.write(slot)
    status, got = viewer.image.read()
    if status is not NEW_DATA or got is not slot or got.array.shape != shape or got.array[-1, -1, -1] != 42:
        raise AssertionError(f"pooled {tag}: read back {status!r} {got!r}, not the slot just written")
    got.release()

    source, sink = app.add(CopyCamera(f"copy_cam_{tag}")), app.add(CopyViewer(f"copy_view_{tag}"))
    app.connect(source.image, sink.image, ConnectionPolicy(BufferPolicy.DATA))
    frame = np.full(shape, 42, np.uint8)
    return {label(POOLED, size): pooled_loop(camera.image, viewer.image, shape),
            label(COPY, size): copy_loop(source.image, sink.image, frame)}


def image_msg(size: tuple[int, int]) -> Image:
    width, height = size
    msg = Image(width=width, height=height, encoding="rgb8", step=width * 3)
    msg.header.frame_id = "camera"
    msg.data = np.full((height, width, 3), 42, np.uint8).tobytes()
    return msg


def tables(samples: dict[str, Samples]) -> tuple[list[Table], dict[str, Any]]:
    main = Table("Figure 2 - one RGB uint8 frame, writer -> reader (per frame, median of repeats)",
                 ["variant", "frame bytes", "time/frame", "copy / this", "rclpy / this"])
    results: dict[str, Any] = {}
    for size in SIZES:
        copy, ros = samples[label(COPY, size)], samples[label(ROS, size)]
        for variant in (POOLED, COPY, ROS):
            s = samples[label(variant, size)]
            nbytes = size[0] * size[1] * 3
            main.add(label(variant, size), f"{nbytes:,}", fmt_time_ns(s.median),
                     fmt_ratio(s.ratio_to(copy)), fmt_ratio(s.ratio_to(ros)))
            results[s.name] = {**s.to_json(), "bytes": nbytes, "x_cheaper_than_copy": s.ratio_to(copy),
                               "x_cheaper_than_rclpy": s.ratio_to(ros)}
    main.notes.append("ratios are medians of per-round ratios; every variant was measured in each round.")

    small, large = SIZES[0], SIZES[-1]
    growth = Table(f"Figure 2b - growth of the cost from {label('', small).strip()} to {label('', large).strip()} "
                   f"({large[0] * large[1] / (small[0] * small[1]):.0f}x the bytes)",
                   ["variant"] + [label("", size).strip() for size in SIZES]
                   + ["largest / smallest", f"goal: pooled <= {CONSTANT:g}x"])
    for variant in (POOLED, COPY, ROS):
        ratio = samples[label(variant, small)].ratio_to(samples[label(variant, large)])
        ok = ratio <= CONSTANT if variant == POOLED else None
        growth.add(variant, *[fmt_time_ns(samples[label(variant, size)].median) for size in SIZES],
                   fmt_ratio(ratio), verdict(ok))
        results[f"growth {variant}"] = {"largest_over_smallest": ratio, "goal_met": ok}
    return [main, growth], results


def draw(samples: dict[str, Samples]):
    def figure(plt: Any) -> Any:
        fig, ax = plt.subplots(figsize=(7, 4.5))
        nbytes = [w * h * 3 for w, h in SIZES]
        for variant, color, dy in ((POOLED, "tab:blue", -13), (COPY, "tab:orange", 6), (ROS, "tab:red", 6)):
            values = [samples[label(variant, size)].median / 1e3 for size in SIZES]
            ax.plot(nbytes, values, marker="o", color=color, label=variant)
            for x, v in zip(nbytes, values):
                ax.annotate(fmt_time_ns(v * 1e3), (x, v), textcoords="offset points", xytext=(4, dy), fontsize=8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(nbytes, [f"{w}x{h}" for w, h in SIZES])
        ax.minorticks_off()
        ax.margins(x=0.12, y=0.15)
        ax.set_xlabel("frame size (RGB uint8, log scale)")
        ax.set_ylabel("time per frame, writer -> reader (us, log)")
        ax.set_title("Pooled frames vs copies vs rclpy Image (one process)")
        ax.legend()
        ax.grid(True, which="major", alpha=0.3)
        return fig

    return figure


def main() -> None:
    args = _report.parser("bench_pool", __doc__.splitlines()[0]).parse_args()
    app = Application("bench_pool")
    variants: dict[str, Loop] = {}
    for size in SIZES:
        variants.update(build_coco(app, size))
    with RosContext() as context:
        loopbacks = []
        for size in SIZES:
            ros = Loopback(context, Image, f"bench_image_{size[0]}x{size[1]}", depth=1)
            msg = image_msg(size)
            ros.wait_matched(msg)
            loopbacks.append(ros)
            variants[label(ROS, size)] = ros_loop(ros, msg)
        try:
            samples = measure(variants, repeats=7, target_s=0.05)
        finally:
            for ros in loopbacks:
                ros.destroy()
    t, results = tables(samples)
    _report.emit("bench_pool", args, t, results)
    _report.save_plot(args, draw(samples))


if __name__ == "__main__":
    main()
