"""Between two processes: the process level's shared-memory channels against the usual ways.

Small messages (a 19-joint sample: 19 names, 19 positions, a send time), one way from this process to
a receiver process:
- *latency*: 1,000 messages a second, each stamped when sent; the receiver blocks until woken and
  records receive time - send time (both CLOCK_MONOTONIC, which every process shares);
- *throughput*: as many as the receiver takes, for a fixed count (a full shared-memory BUFFER makes
  the sender wait for room, as a full ZeroMQ queue blocks it).
Transports: the CoCo shared-memory channel (BUFFER ring, the receiver woken through an eventfd, as the
process level wires an event port; and with a receiver that spins on the ring instead, which shows
the channel's own cost without the kernel's wake-up of a sleeping process), ``multiprocessing.Queue``, ZeroMQ PUSH/PULL over ``ipc://``, and
an rclpy topic (sensor_msgs/JointState, reliable, SingleThreadedExecutor in the receiver), and Eclipse
iceoryx2 (its Python bindings: a zero-copy publish-subscribe service of byte slices holding the same
pickled sample, the receiver blocking in an event listener or polling the subscriber).
Goals: p50 latency >= 20x lower than rclpy and >= 3x lower than multiprocessing.Queue; p50 and p99 no
worse than iceoryx2's with either kind of receiver; throughput at least ZeroMQ's.

Frames (RGB, 160x120 to 1920x1080), one way, 50 a second: from the moment the frame is in the
producer's memory to the moment the receiver has it as a numpy array: the CoCo pooled channel (the
frame is made in a shared-memory slot and read in place), ZeroMQ (``send(copy=False)``, received
into bytes), rclpy sensor_msgs/Image; and the same frame written to a plain (copying) port, through
the value channel (a segment per large value, one copy each way). Goal: the pooled channel's cost
independent of the frame size (largest / smallest <= 1.5x).

    .venv/bin/python bench/bench_ipc.py [--messages 2000] [--rounds 3] [--json PATH] [--no-plot]
"""

from __future__ import annotations

import itertools
import json
import multiprocessing
import os
import pickle
import statistics
import subprocess
import sys
import time
from typing import Any, Callable

import _report
from _table import Table, fmt_ratio, fmt_time_ns, verdict

import numpy as np

NAMES = [f"joint_{k}" for k in range(19)]
SIZES = {"160x120": (120, 160), "640x480": (480, 640), "1920x1080": (1080, 1920)}
WARMUP = 100
GOAL_VS_RCLPY, GOAL_VS_QUEUE, GOAL_FRAMES = 20.0, 3.0, 1.5
TOPIC = "/coco_bench/ipc"


def sample(t: float) -> tuple[float, list[str], np.ndarray]:
    return (t, NAMES, np.arange(19, dtype=np.float64))


def stamped_sample(t: float, number: int) -> Any:
    """The sample as an output port hands it to a channel: a Message with the write's stamp, which
    crosses with it (its number, iteration and time in the slot's header)."""
    from coco_core.stamps import Message

    return Message(sample(t), t, number, "bench.out", number)


def paced(count: int, rate: float, send: Callable[[float], None]) -> None:
    """Call ``send(now)`` ``count`` times on an absolute grid of ``rate`` per second."""
    period = 1.0 / rate
    deadline = time.perf_counter()
    for _ in range(count):
        deadline += period
        while (now := time.perf_counter()) < deadline:
            if deadline - now > 3e-4:
                time.sleep(deadline - now - 2e-4)
        send(time.perf_counter())


def summary(latencies: list[float]) -> dict[str, float]:
    values = np.asarray(latencies[WARMUP:] if len(latencies) > 2 * WARMUP else latencies) * 1e9
    return {"samples": int(values.size), "p50_ns": float(np.percentile(values, 50)),
            "p99_ns": float(np.percentile(values, 99))}


# --- receivers (each in its own process) ------------------------------------------------------------
def receive_shm_polling(spec_hex: str, count: int) -> dict[str, Any]:
    """The receiver spins on the ring instead of sleeping until woken: the channel's own cost, without
    the kernel's wake-up of a sleeping process (it burns a core: not how an activity waits)."""
    from coco_core.connections import EMPTY
    from coco_core.shm import ShmReader

    reader = ShmReader(pickle.loads(bytes.fromhex(spec_hex)))
    print("ready", flush=True)
    latencies: list[float] = []
    first = last = 0.0
    while len(latencies) < count:
        value = reader.pop()
        if value is EMPTY:
            continue
        now = time.perf_counter()
        latencies.append(now - value.value[0])
        first, last = first or now, now
    return {**summary(latencies), "received": len(latencies), "seconds": last - first}


END = 1 << 32
"""Added to the wake-up eventfd by the sender once it sent everything: the receiver drains what is
left and stops. A pooled channel keeps the newest frame only, so a receiver late on a loaded machine
misses some (superseded before it read them): it counts them instead of waiting for an exact count."""


def receive_shm(spec_hex: str, fd: int, count: int, frames: bool) -> dict[str, Any]:
    from coco_core.connections import EMPTY
    from coco_core.shm import ShmPoolReader, ShmReader
    from coco_core.stamps import Message

    spec = pickle.loads(bytes.fromhex(spec_hex))
    reader = ShmPoolReader(spec) if frames else ShmReader(spec)
    print("ready", flush=True)
    latencies: list[float] = []
    first = last = 0.0
    ended = False
    while not ended and len(latencies) < count:
        ended = os.eventfd_read(fd) >= END
        while (value := reader.pop()) is not EMPTY:
            now = time.perf_counter()
            if frames:
                _ = value.array[0, 0, 0] + value.array[-1, -1, -1]  # the pixels are there, in place
                latencies.append(now - value.stamp)
                value.release()
            else:  # a stamped sample arrives as its Message; a value pushed bare (a plain port's frame), bare
                latencies.append(now - (value.value if type(value) is Message else value)[0])
            first, last = first or now, now
    return {**summary(latencies), "received": len(latencies), "skipped": count - len(latencies),
            "seconds": last - first}


def iceoryx2_ports(name: str) -> tuple[Any, Any, Any]:
    """(node, publish-subscribe service of byte slices, event service) called ``name``: iceoryx2's way
    of a blocking reader is a subscriber plus an event listener, the publisher notifying after each
    send (its event-based communication example)."""
    import ctypes

    import iceoryx2 as iox

    iox.set_log_level_from_env_or(iox.LogLevel.Error)
    node = iox.NodeBuilder.new().create(iox.ServiceType.Ipc)
    service = (node.service_builder(iox.ServiceName.new(name)).publish_subscribe(iox.Slice[ctypes.c_uint8])
               .subscriber_max_buffer_size(1024).history_size(0).enable_safe_overflow(False).open_or_create())
    event = node.service_builder(iox.ServiceName.new(f"{name}/wake")).event().open_or_create()
    return node, service, event


def receive_iceoryx2(name: str, count: int, blocking: bool) -> dict[str, Any]:
    """The same samples, pickled into iceoryx2 byte slices: the receiver blocks in
    ``Listener.blocking_wait`` until notified (``blocking``) or spins on ``Subscriber.receive``."""
    _node, service, event = iceoryx2_ports(name)
    subscriber = service.subscriber_builder().create()
    listener = event.listener_builder().create()
    print("ready", flush=True)
    latencies: list[float] = []
    first = last = 0.0
    while len(latencies) < count:
        if blocking:
            listener.blocking_wait()
        while (received := subscriber.receive()) is not None:
            value = pickle.loads(received.payload().as_memory_view())
            received.delete()
            now = time.perf_counter()
            latencies.append(now - value[0])
            first, last = first or now, now
    return {**summary(latencies), "received": len(latencies), "seconds": last - first}


def receive_zmq(address: str, count: int, frames: bool) -> dict[str, Any]:
    import zmq

    context = zmq.Context()
    socket = context.socket(zmq.PULL)
    socket.connect(address)
    print("ready", flush=True)
    latencies: list[float] = []
    first = last = 0.0
    while len(latencies) < count:
        if frames:
            header, data = socket.recv_multipart()
            t, shape = pickle.loads(header)
            array = np.frombuffer(data, np.uint8).reshape(shape)
            _ = array[0, 0, 0] + array[-1, -1, -1]
        else:
            t = socket.recv_pyobj()[0]
        now = time.perf_counter()
        latencies.append(now - t)
        first, last = first or now, now
    socket.close()
    context.term()
    return {**summary(latencies), "received": len(latencies), "seconds": last - first}


def receive_rclpy(count: int, frames: bool, seconds: float) -> dict[str, Any]:
    from _ros import RosContext

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Image, JointState

    latencies: list[float] = []
    marks: list[float] = []

    def joint(message: JointState) -> None:
        now = time.perf_counter()
        latencies.append(now - message.effort[0])
        marks.append(now)

    def image(message: Image) -> None:
        array = np.frombuffer(message.data, np.uint8).reshape(message.height, message.width, 3)
        _ = array[0, 0, 0] + array[-1, -1, -1]
        now = time.perf_counter()
        latencies.append(now - (message.header.stamp.sec + message.header.stamp.nanosec * 1e-9))
        marks.append(now)

    with RosContext() as context:
        node = rclpy.create_node("coco_bench_ipc_receiver", context=context)
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        node.create_subscription(Image if frames else JointState, TOPIC, image if frames else joint, qos)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        print("ready", flush=True)
        deadline = time.monotonic() + seconds
        while len(latencies) < count and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        node.destroy_node()
    return {**summary(latencies), "received": len(latencies), "seconds": (marks[-1] - marks[0]) if marks else 0.0}


def receive_queue(queue: Any, results: Any, ready: Any, count: int) -> None:
    ready.set()
    latencies: list[float] = []
    first = last = 0.0
    while len(latencies) < count:
        t = queue.get()[0]
        now = time.perf_counter()
        latencies.append(now - t)
        first, last = first or now, now
    results.put({**summary(latencies), "received": len(latencies), "seconds": last - first})


# --- senders (this process) ------------------------------------------------------------------------
def spawn(*args: str) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    return subprocess.Popen([sys.executable, __file__, "--receive", *args], stdout=subprocess.PIPE, text=True,
                            env=env, pass_fds=tuple(int(a[3:]) for a in args if a.startswith("fd=")))


def wait_ready(process: subprocess.Popen[str]) -> None:
    """Until the receiver says it is attached (a loaded machine may take seconds to start it): a
    frame published before would be missed, as a pool keeps the newest only."""
    assert process.stdout is not None
    line = process.stdout.readline().strip()
    if line != "ready":
        raise SystemExit(f"the receiver did not start: {line!r}, exit status {process.wait()}")


def result_of(process: subprocess.Popen[str]) -> dict[str, Any]:
    out, _ = process.communicate(timeout=300)
    return json.loads(out.strip().splitlines()[-1])


def run_shm_polling(count: int, rate: float | None) -> dict[str, Any]:
    from coco_core.policy import BufferPolicy, ConnectionPolicy
    from coco_core.shm import Arena, ShmWriter

    arena = Arena(f"benchpoll{os.getpid()}")
    try:
        spec = arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, size=1024), "bench.out->bench.in")
        writer = ShmWriter(spec)
        numbers = itertools.count(1)
        receiver = spawn("shm-poll", pickle.dumps(spec).hex(), str(count))
        wait_ready(receiver)

        def send(now: float) -> None:
            while writer.pending >= 1000:
                pass
            writer.push(stamped_sample(now, next(numbers)))

        drive(count, rate, send)
        return result_of(receiver)
    finally:
        arena.close()


def run_shm(count: int, rate: float | None, frames: tuple[int, int] | None = None) -> dict[str, Any]:
    from coco_core.policy import BufferPolicy, ConnectionPolicy
    from coco_core.shm import Arena, ShmFramePool, ShmWriter

    arena = Arena(f"bench{os.getpid()}")
    fd = os.eventfd(0)
    try:
        if frames is None:
            spec = arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, size=1024), "bench.out->bench.in")
            writer = ShmWriter(spec)
            writer.trigger = lambda: os.eventfd_write(fd, 1)
            numbers = itertools.count(1)
            receiver = spawn("shm", pickle.dumps(spec).hex(), f"fd={fd}", str(count), "values")
            wait_ready(receiver)

            def send(now: float) -> None:
                while writer.pending >= 1000:  # throughput: wait for room rather than drop
                    pass
                writer.push(stamped_sample(now, next(numbers)))
        else:
            spec = arena.channel(ConnectionPolicy(BufferPolicy.POOL, size=4), "bench.frames->bench.in", frames=True)
            pool = ShmFramePool(spec)
            receiver = spawn("shm", pickle.dumps(spec).hex(), f"fd={fd}", str(count), "frames")
            wait_ready(receiver)
            shape = (*frames, 3)

            def send(now: float) -> None:
                slot = pool.acquire(shape, np.uint8)
                assert slot is not None, "the receiver holds every slot"
                slot.array[0, 0, 0] = slot.array[-1, -1, -1] = 7  # the producer made the frame in the slot
                slot.stamp = time.perf_counter()
                pool.publish(slot)
                os.eventfd_write(fd, 1)
        drive(count, rate, send)
        os.eventfd_write(fd, END)  # all sent: the receiver drains and stops
        return result_of(receiver)
    finally:
        arena.close()
        os.close(fd)


def run_shm_plain(count: int, rate: float | None, frames: tuple[int, int]) -> dict[str, Any]:
    """A frame written to a plain (copying) output port: a value larger than a slot, through a
    segment of its own, one copy each way (what a pooled output avoids)."""
    from coco_core.policy import BufferPolicy, ConnectionPolicy
    from coco_core.shm import Arena, ShmWriter

    arena = Arena(f"bench{os.getpid()}")
    fd = os.eventfd(0)
    try:
        spec = arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, size=4), "bench.out->bench.in")
        writer = ShmWriter(spec)
        writer.trigger = lambda: os.eventfd_write(fd, 1)
        receiver = spawn("shm", pickle.dumps(spec).hex(), f"fd={fd}", str(count), "values")
        wait_ready(receiver)
        frame = np.full((*frames, 3), 7, np.uint8)

        def send(now: float) -> None:
            while writer.pending >= 4:  # a receiver behind: wait for room rather than drop
                pass
            writer.push((time.perf_counter(), frame))

        drive(count, rate, send)
        os.eventfd_write(fd, END)  # all sent: the receiver drains and stops
        return result_of(receiver)
    finally:
        arena.close()
        os.close(fd)


def run_iceoryx2(count: int, rate: float | None, blocking: bool = True) -> dict[str, Any]:
    import ctypes

    import iceoryx2 as iox

    name = f"coco-bench-ipc-{os.getpid()}-{time.monotonic_ns()}"
    node, service, event = iceoryx2_ports(name)
    # A full subscriber buffer makes the publisher retry (throughput: wait for room rather than drop).
    publisher = (service.publisher_builder().initial_max_slice_len(1024)
                 .allocation_strategy(iox.AllocationStrategy.PowerOfTwo)
                 .backpressure_strategy(iox.BackpressureStrategy.RetryUntilDelivered).create())
    notifier = event.notifier_builder().create()
    receiver = spawn("iceoryx2", name, str(count), "blocking" if blocking else "polling")
    wait_ready(receiver)  # its subscriber and listener exist
    publisher.update_connections()

    def send(now: float) -> None:
        data = pickle.dumps(sample(now), protocol=5)
        loan = publisher.loan_slice_uninit(len(data))
        ctypes.memmove(loan.payload_ptr, data, len(data))
        loan.assume_init().send()
        notifier.notify()

    drive(count, rate, send)
    result = result_of(receiver)
    del publisher, notifier, node
    return result


def run_iceoryx2_polling(count: int, rate: float | None) -> dict[str, Any]:
    return run_iceoryx2(count, rate, blocking=False)


def drive(count: int, rate: float | None, send: Callable[[float], None]) -> None:
    if rate is None:
        for _ in range(count):
            send(time.perf_counter())
    else:
        paced(count, rate, send)


def run_queue(count: int, rate: float | None) -> dict[str, Any]:
    context = multiprocessing.get_context("spawn")
    queue, results, ready = context.Queue(), context.Queue(), context.Event()
    process = context.Process(target=receive_queue, args=(queue, results, ready, count))
    process.start()
    if not ready.wait(60):
        raise SystemExit("the multiprocessing.Queue receiver did not start in 60 s")
    drive(count, rate, lambda now: queue.put(sample(now)))
    result = results.get(timeout=300)
    process.join()
    return result


def run_zmq(count: int, rate: float | None, frames: tuple[int, int] | None = None) -> dict[str, Any]:
    import zmq

    address = f"ipc:///tmp/coco-bench-{os.getpid()}.ipc"
    context = zmq.Context()
    socket = context.socket(zmq.PUSH)
    socket.bind(address)
    receiver = spawn("zmq", address, str(count), "frames" if frames else "values")
    wait_ready(receiver)
    if frames is None:
        drive(count, rate, lambda now: socket.send_pyobj(sample(now)))
    else:
        frame = np.zeros((*frames, 3), np.uint8)
        drive(count, rate, lambda now: socket.send_multipart(
            [pickle.dumps((time.perf_counter(), frame.shape)), frame], copy=False))
    result = result_of(receiver)
    socket.close()
    context.term()
    return result


def run_rclpy(count: int, rate: float | None, frames: tuple[int, int] | None = None) -> dict[str, Any]:
    from _ros import RosContext

    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Image, JointState

    receiver = spawn("rclpy", str(count), "frames" if frames else "values", str(60))
    wait_ready(receiver)
    with RosContext() as context:
        node = rclpy.create_node("coco_bench_ipc_sender", context=context)
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        publisher = node.create_publisher(Image if frames else JointState, TOPIC, qos)
        deadline = time.monotonic() + 20
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        if frames is None:
            message = JointState(name=NAMES, position=list(range(19)), effort=[0.0])

            def send(now: float) -> None:
                message.effort = [time.perf_counter()]
                publisher.publish(message)
        else:
            height, width = frames
            image = Image(height=height, width=width, encoding="rgb8", step=width * 3,
                          data=np.zeros(height * width * 3, np.uint8).tobytes())

            def send(now: float) -> None:
                sec, nanosec = divmod(time.perf_counter_ns(), 1_000_000_000)
                image.header.stamp.sec, image.header.stamp.nanosec = sec, nanosec
                publisher.publish(image)
        drive(count, rate, send)
        result = result_of(receiver)
        node.destroy_node()
    return result


def receiver_main(args: list[str]) -> None:
    kind = args[0]
    if kind == "shm":
        result = receive_shm(args[1], int(args[2][3:]), int(args[3]), args[4] == "frames")
    elif kind == "shm-poll":
        result = receive_shm_polling(args[1], int(args[2]))
    elif kind == "zmq":
        result = receive_zmq(args[1], int(args[2]), args[3] == "frames")
    elif kind == "iceoryx2":
        result = receive_iceoryx2(args[1], int(args[2]), args[3] == "blocking")
    else:
        result = receive_rclpy(int(args[1]), args[2] == "frames", float(args[3]))
    print(json.dumps(result), flush=True)


def main() -> None:
    parser = _report.parser("bench_ipc", __doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=2000, help="messages per latency run (1,000 a second)")
    parser.add_argument("--frames", type=int, default=200, help="frames per size (50 a second)")
    parser.add_argument("--rounds", type=int, default=3,
                        help="interleaved rounds of the small-message transports (default 3): each figure is the "
                             "median over the rounds, each ratio and verdict the median of the per-round ratios")
    args = parser.parse_args()
    count = args.messages
    runners: dict[str, Callable[[int, float | None], dict[str, Any]]] = {
        "CoCo shared-memory channel": run_shm, "CoCo channel, receiver polling (no wake-up)": run_shm_polling,
        "Eclipse iceoryx2, Listener.blocking_wait": run_iceoryx2,
        "iceoryx2, receiver polling": run_iceoryx2_polling,
        "multiprocessing.Queue": run_queue,
        "ZeroMQ ipc:// PUSH/PULL": run_zmq, "rclpy topic (JointState)": run_rclpy}
    rounds: list[dict[str, dict[str, float]]] = []
    for index in range(args.rounds):
        one: dict[str, dict[str, float]] = {}
        for name, runner in runners.items():
            latency, throughput = runner(count, 1000.0), runner(count * 5, None)
            rate = throughput["received"] / throughput["seconds"] if throughput["seconds"] else float("nan")
            one[name] = {"p50_ns": latency["p50_ns"], "p99_ns": latency["p99_ns"], "rate": rate}
            print(f"round {index + 1}: {name} {one[name]}", flush=True)
        rounds.append(one)

    def med(name: str, key: str) -> float:
        return statistics.median(one[name][key] for one in rounds)

    def ratio(mine: str, anchor: str, key: str) -> float:
        """The median over the rounds of mine[key] / anchor[key]: the printed figure is the judged one."""
        return statistics.median(one[mine][key] / one[anchor][key] for one in rounds)

    ours = "CoCo shared-memory channel"
    small = {name: {key: med(name, key) for key in ("p50_ns", "p99_ns", "rate")} for name in runners}
    table = Table(f"Small message between two processes (19-joint sample), one way (medians of {args.rounds} rounds)",
                  ["transport", "p50", "p99", "messages/s", "p50 / CoCo", "goal"])
    for name, r in small.items():
        lower = {"rclpy topic (JointState)": GOAL_VS_RCLPY, "multiprocessing.Queue": GOAL_VS_QUEUE}.get(name)
        against = ratio(name, ours, "p50_ns")
        table.add(name, fmt_time_ns(r["p50_ns"]), fmt_time_ns(r["p99_ns"]), f"{r['rate']:,.0f}",
                  fmt_ratio(against), f">= {lower:g}x: {verdict(against >= lower)}" if lower else "-")
    for ours_name, anchor in ((ours, "Eclipse iceoryx2, Listener.blocking_wait"),
                              ("CoCo channel, receiver polling (no wake-up)", "iceoryx2, receiver polling")):
        p50, p99 = ratio(ours_name, anchor, "p50_ns"), ratio(ours_name, anchor, "p99_ns")
        table.notes.append(f"{verdict(p50 <= 1.0 and p99 <= 1.0)}: {ours_name} against {anchor}: {p50:.2f}x at p50, "
                           f"{p99:.2f}x at p99 (goal: no worse, <= 1.00x both)")
    rates = ratio(ours, "ZeroMQ ipc:// PUSH/PULL", "rate")
    table.notes.append(f"{verdict(rates >= 1.0)}: throughput {small[ours]['rate']:,.0f} messages/s against ZeroMQ's "
                       f"{small['ZeroMQ ipc:// PUSH/PULL']['rate']:,.0f} (goal: at least as many; {rates:.2f}x)")
    table.notes.append("Figures: medians over the interleaved rounds; ratios and verdicts: medians of the per-round "
                       "ratios (a ratio of two medians can differ on a noisy machine).")
    table.notes.append("iceoryx2: the sample pickled into a byte slice loaned from its shared memory (the same "
                       "payload and codec as the CoCo channel), the subscriber woken by an event notifier after "
                       "each send, as its event-based communication example does.")
    frames: dict[str, dict[str, Any]] = {}
    for name, runner in {"CoCo pooled channel": run_shm, "CoCo value channel (plain port, copies)": run_shm_plain,
                         "ZeroMQ (copy)": run_zmq,
                         "rclpy sensor_msgs/Image": run_rclpy}.items():
        frames[name] = {size: runner(args.frames, 50.0, shape) for size, shape in SIZES.items()}  # type: ignore[call-arg]
        print(name, frames[name], flush=True)
    frame_table = Table("RGB frame between two processes, one way, p50 (frame in the producer's memory -> "
                        "numpy array in the receiver's)",
                        ["transport", *SIZES, "largest / smallest", "goal", "not received"])
    for name, by_size in frames.items():
        spread = by_size["1920x1080"]["p50_ns"] / by_size["160x120"]["p50_ns"]
        goal = f"<= {GOAL_FRAMES:g}x: {verdict(spread <= GOAL_FRAMES)}" if name == "CoCo pooled channel" else "-"
        lost = sum(args.frames - by_size[size]["received"] for size in SIZES)
        frame_table.add(name, *(fmt_time_ns(by_size[size]["p50_ns"]) for size in SIZES), fmt_ratio(spread), goal,
                        f"{lost} of {args.frames * len(SIZES)}")
    frame_table.notes.append("not received: frames sent that the receiver never had, over all sizes; a pooled "
                             "channel keeps the newest frame only, so one the receiver was late for is superseded "
                             "(counted here; the run ends when the sender has sent them all, not at a frame count)")
    _report.emit("bench_ipc", args, [table, frame_table], {"small": small, "rounds": rounds, "frames": frames})

    def draw(plt: Any) -> Any:
        figure, (left, right) = plt.subplots(1, 2, figsize=(11, 3.6))
        names = list(small)
        left.barh(names, [small[n]["p50_ns"] / 1e3 for n in names], color="#4c72b0")
        left.set_xscale("log")
        left.set_xlabel("one-way p50 latency (us, log)")
        left.set_title("19-joint sample between two processes")
        for name, by_size in frames.items():
            right.plot(list(SIZES), [by_size[s]["p50_ns"] / 1e3 for s in SIZES], marker="o", label=name)
        right.set_yscale("log")
        right.set_ylabel("one-way p50 (us, log)")
        right.set_title("RGB frame between two processes")
        right.legend()
        figure.tight_layout()
        return figure

    _report.save_plot(args, draw)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--receive":
        receiver_main(sys.argv[2:])
    else:
        main()
