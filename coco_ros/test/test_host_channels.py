"""Connections between hosts over real DDS (coco_ros.hosts): the writer's end on one HostBridge, the
reader's end on another (two rclpy contexts, two DDS participants, as two hosts have), and a writer
in another process. Values and stamps arrive (times through the hosts' clock functions), the
reader's policy decides what it keeps, every loss is counted on the reader's side, damaged samples
are counted and skipped, filters run on the reader's side. Domain 164, localhost only."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

from coco_core import Application, Component, InputPort, OutputPort, PeriodicActivity, TriggeredActivity
from coco_core.errors import ChannelError, ConfigError
from coco_core.filters import Greedy, MaxFrequency, Merge, MergeGroup, Split
from coco_core.hosts.auth import Sealer
from coco_core.hosts.channel import HostChannel, topic_of
from coco_core.hosts.key import AppKey
from coco_core.policy import NEW_DATA, OLD_DATA, BufferPolicy, ConnectionPolicy, SyncPolicy
from coco_core.pool import Slot, SlotState
from coco_core.ports import PooledOutputPort
from coco_core.report import snapshot
from coco_core.stamps import Stamp, Stamped
from coco_interfaces.msg import Sample
from coco_ros.hosts.bridge import THREAD_NAME, HostBridge
from coco_ros.hosts.channel import DdsFrameReader, DdsReader, DdsWriter, attach_between_hosts
from coco_ros.hosts.qos import qos_of
from coco_ros.hosts.sample import SampleEncoder, sample_parts
from coco_ros.hosts.seal import sealed

DOMAIN = "164"  # its own: no other test uses it
REDWOOD = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgbd" / "redwood"
DATA = ConnectionPolicy(BufferPolicy.DATA, SyncPolicy.LOCKED, 1)
KEY = AppKey(bytes(range(32)), "the tests' key")
HOSTS = ("alpha", "beta")


def buffer(size: int) -> ConnectionPolicy:
    return ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, size)


def to_app(seconds: float) -> float:
    """The writer's host: its clock is 1000 s behind the application's."""
    return seconds + 1000.0


def from_app(seconds: float) -> float:
    """The reader's host: its clock is 999.5 s behind the application's (0.5 s ahead of the writer's)."""
    return seconds - 999.5


def wait_for(predicate: Callable[[], object], timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return bool(predicate())
        time.sleep(0.002)
    return True


@pytest.fixture(scope="module", autouse=True)
def dds_domain() -> Iterator[None]:
    with pytest.MonkeyPatch.context() as env:  # the environment of the later test modules stays as it was
        env.setenv("ROS_DOMAIN_ID", DOMAIN)  # read by rclpy.init, and by the writer's process
        env.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        yield


@pytest.fixture(scope="module")
def hosts() -> Iterator[tuple[HostBridge, HostBridge]]:
    """The DDS side of a process on host alpha and of one on host beta."""
    alpha, beta = HostBridge("coco_test_alpha"), HostBridge("coco_test_beta")
    yield alpha, beta
    alpha.close()
    beta.close()


class Source(Component):
    out = OutputPort(object)

    def init(self) -> None:
        self.limit = 0
        self.written: list[Stamp] = []

    def on_update(self) -> None:
        if len(self.written) < self.limit:
            count = len(self.written)
            made = Stamp(time.perf_counter() - 0.25, count, "camera").step("made")
            self.out.write(Stamped({"count": count, "array": np.arange(count + 1.0)}, made), stamps={"box": (count, 1)})
            assert self.out.last is not None
            self.written.append(self.out.last.stamp)


class Sink(Component):
    sample = InputPort(object, event=True)

    def init(self) -> None:
        self.got: list[Any] = []

    def on_update(self) -> None:
        self.got += self.sample.read_all()


class Stamps(Component):
    sample = InputPort(Stamp)


class Typed(Component):
    """A reader of numbers only: a value of another type is refused by the connection."""

    sample = InputPort(int | float, event=True)


class Frames(Component):
    out = PooledOutputPort(slots=3)


class Link:
    """A connection ``source.out -> sink.sample`` from host alpha's process to host beta's."""

    def __init__(self, hosts: tuple[HostBridge, HostBridge], name: str, policy: ConnectionPolicy, *,
                 source: Component | None = None, sink: Component | None = None, codec: str = "plain",
                 filter: Any = None, router: Any = None, stamps_only: bool = False,
                 event: bool | None = None) -> None:
        self.channel = HostChannel("source.out", "sink.sample", "alpha", "beta", "", "", policy, event, codec,
                                   topic_of(name, "source.out", "sink.sample"), stamps_only, filter is not None)
        self.writer_app, self.reader_app = Application(name), Application(name)
        self.source = self.writer_app.add(source or Source("source"))
        self.sink = self.reader_app.add(sink or Sink("sink"))
        if filter is not None:  # as the builder makes it on the reader's side
            self.reader_app.incoming_filters[self.channel.label] = filter
        if router is not None:  # as the builder makes a Split's or Cull's on the writer's side
            self.writer_app.outgoing_routers[self.channel.label] = router
        alpha, beta = hosts
        [self.reader] = attach_between_hosts(self.reader_app, beta, [self.channel], "beta", KEY, HOSTS,
                                             from_app=from_app).readers
        [self.writer] = attach_between_hosts(self.writer_app, alpha, [self.channel], "alpha", KEY, HOSTS,
                                             to_app=to_app).writers
        assert wait_for(lambda: self.writer.matched and self.reader.matched)

    @property
    def front(self) -> Any:
        [connection] = self.sink.port("sample").connections
        return connection


@pytest.fixture
def link(hosts: tuple[HostBridge, HostBridge]) -> Iterator[Callable[..., Link]]:
    made: list[Link] = []

    def make(name: str, policy: ConnectionPolicy, **options: Any) -> Link:
        made.append(Link(hosts, name, policy, **options))
        return made[-1]

    yield make
    for each in made:
        each.writer_app.stop()
        each.reader_app.stop()


def test_the_qos_follows_the_connections_policy():
    for policy, depth in ((DATA, 2), (buffer(7), 8), (ConnectionPolicy(BufferPolicy.CIRCULAR, size=3), 4),
                          (ConnectionPolicy(BufferPolicy.POOL, size=4), 2)):
        qos = qos_of(policy)
        assert (qos.history, qos.depth) == (HistoryPolicy.KEEP_LAST, depth), policy
        assert (qos.reliability, qos.durability) == (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE)


def test_values_and_stamps_cross_on_the_applications_clock(link):
    """An activity writes three Stamped values with user stamps: the reader on the other host reads
    them with the stamp the writing port made (number, iteration, source, user stamps) and every time
    in it, the value's own stamp's included, moved from the writer's clock to the reader's (0.5 s);
    the activity's end reaches the reader as its writer_done."""
    crossing = link("stamps", buffer(10))
    source, sink = crossing.source, crossing.sink
    source.limit = 3
    crossing.writer_app.add_activity(PeriodicActivity("ticks", 0.002, [source]))
    crossing.writer_app.start()
    assert wait_for(lambda: crossing.reader.pending == 3)
    assert not crossing.reader.writer_finished
    for count, sent in enumerate(source.written):
        status, value = sink.sample.read()
        stamp = sink.sample.stamp
        assert status is NEW_DATA and value.value["count"] == count
        assert np.array_equal(value.value["array"], np.arange(count + 1.0))
        assert (stamp.seq, stamp.source, stamp.it, dict(stamp.user)) == (count + 1, "source.out", sent.it, {"box": (count, 1)})
        assert sent.it >= count and stamp.time == pytest.approx(sent.time + 0.5, abs=1e-9)
        assert [name for name, _ in stamp.steps] == ["made"]
        assert stamp.steps[0][1] == pytest.approx(sent.steps[0][1] + 0.5, abs=1e-9)
        own = value.stamp  # the Stamped value's own stamp: its number and source, its times moved too
        assert (own.seq, own.source) == (count, "camera") and own.time == pytest.approx(sent.time + 0.5, abs=1e-9)
    crossing.writer_app.stop()  # the activity's finish: writer_done
    assert wait_for(lambda: crossing.reader.writer_finished)
    assert crossing.reader.counters() == {"written": 3, "read": 3, "dropped": 0, "pending": 0}


def test_a_buffer_delivers_every_sample_in_order(link):
    crossing = link("buffer", buffer(500))
    for count in range(300):
        crossing.source.out.write(count)
    assert wait_for(lambda: crossing.reader.pending == 300)
    assert crossing.sink.sample.read_all() == list(range(300))
    assert crossing.reader.counters() == {"written": 300, "read": 300, "dropped": 0, "pending": 0}


def test_data_with_a_slow_reader_counts_what_it_missed_on_both_sides(link):
    """DATA: the reader keeps the newest. 200 writes, 10 reads: at least 189 dropped on the reader's
    side, every one of them accounted for (written = read + dropped + pending), the last value
    delivered; the writer's side published all 200. Both profiles show their side."""
    crossing = link("latest", DATA)
    reads = []
    for count in range(200):
        crossing.source.out.write(count)
        if count % 20 == 19:
            reads.append(crossing.sink.sample.read())
    crossing.writer.writer_done()
    assert wait_for(lambda: crossing.reader.writer_finished)  # after the last value: samples keep their order
    reads.append(crossing.sink.sample.read())
    assert reads[-1][1] == 199
    counters = crossing.reader.counters()
    assert counters["written"] == 200 and counters["pending"] == 0
    assert counters["read"] == sum(status is NEW_DATA for status, _ in reads) <= 11
    assert counters["dropped"] == 200 - counters["read"] >= 189
    assert crossing.writer.counters() == {"written": 200, "read": 200, "dropped": 0, "pending": 0}
    [writer_row] = snapshot(crossing.writer_app).connections
    [reader_row] = snapshot(crossing.reader_app).connections
    assert writer_row == ["source.out -> sink.sample", "DATA/LOCKED, DDS to host beta", "200", "200", "0", "0", "-"]
    assert reader_row == ["source.out -> sink.sample", "DATA/LOCKED, DDS from host alpha", "200",
                          str(counters["read"]), str(counters["dropped"]), "0", "-"]  # unprofiled: no age


def test_a_triggered_reader_is_woken_by_what_arrives(link):
    crossing = link("woken", buffer(10))
    crossing.reader_app.add_activity(TriggeredActivity("reading", [crossing.sink]))
    crossing.reader_app.start()
    for count in range(5):
        crossing.source.out.write(count)
    assert wait_for(lambda: crossing.sink.got == list(range(5)))
    assert crossing.reader_app.activity("reading").stats.cycles >= 1
    crossing.writer.writer_done()  # the reader's natural stop waits for the writer of its BUFFER: it is done


class Counter(Component):
    def init(self) -> None:
        self.updates = 0

    def on_update(self) -> None:
        self.updates += 1


def test_an_activitys_endit_on_one_host_paces_an_activitys_beginit_on_another(hosts):
    """FlowVR's data-driven coupling across hosts: each cycle of ``ticks`` (host alpha) sends its
    ``endit``, and ``loop`` (host beta) cycles once per message on its ``beginit``."""
    channel = HostChannel("ticks.endit", "loop.beginit", "alpha", "beta", "", "", buffer(100), None, "plain",
                          topic_of("paced", "ticks.endit", "loop.beginit"), src_activity=True, dest_activity=True)
    writer_app, reader_app = Application("paced"), Application("paced")
    source = writer_app.add(Source("source"))
    counter = reader_app.add(Counter("counter"))
    ticks = writer_app.add_activity(PeriodicActivity("ticks", 0.005, [source]))
    loop = reader_app.add_activity(TriggeredActivity("loop", [counter]))
    readers = attach_between_hosts(reader_app, hosts[1], [channel], "beta", KEY, HOSTS)
    writers = attach_between_hosts(writer_app, hosts[0], [channel], "alpha", KEY, HOSTS)
    assert wait_for(lambda: readers.matched and writers.matched)
    [reader] = readers.readers
    reader_app.start()
    writer_app.start()
    try:
        assert wait_for(lambda: counter.updates >= 5)
    finally:
        writer_app.stop()  # its finish sends writer_done: the reader's natural stop need not wait
        assert wait_for(lambda: reader.writer_finished)
        reader_app.stop()
    assert ticks.stats.cycles == reader.written and loop.stats.cycles == reader.read
    assert reader.counters()["dropped"] == 0 and counter.updates == loop.stats.cycles


def test_a_writer_in_another_process(hosts, tmp_path):
    """A writer in its own process (its own DDS participant, as on another host): 20 values, then
    its writer_done; the reader here gets all of them, in order, with their user stamps."""
    script = tmp_path / "writer.py"
    script.write_text(WRITER_PROCESS)
    crossing_channel = HostChannel("source.out", "sink.sample", "alpha", "beta", "", "", buffer(50), None, "plain",
                                   topic_of("process", "source.out", "sink.sample"))
    app = Application("process")
    sink = app.add(Sink("sink"))
    [reader] = attach_between_hosts(app, hosts[1], [crossing_channel], "beta", KEY, HOSTS).readers
    writer = subprocess.Popen([sys.executable, str(script)], env={**os.environ, "COCO_TEST_KEY": KEY.secret.hex()},
                              stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True)
    try:
        output = writer.communicate(timeout=60)[0]
    finally:
        writer.kill()
    assert writer.returncode == 0, output
    assert wait_for(lambda: reader.writer_finished and reader.pending == 20)
    values = []
    while (item := sink.sample.read())[0] is NEW_DATA:
        values.append((item[1], dict(sink.sample.stamp.user)))
    assert values == [(count, {"i": count}) for count in range(20)]
    assert reader.counters() == {"written": 20, "read": 20, "dropped": 0, "pending": 0}


WRITER_PROCESS = """
import time
from coco_core import Application, Component, OutputPort
from coco_core.hosts.channel import HostChannel, topic_of
from coco_core.hosts.key import AppKey
from coco_core.policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from coco_ros.hosts.bridge import HostBridge
from coco_ros.hosts.channel import attach_between_hosts

class Source(Component):
    out = OutputPort(object)

channel = HostChannel("source.out", "sink.sample", "alpha", "beta", "", "",
                      ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 50), None, "plain",
                      topic_of("process", "source.out", "sink.sample"))
app = Application("process")
source = app.add(Source("source"))
with HostBridge("coco_test_writer_process") as bridge:
    ends = attach_between_hosts(app, bridge, [channel], "alpha", AppKey.from_environment("COCO_TEST_KEY"),
                                ("alpha", "beta"))
    deadline = time.monotonic() + 30
    while not ends.matched:
        assert time.monotonic() < deadline, "the reader never subscribed"
        time.sleep(0.005)
    for count in range(20):
        source.out.write(count, stamps={"i": count})
    ends.writers[0].writer_done()
"""


def test_the_rgbd_codec_carries_a_redwood_frame(link):
    """JPEG colour (close), Zstandard depth (exact), intrinsics, depth scale, the images' stamps and
    the Stamped value's stamp on the reader's clock; a colour image alone comes back in its format."""
    from coco_mr_vision.image import CameraIntrinsics, ImageFormat
    from coco_mr_vision.rgbd import RGBDFrame

    if not REDWOOD.exists():
        pytest.skip(f"{REDWOOD} is absent (the shared data sets are not beside this checkout)")
    intrinsics = CameraIntrinsics.from_json(REDWOOD / "camera_primesense.json")
    frame = RGBDFrame.load(REDWOOD / "color" / "00000.jpg", REDWOOD / "depth" / "00000.png", intrinsics,
                           stamp=17.5, frame_id="camera")
    rgb = frame.color.to(ImageFormat.RGB8)
    crossing = link("rgbd", buffer(4), codec="rgbd")
    taken = Stamp.now(9, "camera")
    crossing.source.out.write(Stamped(frame, taken))
    written = crossing.source.out.last
    crossing.source.out.write(rgb)
    assert wait_for(lambda: crossing.reader.pending == 2)
    [got, image] = crossing.sink.sample.read_all()
    assert got.stamp.time == pytest.approx(taken.time + 0.5, abs=1e-9) and got.stamp.seq == 9
    arrived = got.value
    assert isinstance(arrived, RGBDFrame) and arrived.depth_scale == frame.depth_scale
    assert arrived.depth.format is ImageFormat.DEPTH16 and np.array_equal(arrived.depth.data, frame.depth.data)
    assert arrived.color.format is ImageFormat.BGR8
    assert np.abs(arrived.color.data.astype(int) - frame.color.data).mean() < 3
    assert arrived.intrinsics is not None and np.array_equal(arrived.intrinsics.K, intrinsics.K)
    assert (arrived.depth.stamp, arrived.depth.frame_id) == (17.5, "camera")
    assert image.format is ImageFormat.RGB8 and np.abs(image.data.astype(int) - rgb.data).mean() < 3
    raw = frame.color.data.nbytes + frame.depth.data.nbytes
    coded = len(SampleEncoder("rgbd", Sealer(KEY, "/t", "alpha")).encode(written, 1).payload)
    assert coded < raw / 4, (coded, raw)


def test_a_damaged_sample_is_counted_reported_and_skipped(link, hosts):
    """Samples with the key that do not decode (garbage, an unknown codec, user stamps that are
    not, a pickle, numbers out of range, a value of another type than the port takes) are counted
    and reported as damaged input, the first ten of the connection (a flood is only counted); the
    next good sample is read as usual."""
    crossing = link("damaged", buffer(20), sink=Typed("sink"))
    garbage = hosts[0].node.create_publisher(Sample, crossing.channel.topic, qos_of(crossing.channel.policy))
    assert wait_for(lambda: garbage.get_subscription_count() == 1)
    sealer = Sealer(KEY, crossing.channel.topic, "alpha")
    bad = [Sample(number=1, seq=1, codec="plain", payload=b"garbage, not a value"),
           Sample(number=2, seq=2, codec="morse", payload=b"..."),
           Sample(number=3, seq=3, codec="plain", user=b"\x00\x01"),
           Sample(number=4, seq=4, codec="plain", payload=__import__("pickle").dumps(4)),
           Sample(number=2 ** 64 - 1, seq=5, codec="plain", payload=SampleEncoder("plain", sealer).encode(5, 1).payload),
           Sample(number=6, seq=6, codec="plain", time=float("nan"),
                  payload=SampleEncoder("plain", sealer).encode(6, 1).payload),
           Sample(number=7, seq=7, codec="plain", payload=SampleEncoder("plain", sealer).encode("a str", 1).payload)]
    bad += [Sample(number=number, seq=number, codec="plain", payload=bytes(number)) for number in range(8, 13)]
    for sample in bad:
        garbage.publish(sealed(sample, sealer, sample_parts(sample)))
    assert wait_for(lambda: crossing.reader.damaged == 12)
    damage = crossing.reader_app.damage
    assert len(damage) == 10 and all("source.out->sink.sample from host alpha" in what for what in damage)
    assert "unknown codec 'morse'" in damage[1] and "further damaged samples are only counted" in damage[-1]
    assert "write number 18446744073709551615 out of range" in damage[4] and "not a finite number" in damage[5]
    assert "holds a str, which sink.sample does not take" in damage[6]
    assert crossing.reader.written == 0  # the damaged 2^64 - 1 did not become the highest write number
    garbage.publish(SampleEncoder("plain", sealer).encode(13, 13))
    assert wait_for(lambda: crossing.reader.pending == 1)
    assert crossing.sink.sample.read() == (NEW_DATA, 13) and crossing.reader_app.network_refusals.total == 0
    hosts[0].node.destroy_publisher(garbage)


class Bomb:
    """What a pickle-bomb's author sends: unpickled, it runs a command."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[Any, ...]:
        return os.system, (f"touch {self.marker}",)


def test_a_sample_without_the_key_is_refused_counted_and_never_decoded(link, hosts, tmp_path):
    """What any participant of the DDS domain can publish on a connection's topic, refused before
    it is decoded, counted by sender and reason, never damage and never a stop: a pickle-bomb
    claiming to be the writer's host, a sample sealed with another key, one sealed with the key by
    a host the application does not declare and by one that does not write there, a replay of an
    authentic sample, one whose counter was changed; the writer's own samples go on arriving."""
    crossing = link("forged", buffer(20))
    forger = hosts[0].node.create_publisher(Sample, crossing.channel.topic, qos_of(crossing.channel.policy))
    assert wait_for(lambda: forger.get_subscription_count() == 1)
    crossing.source.out.write("first")
    assert wait_for(lambda: crossing.reader.pending == 1)
    marker = tmp_path / "pwned"
    topic = crossing.channel.topic
    bomb = Sample(number=2, seq=2, codec="pickle", sender="alpha", counter=2, wall=time.time(), mac=bytes(32),
                  payload=__import__("pickle").dumps(Bomb(marker)))
    other_key = SampleEncoder("plain", Sealer(AppKey(bytes(32), "another key"), topic, "alpha")).encode("other", 3)
    ghost = SampleEncoder("plain", Sealer(KEY, topic, "ghost")).encode("ghost", 4)
    beta = SampleEncoder("plain", Sealer(KEY, topic, "beta")).encode("beta", 5)
    for forged in (bomb, other_key, ghost, beta):
        forger.publish(forged)
    replayed = SampleEncoder("plain", Sealer(KEY, topic, "alpha")).encode("replayed", 6)
    forger.publish(replayed)  # with the key, from the writer's host: a second launch claims it
    assert wait_for(lambda: crossing.reader_app.network_refusals.total == 5)
    crossing.source.out.write("second")
    assert wait_for(lambda: crossing.reader.pending == 2)
    assert crossing.sink.sample.read_all() == ["first", "second"]
    assert not marker.exists() and crossing.reader_app.damage == [] and not crossing.reader_app.stop_requested
    rows = {(sender, why.split(" (")[0].split(":")[0]): int(count)
            for _, sender, why, count in crossing.reader_app.network_refusals.rows()}
    assert rows == {("'alpha'", "not authenticated"): 2, ("'ghost'", "a host this application does not declare"): 1,
                    ("'beta'", "a host that does not write on this topic"): 1,
                    ("'alpha'", "a second launch claiming this host name"): 1}
    assert crossing.reader.counters() == {"written": 2, "read": 2, "dropped": 0, "pending": 0}
    shot = snapshot(crossing.reader_app)
    assert any(row[1] == "'ghost'" for row in shot.refused)
    hosts[0].node.destroy_publisher(forger)


def test_a_value_that_cannot_be_sent_is_an_error_and_counted_on_both_sides(link):
    crossing = link("unpicklable", buffer(4))
    with pytest.raises(ChannelError, match="a function value cannot be sent to host beta"):
        crossing.source.out.write(lambda: None)
    crossing.source.out.write("next")
    assert wait_for(lambda: crossing.reader.pending == 1)
    assert crossing.sink.sample.read() == (NEW_DATA, "next")
    assert crossing.writer.counters() == {"written": 2, "read": 1, "dropped": 1, "pending": 0}
    assert crossing.reader.counters() == {"written": 2, "read": 1, "dropped": 1, "pending": 0}


def test_a_greedy_filter_between_hosts_is_on_the_readers_side(link):
    """The Greedy filter of a connection between hosts runs where its reader is: the reader gets
    the newest message that reached its host, then OLD_DATA; what it never took is dropped."""
    crossing = link("greedy", DATA, filter=Greedy(DATA))
    for count in range(5):
        crossing.source.out.write(count)
    crossing.writer.writer_done()
    assert wait_for(lambda: crossing.reader.writer_finished)  # after the last value: samples keep their order
    assert crossing.sink.sample.read() == (NEW_DATA, 4)
    assert crossing.sink.sample.read() == (OLD_DATA, 4)
    assert crossing.front.describe() == "Greedy" and crossing.front.label == "source.out -> sink.sample"
    assert crossing.front.counters() == {"written": 5, "read": 1, "dropped": 4, "pending": 0}


def test_a_max_frequency_filter_between_hosts_times_on_the_readers_side(link):
    crossing = link("frequency", buffer(4), filter=MaxFrequency(buffer(4), hz=20))
    front = crossing.front
    status, token = crossing.sink.sample.read()
    taken = time.perf_counter()
    assert status is NEW_DATA and token is None  # the filter's own token, at once
    crossing.source.out.write("later")
    assert wait_for(lambda: front.pending == 1)
    due = front.ready_at()
    assert due is not None and due >= taken + 0.05 - 1e-3
    assert wait_for(lambda: crossing.sink.sample.read() == (NEW_DATA, "later"))
    assert time.perf_counter() >= due
    assert front.counters() == {"written": 2, "read": 2, "dropped": 0, "pending": 0}


def test_a_merge_joins_an_input_from_another_host_and_one_of_its_own(link):
    """One Merge input fed from the network (its filter on the reader's side, in its group), one
    from a writer on the reader's host: one tuple once each has a message, stamped as the first's."""
    group = MergeGroup()
    far, near = Merge(buffer(4), group), Merge(buffer(4), group)
    crossing = link("merge", buffer(4), filter=far)
    right = crossing.reader_app.add(Source("right"))
    crossing.reader_app.connect(right.out, crossing.sink.sample, connection=near)
    crossing.source.out.write("left")
    assert wait_for(lambda: crossing.reader.pending == 1)
    assert crossing.sink.sample.read()[0] is not NEW_DATA  # the right one has nothing yet
    right.out.write("right")
    assert crossing.sink.sample.read() == (NEW_DATA, ("left", "right"))
    stamp = crossing.sink.sample.stamp
    assert (stamp.source, stamp.seq) == ("source.out", 1)


def test_a_split_between_hosts_decides_on_the_writers_host_and_publishes_only_its_readers_messages(link):
    """The writer's end asks the Split before the network: of seven messages, output 1 of 2 gets the
    2nd, 4th and 6th, and only those three are published (the writer's counters); both hosts profile
    the routed-away count (the reader's from the samples: the 7th, routed away after the last sample
    sent, is counted from the writer's last word)."""
    crossing = link("split", buffer(8), filter=Split(buffer(8), 1, 2), router=Split(buffer(8), 1, 2))
    for count in range(7):
        crossing.source.out.write(count)
    crossing.writer.writer_done()
    assert wait_for(lambda: crossing.reader.writer_finished)
    assert (crossing.writer.written, crossing.writer.read) == (3, 3)  # not 6: the others never left alpha
    assert crossing.sink.sample.read_all() == [1, 3, 5]
    [routing] = crossing.writer_app.connections
    assert routing.describe() == "Split(out1 of 2, in turn), routed away 4, BUFFER/LOCKED[8], DDS to host beta"
    assert crossing.front.describe() == "Split(out1 of 2, in turn), routed away 4"  # the samples carry the count
    assert crossing.front.counters() == {"written": 3, "read": 3, "dropped": 0, "pending": 0}


def test_a_stamps_only_connection_sends_no_payload(link):
    crossing = link("dashed", buffer(4), sink=Stamps("sink"), stamps_only=True)
    crossing.source.out.write(np.zeros(1_000_000), stamps={"box": (1, 2)})
    assert wait_for(lambda: crossing.reader.pending == 1)
    status, stamp = crossing.sink.sample.read()
    assert status is NEW_DATA and isinstance(stamp, Stamp) and (stamp.seq, stamp.source) == (1, "source.out")
    sent = crossing.source.out.stamp
    assert stamp.time == pytest.approx(sent.time + 0.5, abs=1e-9) and dict(stamp.user) == {"box": (1, 2)}
    assert crossing.reader.describe() == "BUFFER/LOCKED[4], stamps only, DDS from host alpha"
    assert len(SampleEncoder("stamp", Sealer(KEY, "/t", "alpha")).encode(crossing.source.out.last, 1).payload) == 0


def test_a_pooled_outputs_frames_cross_into_a_pool_of_the_readers(link):
    pooled = ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED, 3)
    crossing = link("frames", pooled, source=Frames("source"))
    out = crossing.source.out
    for value in (1, 2):
        slot = out.acquire((480, 640, 3))
        slot.array[:] = value
        slot.stamp = Stamp(100.0 + value, value, "camera")
        out.write(slot)
    assert isinstance(crossing.reader, DdsFrameReader)
    assert wait_for(lambda: crossing.reader.pool.published == 2)  # both stored in the reader's pool
    status, frame = crossing.sink.sample.read()
    assert status is NEW_DATA and isinstance(frame, Slot) and frame.array.shape == (480, 640, 3)
    assert (frame.array == 2).all() and frame.stamp == Stamp(102.5, 2, "camera")
    assert crossing.sink.sample.stamp.seq == 2
    frame.release()
    assert crossing.sink.sample.read()[0] is not NEW_DATA
    assert crossing.reader.counters() == {"written": 2, "read": 1, "dropped": 1, "pending": 0}


def test_a_pooled_frames_user_stamps_and_own_stamp_cross_between_hosts(link):
    """The frame's user stamps travel in the Sample's own field, its own acquisition stamp in the
    frame: the reader's port.stamp has the user stamps and the acquisition's time (on its clock),
    port.origin is the acquisition stamp, as in the writer's process."""
    pooled = ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED, 3)
    crossing = link("stamped_frames", pooled, source=Frames("source"))
    out = crossing.source.out
    slot = out.acquire((4, 4))
    slot.array[:] = 7
    slot.stamp = Stamp(100.0, 7, "camera").step("exposed", 100.25)
    out.write(slot, stamps={"bbox": (0.0, 0.0, 1.0, 1.0), "part": 3})
    assert wait_for(lambda: crossing.reader.pool.published == 1)
    port = crossing.sink.sample
    status, frame = port.read()
    assert status is NEW_DATA and (frame.array == 7).all()
    stamp, origin = port.stamp, port.origin
    frame.release()
    assert (stamp.seq, stamp.source) == (1, "source.out")
    assert dict(stamp.user) == {"bbox": (0.0, 0.0, 1.0, 1.0), "part": 3}
    assert origin == Stamp(100.5, 7, "camera", (("exposed", 100.75),)), "the acquisition, on the reader's clock"
    assert (stamp.time, stamp.steps) == (origin.time, origin.steps)


def test_a_stamps_only_connection_from_a_pooled_output_sends_the_frames_stamps(link):
    """No frame crosses and none is held: the writer's pool never stalls for this reader."""
    crossing = link("dashed_frames", buffer(8), source=Frames("source"), sink=Stamps("sink"), stamps_only=True)
    out = crossing.source.out
    for number in range(6):
        slot = out.acquire((480, 640, 3))
        slot.array[:] = number
        out.write(slot, stamps={"part": number})
    assert out.pool.stalls == 0 and SlotState.READING not in out.pool.states()
    assert wait_for(lambda: crossing.reader.pending == 6)
    got = crossing.sink.sample.read_all()
    assert all(isinstance(stamp, Stamp) for stamp in got)
    assert [(stamp.seq, stamp.source, dict(stamp.user)) for stamp in got] == [
        (number + 1, "source.out", {"part": number}) for number in range(6)]
    assert crossing.reader.describe() == "BUFFER/LOCKED[8], stamps only, DDS from host alpha"
    assert crossing.reader.counters() == {"written": 6, "read": 6, "dropped": 0, "pending": 0}


def test_a_stamps_only_connection_between_hosts_carries_no_frames(hosts):
    channel = HostChannel("source.out", "sink.sample", "alpha", "beta", "", "", ConnectionPolicy(BufferPolicy.POOL),
                          None, "plain", topic_of("dashed_pool", "source.out", "sink.sample"), True)
    app = Application("dashed_pool")
    app.add(Frames("source"))
    with pytest.raises(ConfigError, match="a stamps-only connection carries the messages' stamps, not frames: .* "
                                          "not POOL"):
        attach_between_hosts(app, hosts[0], [channel], "alpha", KEY, HOSTS)
    assert app.connections == []


def test_a_pooled_output_needs_a_pool_connection(hosts):
    channel = HostChannel("source.out", "sink.sample", "alpha", "beta", "", "", DATA, None, "plain",
                          topic_of("wrong", "source.out", "sink.sample"))
    app = Application("wrong")
    app.add(Frames("source"))
    with pytest.raises(ConfigError, match="a pooled output's frames cross with data=POOL only"):
        attach_between_hosts(app, hosts[0], [channel], "alpha", KEY, HOSTS)
    assert app.connections == []


def test_unsync_cannot_join_two_hosts(hosts):
    unsync = ConnectionPolicy(BufferPolicy.DATA, SyncPolicy.UNSYNC, 1)
    channel = HostChannel("source.out", "sink.sample", "alpha", "beta", "", "", unsync, None, "plain",
                          topic_of("unsync", "source.out", "sink.sample"))
    app = Application("unsync")
    app.add(Source("source"))
    with pytest.raises(ConfigError, match="UNSYNC is only valid inside one activity"):
        attach_between_hosts(app, hosts[0], [channel], "alpha", KEY, HOSTS)


def test_a_bridge_stops_its_thread_within_a_second_and_leaves_the_launchers_ros_alone():
    """The bridge has a context of its own: closing it leaves the ROS launcher's (here a context of
    this test's) running."""
    launcher = Context()
    rclpy.init(context=launcher)
    bridge = HostBridge("coco_test_closing")
    assert bridge.running and any(thread.name == THREAD_NAME for thread in threading.enumerate())
    assert bridge.close(timeout=1.0) and not bridge.running
    assert bridge.close()  # twice: harmless
    assert launcher.ok()
    launcher.try_shutdown()
