"""Vision module costs against their anchors, measured side by side in one run.

1. Format conversions through the ImageConverter component (port in, convert, port out) vs a bare
   ``cv2.cvtColor``: the framework's overhead per frame.
2. MarkerTracker (detect, sub-pixel, IPPE pose, edge into the transformation graph) on the real
   1280x960 ArUco image vs bare ``cv2.aruco`` detection + ``solvePnP``.
3. MeshReconstructor on a real 640x480 Redwood RGB-D frame (its default two bands of rows on two
   threads, and one thread) vs Open3D's RGB-D -> point cloud (one thread), and Open3D's cloud +
   normals (``estimate_normals``). Goal: faster than Open3D. Open3D allocates its
   cloud (12.8 MB of float64) every frame: where glibc hands that memory back to the system after
   each frame, as in a fresh process, every frame pays ~3,700 page faults and takes 3x longer. The
   anchor is Open3D at its best (glibc told to keep freed memory: ``mallopt``); the fresh-process
   figure is shown beside it, measured in a child process.
4. Streaming packets for 640x480 RGB-D: bytes per frame and encode + decode time for JPEG / raw
   colour and Zstandard / PNG / raw depth, and the default packet's colour and depth coded on two
   threads at once against one; a 30 Hz run over ZeroMQ TCP loopback with the receiver in a
   triggered activity woken by its socket against the same in a periodic 10 ms activity (a poll),
   and the same frames as rclpy Image / CompressedImage over DDS.

Run: ``python bench/bench_vision.py --json bench/results/bench_vision.json`` (about a minute).
"""

from __future__ import annotations

import ctypes
import glob
import importlib.util
import json
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from _report import LoadMeter, emit, parser, save_plot
from _table import Table, fmt_ratio, fmt_time_ns, verdict
from _timing import measure

REPO = Path(__file__).resolve().parents[1]
for package in ("coco_core", "coco_mr_vision"):
    if str(REPO / package) not in sys.path:
        sys.path.insert(0, str(REPO / package))

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort, OutputPort  # noqa: E402
from coco_core.stamps import Stamp, Stamped  # noqa: E402
from coco_mr_vision.converter import ImageConverter  # noqa: E402
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat  # noqa: E402
from coco_mr_vision.marker_tracker import MarkerTracker, marker_pose  # noqa: E402
from coco_mr_vision.mesh import TriangleMesh  # noqa: E402
from coco_mr_vision.mesh_reconstructor import MeshReconstructor  # noqa: E402
from coco_mr_vision.rgbd import RGBDFrame  # noqa: E402
from coco_mr_vision.stream_codec import decode, encode  # noqa: E402

DATA = REPO.parent / "shared" / "data"
REDWOOD = DATA / "rgbd" / "redwood"
ARUCO = DATA / "aruco"


class Source(Component):
    out = OutputPort(object)


class Sink(Component):
    inp = InputPort(object)


def open3d_core():
    """Open3D's compiled core (``open3d.pybind``), loaded without the package's ``__init__``, which
    imports the web visualiser (plotly, dash, flask): those are not needed for geometry."""
    spec = importlib.util.find_spec("open3d")
    if spec is None or spec.origin is None:
        return None
    found = glob.glob(str(Path(spec.origin).parent / "pybind*.so"))
    if not found:
        return None
    module_spec = importlib.util.spec_from_file_location("pybind", found[0])
    module = importlib.util.module_from_spec(module_spec)
    module_spec.loader.exec_module(module)
    return module


def bench_conversions(photo: np.ndarray) -> tuple[Table, dict]:
    table = Table("Format conversion 640x480: ImageConverter component vs bare cv2.cvtColor",
                  ["conversion", "cv2.cvtColor", "component", "overhead", "ratio"])
    results = {}
    cases = [("YUYV", "BGR8", cv2.COLOR_YUV2BGR_YUYV), ("I420", "RGB8", cv2.COLOR_YUV2RGB_I420),
             ("BGR8", "GRAY8", cv2.COLOR_BGR2GRAY), ("RGB8", "YUYV", cv2.COLOR_RGB2YUV_YUYV)]
    for source, target, code in cases:
        data = Image(photo, ImageFormat.BGR8).to(source).data
        app = Application("convert")
        src = app.add(Source("src"))
        converter = app.add(ImageConverter("conv", format=target))
        sink = app.add(Sink("sink"))
        app.connect(src.out, converter.image, ConnectionPolicy(BufferPolicy.BUFFER, size=2))
        app.connect(converter.converted, sink.inp)
        stamp = Stamp.now(0, "camera")

        def component(n: int) -> None:
            for _ in range(n):
                src.out.write(Stamped(Image(data, source), stamp))  # a new image per frame, as a camera
                converter.on_update()
                sink.inp.read()

        def bare(n: int) -> None:
            for _ in range(n):
                cv2.cvtColor(data, code)

        samples = measure({"bare": bare, "component": component}, repeats=5, target_s=0.1)
        b, c = samples["bare"], samples["component"]
        table.add(f"{source} -> {target}", fmt_time_ns(b.median), fmt_time_ns(c.median),
                  fmt_time_ns(c.median - b.median), fmt_ratio(c.ratio_to(b)))
        results[f"{source}->{target}"] = {"bare": b.to_json(), "component": c.to_json()}
    table.notes.append("ratio: bare / component time (1.00x = no overhead); overhead: the difference per frame")
    return table, results


def bench_markers() -> tuple[Table, dict]:
    document = json.loads((ARUCO / "tag_01_d7_14cm.json").read_text())
    intrinsics = CameraIntrinsics.from_json(document)
    bgr = cv2.imread(str(ARUCO / "tag_01_d7_14cm.png"), cv2.IMREAD_COLOR)
    app = Application("markers")
    src = app.add(Source("src"))
    tracker = app.add(MarkerTracker("tracker", dictionary=document["dictionary"], marker_length=0.145))
    sink = app.add(Sink("sink"))
    app.connect(src.out, tracker.image, ConnectionPolicy(BufferPolicy.BUFFER, size=2))
    app.connect(tracker.markers, sink.inp)
    tracker.on_config()
    parameters = cv2.aruco.DetectorParameters()
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_1000), parameters)

    def component(n: int) -> None:
        for _ in range(n):
            src.out.write(Image(bgr, ImageFormat.BGR8, 1.0, "camera", intrinsics))
            tracker.on_update()
            sink.inp.read()

    def bare(n: int) -> None:
        for _ in range(n):
            grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
            corners, ids, _ = detector.detectMarkers(grey)
            for c in corners:
                marker_pose(c.reshape(4, 2), 0.145, intrinsics)

    samples = measure({"bare": bare, "component": component}, repeats=5, target_s=0.3)
    b, c = samples["bare"], samples["component"]
    table = Table("MarkerTracker per frame (1280x960, one marker) vs bare cv2.aruco + solvePnP",
                  ["variant", "per frame", "ratio"])
    table.add("bare cv2.aruco + IPPE solvePnP", fmt_time_ns(b.median), "-")
    table.add("MarkerTracker (port, pose, graph edge)", fmt_time_ns(c.median), fmt_ratio(c.ratio_to(b)))
    return table, {"bare": b.to_json(), "component": c.to_json()}


def redwood_frame() -> RGBDFrame:
    return RGBDFrame.load(REDWOOD / "color" / "00000.jpg", REDWOOD / "depth" / "00000.png",
                          CameraIntrinsics.from_json(REDWOOD / "camera_primesense.json"))


def open3d_cloud(o3d, frame: RGBDFrame):
    """One frame through Open3D, as its tutorials do it: RGBDImage, then PointCloud."""
    color = o3d.geometry.Image(np.ascontiguousarray(frame.color.to("RGB8").data))
    depth = o3d.geometry.Image(frame.depth.data)
    k = o3d.camera.PinholeCameraIntrinsic(640, 480, 525.0, 525.0, 319.5, 239.5)

    def cloud():
        rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(color, depth, depth_trunc=10.0,
                                                                  convert_rgb_to_intensity=False)
        return o3d.geometry.PointCloud.create_from_rgbd_image(rgbd, k)
    return cloud


_FRESH = """
import statistics, sys, time
sys.path.insert(0, {bench!r})
import bench_vision
cloud = bench_vision.open3d_cloud(bench_vision.open3d_core(), bench_vision.redwood_frame())
times = []
for _ in range({frames}):
    start = time.perf_counter_ns()
    cloud()
    times.append(time.perf_counter_ns() - start)
print(statistics.median(times))
"""


def open3d_fresh_process(frames: int = 40) -> float:
    """Open3D's per-frame time (ns, median) in a process of its own, whose heap nothing has grown."""
    code = _FRESH.format(bench=str(Path(__file__).resolve().parent), frames=frames)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300)
    return float(done.stdout.split()[-1])


def keep_freed_memory() -> None:
    """glibc: serve large blocks from the heap and keep what is freed (no trimming), so that a
    library that allocates its output every frame reuses pages instead of faulting in new ones."""
    libc = ctypes.CDLL(None)
    libc.mallopt(-3, 256 << 20)  # M_MMAP_THRESHOLD
    libc.mallopt(-1, 1 << 30)    # M_TRIM_THRESHOLD


def bench_mesh(o3d) -> tuple[Table, dict]:
    frame = redwood_frame()
    variants = {}
    for stride, threads in ((1, 2), (1, 1), (2, 2)):
        app = Application("mesh")
        src = app.add(Source("src"))
        mesher = app.add(MeshReconstructor(f"mesher{stride}_{threads}", stride=stride, threads=threads))
        sink = app.add(Sink("sink"))
        app.connect(src.out, mesher.rgbd, ConnectionPolicy(BufferPolicy.BUFFER, size=2))
        app.connect(mesher.mesh, sink.inp)

        def run(n: int, src=src, mesher=mesher, sink=sink) -> None:
            for _ in range(n):
                src.out.write(frame)
                mesher.on_update()
                _, slot = sink.inp.read()
                slot.release()
        variants[f"MeshReconstructor stride {stride}, {threads} thread{'s' if threads > 1 else ''}"] = run
    counts = {}
    fresh_ns = None
    if o3d is not None:
        fresh_ns = open3d_fresh_process()
        keep_freed_memory()
        make_cloud = open3d_cloud(o3d, frame)

        def cloud(n: int) -> None:
            for _ in range(n):
                counts["open3d points"] = len(make_cloud().points)

        def cloud_normals(n: int) -> None:
            for _ in range(n):
                make_cloud().estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.02, max_nn=16))
        variants["Open3D RGB-D -> cloud"] = cloud
        variants["Open3D RGB-D -> cloud + normals"] = cloud_normals
    samples = measure(variants, repeats=5, target_s=0.5)
    anchor = samples.get("Open3D RGB-D -> cloud")
    anchor_n = samples.get("Open3D RGB-D -> cloud + normals")
    table = Table("MeshReconstructor 640x480 (Redwood frame) vs Open3D",
                  ["variant", "per frame", "vs O3D cloud", "vs O3D cloud, fresh process", "vs O3D cloud+normals",
                   "goal: faster"])
    for name, s in samples.items():
        ours = name.startswith("MeshReconstructor")
        table.add(name, fmt_time_ns(s.median), fmt_ratio(s.ratio_to(anchor)) if anchor and ours else "-",
                  fmt_ratio(fresh_ns / s.median) if fresh_ns and ours else "-",
                  fmt_ratio(s.ratio_to(anchor_n)) if anchor_n and ours else "-",
                  verdict(s.ratio_to(anchor) > 1.0) if anchor and ours else "-")
    if fresh_ns is not None:
        table.add("Open3D RGB-D -> cloud, fresh process", fmt_time_ns(fresh_ns), "-", "-", "-", "-")
    mesh_app = Application("count")
    src = mesh_app.add(Source("src"))
    mesher = mesh_app.add(MeshReconstructor("m"))
    sink = mesh_app.add(Sink("sink"))
    mesh_app.connect(src.out, mesher.rgbd)
    mesh_app.connect(mesher.mesh, sink.inp)
    src.out.write(frame)
    mesher.on_update()
    mesh = TriangleMesh.from_slot(sink.inp.read()[1])
    table.notes.append(f"ours: {len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles, normals and colours; "
                       f"Open3D: {counts.get('open3d points', 'n/a')} points (no triangles; normals by a KD-tree "
                       "search, radius 2 cm, 16 neighbours)")
    if o3d is None:
        table.notes.append("open3d is not installed: the anchor rows are missing")
    results = {name: s.to_json() for name, s in samples.items()}
    if fresh_ns is not None:
        results["Open3D RGB-D -> cloud, fresh process"] = {"median_ns": fresh_ns}
    return table, results


def bench_streaming() -> tuple[Table, Table, dict]:
    frame = redwood_frame()
    packets = Table("Stream packet for one 640x480 RGB-D frame: size and encode + decode time",
                    ["colour", "depth", "bytes", "Mbit/s at 30 Hz", "encode", "decode"])
    results: dict = {}
    for color_encoding, depth_encoding in (("jpeg", "zstd"), ("jpeg", "png"), ("jpeg", "raw"), ("raw", "zstd"),
                                           ("raw", "png"), ("raw", "raw")):
        packet = encode(1, 0.0, 0.0, frame.color, frame.depth, color_encoding=color_encoding,
                        depth_encoding=depth_encoding)

        def enc(n: int, ce=color_encoding, de=depth_encoding) -> None:
            for _ in range(n):
                encode(1, 0.0, 0.0, frame.color, frame.depth, color_encoding=ce, depth_encoding=de)

        def dec(n: int, packet=packet) -> None:
            for _ in range(n):
                decode(packet)
        samples = measure({"encode": enc, "decode": dec}, repeats=3, target_s=0.2)
        packets.add(color_encoding + (" q90" if color_encoding == "jpeg" else ""), depth_encoding, f"{len(packet):,}",
                    f"{len(packet) * 8 * 30 / 1e6:.1f}", fmt_time_ns(samples["encode"].median),
                    fmt_time_ns(samples["decode"].median))
        results[f"{color_encoding}+{depth_encoding}"] = {"bytes": len(packet), "encode": samples["encode"].to_json(),
                                                        "decode": samples["decode"].to_json()}
    packets.add(*two_threads(frame, results))
    packets.notes.append("on two threads: the colour (JPEG) in the calling thread and the depth (Zstandard) "
                         "on a worker thread at once (both release the GIL); in brackets the ratio to the same "
                         "packet on one thread, measured interleaved with it (>1: the threads pay)")
    live = Table("Streaming 640x480 RGB-D at 30 Hz over ZeroMQ TCP loopback (server and receiver threads)",
                 ["encoding", "receiver", "frames", "dropped", "latency p50", "latency p90", "latency max",
                  "cycles", "CPU (process)"])
    from coco_mr_vision.streaming import StreamingReceiver, StreamingServer
    port = 5701
    for ce, de in (("jpeg", "zstd"), ("jpeg", "png"), ("raw", "raw")):
        for mode in RECEIVER_MODES:  # the triggered receiver and its anchor, one after the other
            port += 1
            row = stream_live(frame, port, ce, de, mode, StreamingServer, StreamingReceiver)
            lat = np.array(row["latency_ns"])
            live.add(f"{ce} + {de}", mode, row["counters"]["frames"], row["counters"]["dropped"],
                     fmt_time_ns(float(np.median(lat))), fmt_time_ns(float(np.percentile(lat, 90))),
                     fmt_time_ns(float(lat.max())), row["cycles"], f"{row['cpu_cores'] * 100:.0f}% of a core")
            results[f"live {ce}+{de}, {mode}"] = row
    results.update(bench_dds(frame, live))
    live.notes.append("latency: from the frame's acquisition stamp to its delivery on the receiver's port "
                      "(encode, TCP, the wait for the receiver's cycle, decode, newest-frame selection), the "
                      "stamp's 'received' step; receiver: in a triggered activity woken by its socket "
                      "(DescriptorTrigger), or, the anchor, in a periodic 10 ms activity that looks at each "
                      "cycle (the palpation app's stream before issue 34); cycles: the receiver activity's; "
                      "the rclpy rows: from before the "
                      "conversion to messages to both messages decoded in the subscriber (publish + spin "
                      "in one thread, Fast DDS in the same process, shared-memory transport allowed)")
    return packets, live, results


def two_threads(frame: RGBDFrame, results: dict) -> list[str]:
    """The default packet (JPEG q90 + Zstandard) with its colour and depth encoded, and decoded, on
    two threads at once, against the same on one thread, interleaved: whether issue 34's parallel
    coding pays on this machine. A row of the packets table."""
    from concurrent.futures import ThreadPoolExecutor

    color_packet, depth_packet = encode(1, 0.0, 0.0, frame.color, None), encode(1, 0.0, 0.0, None, frame.depth)
    whole = encode(1, 0.0, 0.0, frame.color, frame.depth)
    with ThreadPoolExecutor(1) as worker:
        def enc_two(n: int) -> None:
            for _ in range(n):
                depth = worker.submit(encode, 1, 0.0, 0.0, None, frame.depth)
                encode(1, 0.0, 0.0, frame.color, None)
                depth.result()

        def dec_two(n: int) -> None:
            for _ in range(n):
                depth = worker.submit(decode, depth_packet)
                decode(color_packet)
                depth.result()

        def enc_one(n: int) -> None:
            for _ in range(n):
                encode(1, 0.0, 0.0, frame.color, frame.depth)

        def dec_one(n: int) -> None:
            for _ in range(n):
                decode(whole)
        samples = measure({"encode, one thread": enc_one, "encode, two threads": enc_two,
                           "decode, one thread": dec_one, "decode, two threads": dec_two}, repeats=5, target_s=0.2)
    results["jpeg+zstd, two threads"] = {name: sample.to_json() for name, sample in samples.items()}
    enc = samples["encode, two threads"]
    dec = samples["decode, two threads"]
    return ["jpeg q90 (thread 1)", "zstd (thread 2)", f"{len(color_packet) + len(depth_packet):,}", "-",
            f"{fmt_time_ns(enc.median)} ({fmt_ratio(enc.ratio_to(samples['encode, one thread']))})",
            f"{fmt_time_ns(dec.median)} ({fmt_ratio(dec.ratio_to(samples['decode, one thread']))})"]


RECEIVER_MODES = ("triggered", "periodic 10 ms")
"""How the receiver's activity runs: woken by its socket, or the anchor, a 10 ms period (a poll)."""


class Taken(Component):
    """Collects what the receiver delivers, in the receiver's activity (after it, in the same cycle)."""

    inp = InputPort(object)

    def init(self) -> None:
        self.latencies: list[float] = []

    def on_update(self) -> None:
        for value in self.inp.read_all():
            self.latencies.append(dict(value.stamp.steps)["received"] - value.stamp.time)


def stream_live(frame: RGBDFrame, port: int, ce: str, de: str, mode: str, server_class, receiver_class) -> dict:
    """150 frames at 30 Hz from a server driven by this thread to a receiver in its own activity
    (``mode``, one of :data:`RECEIVER_MODES`); the latencies and the receiver's counters."""
    from coco_core import PeriodicActivity, TriggeredActivity

    sender = Application("send")  # driven by this thread, never started
    src = sender.add(Source("src"))
    server = sender.add(server_class("server", address=f"tcp://127.0.0.1:{port}", color_encoding=ce,
                                     depth_encoding=de))
    sender.connect(src.out, server.rgbd)
    app = Application("receive")
    activity = TriggeredActivity("receive") if mode == "triggered" else PeriodicActivity("receive", 0.010)
    receiver = app.add(receiver_class("receiver", address=f"tcp://127.0.0.1:{port}"), activity)
    taken = app.add(Taken("taken"), activity)
    app.connect(receiver.rgbd, taken.inp, ConnectionPolicy(BufferPolicy.BUFFER, size=200))
    server.on_config()
    app.start()
    try:
        deadline = time.perf_counter() + 10
        seq = 0
        while receiver.frames == 0 and time.perf_counter() < deadline:  # the subscription is up
            seq += 1
            src.out.write(Stamped(frame, Stamp.now(seq, "camera")))
            server.on_update()
            time.sleep(0.05)
        first = len(taken.latencies)
        cycles0 = activity.stats.cycles
        cpu0 = time.process_time()
        wall0 = time.perf_counter()
        for index in range(1, 151):
            seq += 1
            src.out.write(Stamped(frame, Stamp.now(seq, "camera")))
            server.on_update()
            time.sleep(max(0.0, wall0 + index / 30 - time.perf_counter()))
        time.sleep(0.2)  # the last frame's way (the server is gone after this)
        cpu = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
        cycles = activity.stats.cycles - cycles0
    finally:
        app.stop()
        server.on_stop()
    lat = np.array(taken.latencies[first:]) * 1e9
    return {"counters": receiver.counters(), "latency_ns": lat.tolist(), "cpu_cores": cpu, "cycles": cycles}


def bench_dds(frame: RGBDFrame, live: Table) -> dict:
    """The same 150 frames at 30 Hz as rclpy sensor_msgs/Image (raw) and CompressedImage (JPEG colour,
    PNG depth), colour and depth on two topics, publisher and subscriber nodes in this process."""
    try:
        from _ros import Loopback, RosContext
        from sensor_msgs.msg import CompressedImage
        from sensor_msgs.msg import Image as ImageMsg
        from coco_ros.convert.images import ImageMessageConverter as RosImages
    except ImportError as error:
        live.notes.append(f"rclpy rows missing: {error}")
        return {}
    images = RosImages()
    results = {}

    def raw(color: Image, depth: Image):
        return images.to_ros(color), images.to_ros(depth)

    def compressed(color: Image, depth: Image):
        return (CompressedImage(format="jpeg", data=cv2.imencode(".jpg", color.data,
                                                                 [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes()),
                CompressedImage(format="png", data=cv2.imencode(".png", depth.data,
                                                                [cv2.IMWRITE_PNG_COMPRESSION, 1])[1].tobytes()))

    def decode_raw(msg):
        return images.to_coco(msg)

    def decode_compressed(msg):
        return cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_UNCHANGED)

    with RosContext() as context:
        for name, msg_type, make, unpack in (("rclpy Image (raw)", ImageMsg, raw, decode_raw),
                                             ("rclpy CompressedImage (JPEG + PNG)", CompressedImage, compressed,
                                              decode_compressed)):
            tag = "raw" if msg_type is ImageMsg else "compressed"
            color_link = Loopback(context, msg_type, f"vision_color_{tag}")
            depth_link = Loopback(context, msg_type, f"vision_depth_{tag}")
            first = make(frame.color, frame.depth)
            color_link.wait_matched(first[0])
            depth_link.wait_matched(first[1])
            latencies, sizes = [], []
            cpu0, wall0 = time.process_time(), time.perf_counter()
            for seq in range(1, 151):
                start = time.perf_counter()
                color_msg, depth_msg = make(frame.color, frame.depth)
                color_link.rounds(color_msg, 1)
                depth_link.rounds(depth_msg, 1)
                unpack(color_link.last)
                unpack(depth_link.last)
                latencies.append((time.perf_counter() - start) * 1e9)
                sizes.append(len(color_msg.data) + len(depth_msg.data))
                time.sleep(max(0.0, wall0 + seq / 30 - time.perf_counter()))
            cpu = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
            color_link.destroy()
            depth_link.destroy()
            lat = np.array(latencies)
            live.add(name, "publish + spin", 150, 0, fmt_time_ns(float(np.median(lat))),
                     fmt_time_ns(float(np.percentile(lat, 90))), fmt_time_ns(float(lat.max())), "-",
                     f"{cpu * 100:.0f}% of a core")
            results[name] = {"latency_ns": latencies, "bytes": int(np.mean(sizes)), "cpu_cores": cpu}
    return results


def main() -> None:
    args = parser("bench_vision", __doc__.splitlines()[0]).parse_args()
    photo = cv2.imread(str(REDWOOD / "color" / "00000.jpg"), cv2.IMREAD_COLOR)
    o3d = open3d_core()
    with LoadMeter() as load:
        conversions, conv_results = bench_conversions(photo)
        print(conversions.text(), flush=True)
        markers, marker_results = bench_markers()
        print(markers.text(), flush=True)
        mesh, mesh_results = bench_mesh(o3d)
        print(mesh.text(), flush=True)
        packets, live, stream_results = bench_streaming()
    conversions.notes.append(f"other processes used {load.others * 100:.0f}% of the machine during the whole run"
                             if load.others is not None else "machine load unknown")
    results = {"conversions": conv_results, "markers": marker_results, "mesh": mesh_results,
               "streaming": stream_results}
    emit("bench_vision", args, [conversions, markers, mesh, packets, live], results)

    def draw(plt):
        figure, axes = plt.subplots(1, 2, figsize=(11, 3.8))
        names = list(mesh_results)
        ms = [mesh_results[n]["median_ns"] / 1e6 for n in names]
        axes[0].barh(names, ms, color=["tab:blue" if n.startswith("Mesh") else "tab:gray" for n in names])
        for y, value in enumerate(ms):
            axes[0].annotate(f"{value:.2f}", (value, y), xytext=(3, 0), textcoords="offset points", va="center")
        axes[0].set_xscale("log")  # Open3D's normals take 100x the others: a linear axis hides them
        axes[0].set_xlim(right=max(ms) * 4)
        axes[0].set_xlabel("ms per 640x480 frame (log scale)")
        axes[0].set_title("RGB-D -> geometry")
        names = list(conv_results)
        x = np.arange(len(names))
        axes[1].bar(x - 0.2, [conv_results[n]["bare"]["median_ns"] / 1e3 for n in names], 0.4, label="cv2.cvtColor",
                    color="tab:gray")
        axes[1].bar(x + 0.2, [conv_results[n]["component"]["median_ns"] / 1e3 for n in names], 0.4,
                    label="ImageConverter", color="tab:blue")
        axes[1].set_xticks(x, names, rotation=20)
        axes[1].set_ylabel("us per frame")
        axes[1].set_title("Format conversion 640x480")
        axes[1].legend()
        figure.tight_layout()
        return figure
    save_plot(args, draw)


if __name__ == "__main__":
    main()
