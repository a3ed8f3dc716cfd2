"""An activity's beginit/endit ports and the filters on connections (PreSignal, MaxFrequency,
Greedy), from Python and from the XML, with the errors a wrong file gets."""

from __future__ import annotations

import time

import pytest

from coco_core import (
    BufferPolicy,
    Component,
    ConnectionPolicy,
    InputPort,
    OutputPort,
    PeriodicActivity,
    SyncPolicy,
    TriggeredActivity,
)
from coco_core.builder import build_application
from coco_core.connections import EMPTY
from coco_core.errors import ConfigErrors
from coco_core.filters import Greedy, MaxFrequency, Merge, MergeGroup, PreSignal
from coco_core.iteration import port_of
from coco_core.policy import NEW_DATA, NO_DATA, OLD_DATA
from coco_core.stamps import Message
from coco_core.wakeup import Wakeup
from coco_core.xml import parse_application_string

BUFFERED = ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 100)


class Ticker(Component):
    """Writes its update count."""

    out = OutputPort(int)

    def init(self) -> None:
        self.updates = 0

    def on_update(self) -> None:
        self.out.write(self.updates)
        self.updates += 1


class Sink(Component):
    sample = InputPort(int)


def message(number: int) -> Message:
    return Message(number, time.perf_counter(), number, "test.out", number)


# --- beginit / endit ------------------------------------------------------------------------------

def test_a_triggered_activity_with_a_connected_beginit_cycles_once_per_message(make_app, wait_until):
    app = make_app()
    ticker, source = app.add(Ticker("ticker")), app.add(Ticker("source"))
    loop = app.add_activity(TriggeredActivity("loop", [ticker]))
    begin = app.connect(source.out, port_of(loop, "beginit"), BUFFERED)
    app.start()
    for count in (1, 2, 3):
        source.out.write(count)
        assert wait_until(lambda: ticker.updates == count)
    assert begin.pending == 0 and loop.stats.cycles == 3
    assert loop.iteration is not None and loop.iteration.begun is not None
    assert loop.iteration.begun.source == "source.out"


def test_a_periodic_activity_skips_the_ticks_without_a_begin_message(make_app, wait_until):
    app = make_app()
    ticker, source = app.add(Ticker("ticker")), app.add(Ticker("source"))
    clock = app.add_activity(PeriodicActivity("clock", 0.002, [ticker]))
    app.connect(source.out, port_of(clock, "beginit"), BUFFERED)
    app.start()
    source.out.write(0)
    source.out.write(1)
    assert wait_until(lambda: ticker.updates == 2)
    time_at_two = time.monotonic()
    assert wait_until(lambda: time.monotonic() - time_at_two > 0.05)  # 25 ticks later: still 2
    assert ticker.updates == 2 and clock.stats.cycles == 2


def test_endit_says_each_cycle_with_its_number(make_app, wait_until):
    app = make_app()
    ticker, sink = app.add(Ticker("ticker")), app.add(Sink("sink"))
    clock = app.add_activity(PeriodicActivity("clock", 0.002, [ticker]))
    end = app.connect(port_of(clock, "endit"), sink.sample, BUFFERED)
    app.start()
    assert wait_until(lambda: end.pending >= 5)
    app.stop()
    ends = []
    while (status := sink.sample.read())[0] is NEW_DATA:
        stamp = sink.sample.stamp
        assert stamp is not None and stamp.source == "clock.endit" and stamp.it == status[1]
        ends.append(status[1])
    assert ends == list(range(len(ends))) and len(ends) == clock.stats.cycles


def test_an_activity_has_only_beginit_and_endit(make_app):
    app = make_app()
    loop = app.add_activity(TriggeredActivity("loop"))
    with pytest.raises(Exception, match="activity loop has no port 'begin'; an activity's ports are beginit and endit"):
        port_of(loop, "begin")


# --- filters --------------------------------------------------------------------------------------

def test_presignal_starts_with_its_tokens_then_forwards_in_order():
    presignal = PreSignal(ConnectionPolicy(size=4), tokens=2)
    assert presignal.pending == 2 and presignal.written == 2 and presignal.dropped == 0
    tokens = [presignal.pop(), presignal.pop()]
    assert all(token.value is None and token.stamp.seq == number for number, token in zip((1, 2), tokens))
    presignal.push(message(7))
    presignal.push(message(8))
    assert [presignal.pop().value, presignal.pop().value, presignal.pop()] == [7, 8, EMPTY]
    assert presignal.counters() == {"written": 4, "read": 4, "dropped": 0, "pending": 0}
    with pytest.raises(Exception, match="buffer of at least 3"):
        PreSignal(ConnectionPolicy(size=2), tokens=3)


def test_max_frequency_releases_no_closer_than_its_interval():
    limiter = MaxFrequency(ConnectionPolicy(size=4), hz=20.0)
    assert limiter.ready_at() == 0.0  # its first token: at once
    asked = time.perf_counter()
    first = limiter.pop()
    assert first is not EMPTY and first.value is None
    limiter.push(message(1))
    due = limiter.ready_at()
    assert due is not None and due >= asked + 0.05  # taken after it was asked for
    refused = 0
    while (second := limiter.pop()) is EMPTY:  # not yet, however often it is asked
        refused += 1
    assert second.value == 1 and time.perf_counter() >= due, "released before its time"
    assert refused, "asked right after the write, 50 ms early, it said not yet"
    assert limiter.ready_at() is None and limiter.dropped == 0


def test_greedy_gives_the_newest_and_then_says_reuse(make_app):
    app = make_app()
    ticker, sink = app.add(Ticker("ticker")), app.add(Sink("sink"))
    greedy = app.connect(ticker.out, sink.sample, connection=Greedy(ConnectionPolicy()))
    assert sink.sample.read() == (NO_DATA, None) and greedy.reused == 0
    for value in range(5):
        ticker.out.write(value)
    assert sink.sample.read() == (NEW_DATA, 4)
    assert sink.sample.read() == (OLD_DATA, 4) and greedy.reused == 1
    ticker.out.write(5)
    assert sink.sample.read_newest() == (NEW_DATA, 5) and greedy.reused == 1
    assert greedy.counters() == {"written": 6, "read": 2, "dropped": 4, "pending": 0}


# --- the XML --------------------------------------------------------------------------------------

APP = """<package name="coupled">
    <components>
        <component><name>producer</name><task>CostlyProducer</task></component>
        <component><name>consumer</name><task>CostlyConsumer</task></component>
    </components>
    <connections>
        <connection>
            <src task="producer" port="out"/>
            <dest task="consumer" port="item"/>
            {data_filter}
        </connection>
        <connection {attributes}>
            <src {src}/>
            <dest {dest}/>
            {filter}
        </connection>
    </connections>
    <activities>
        <activity name="produce"><schedule type="triggered"/><components><component name="producer"/></components></activity>
        <activity name="consume"><schedule type="triggered"/><components><component name="consumer"/></components></activity>
    </activities>
</package>"""


def parse(data_filter: str = "", attributes: str = "", src: str = 'activity="consume" port="endit"',
          dest: str = 'activity="produce" port="beginit"', filter: str = '<filter type="PreSignal"/>'):
    return parse_application_string(APP.format(data_filter=data_filter, attributes=attributes, src=src, dest=dest,
                                               filter=filter), filename="app.xml")


def errors_of(**parts) -> list[str]:
    with pytest.raises(ConfigErrors) as raised:
        parse(**parts)
    return [str(error) for error in raised.value.errors]


def test_the_xml_puts_filters_on_connections_and_names_activity_ports():
    spec = parse(data_filter='<filter type="Greedy"/>', attributes='buffersize="2"',
                 filter='<filter type="PreSignal" tokens="2"/>')
    data, loop = spec.connections
    assert data.filter is not None and data.filter.type == "Greedy"
    assert loop.src.activity and (loop.src.component, loop.src.port) == ("consume", "endit")
    assert loop.dest.activity and str(loop.dest) == "produce.beginit"
    assert loop.filter is not None and (loop.filter.type, loop.filter.tokens) == ("PreSignal", 2)
    app = build_application(spec)
    greedy, presignal = app.connections
    assert isinstance(greedy, Greedy) and isinstance(presignal, PreSignal) and presignal.pending == 2
    assert greedy.trigger is None  # a greedy reader runs at its own rate: values do not wake it
    assert presignal.sink is app.activity("produce").iteration.beginit  # type: ignore[union-attr]


def test_wrong_coupling_xml_is_reported_with_its_line_and_what_was_expected():
    assert errors_of(src='activity="consumer" port="endit"') == [
        "app.xml:13: <src activity=\"consumer\"> is not a defined activity; did you mean 'consume'? valid: consume, produce"]
    [wrong_port] = errors_of(dest='activity="produce" port="endit"')
    assert wrong_port.startswith("app.xml:14:") and "an activity's ports are beginit and endit" in wrong_port
    [both] = errors_of(src='task="producer" activity="consume" port="endit"')
    assert "needs either task= (a component) or activity=" in both
    [unknown] = errors_of(filter='<filter type="Greddy"/>')
    assert unknown.startswith("app.xml:15:") and "expected one of: PreSignal, MaxFrequency, Greedy, Merge" in unknown
    [tokens] = errors_of(filter='<filter type="PreSignal" tokens="3"/>')
    assert "needs buffersize >= 3" in tokens
    [hz] = errors_of(filter='<filter type="MaxFrequency" hz="0"/>')
    assert 'hz="0": expected a frequency in Hz > 0' in hz
    [data] = errors_of(attributes='data="BUFFER" buffersize="4"')
    assert 'leave out data="BUFFER"' in data


def test_an_activity_port_connection_between_processes_has_its_filter_on_the_readers_side():
    """Before: refused ('works inside one process in this version'). Now the reader's process (the
    launcher's here, which runs produce) holds the PreSignal, to be fed from the channel; the
    writer's process (worker, which runs consume) has no filter of it."""
    text = APP.format(data_filter="", attributes="", src='activity="consume" port="endit"',
                      dest='activity="produce" port="beginit"', filter='<filter type="PreSignal"/>')
    text = text.replace('<activity name="consume">', '<process name="worker"><activity name="consume">').replace(
        '<component name="consumer"/></components></activity>',
        '<component name="consumer"/></components></activity></process>')
    spec = parse_application_string(text, filename="app.xml")
    reader, writer = build_application(spec), build_application(spec, "worker")
    [(label, made)] = reader.incoming_filters.items()
    assert label == "consume.endit->produce.beginit" and isinstance(made, PreSignal) and made.pending == 1
    assert writer.incoming_filters == {}


def test_a_max_frequency_from_another_process_times_the_messages_on_the_readers_side():
    """consume.endit in another process -> MaxFrequency -> produce.beginit here: the filter is on
    this side, fed from the ring when asked; its first token at once, the next message from the ring
    no earlier than 1/hz after the token was taken (the gated activity's clock), and the counters of
    one connection (the token + what the writer offered)."""
    from coco_core.deployment import plan_deployment
    from coco_core.processes.channels import attach, plan_channels
    from coco_core.processes.filtered import FedFilter
    from coco_core.shm import Arena, ShmWriter

    text = APP.format(data_filter="", attributes='buffersize="4"', src='activity="consume" port="endit"',
                      dest='activity="produce" port="beginit"', filter='<filter type="MaxFrequency" hz="20"/>')
    text = text.replace('<activity name="consume">', '<process name="worker"><activity name="consume">').replace(
        '<component name="consumer"/></components></activity>',
        '<component name="consumer"/></components></activity></process>')
    spec = parse_application_string(text, filename="app.xml")
    app = build_application(spec)
    arena = Arena(f"maxfreq{time.monotonic_ns()}")
    try:
        plans = plan_channels(arena, plan_deployment(spec).host())
        [loop] = [plan for plan in plans if plan.dest_activity]
        assert (loop.src_process, loop.dest_process, loop.wakes) == ("worker", "", "produce")
        consume = Wakeup.new()  # what the launcher makes for the reader of producer.out, in worker
        attach(app, plans, {"consume": consume})
        [limiter] = port_of(app.activity("produce"), "beginit").connections
        assert isinstance(limiter, FedFilter) and limiter.describe() == "MaxFrequency(hz=20)"
        assert limiter.ready_at() == 0.0 and limiter.pop() is not EMPTY  # the token
        taken = time.perf_counter()
        ShmWriter(loop.channel).push(Message(0, time.perf_counter(), 1, "consume.endit", 0))
        assert limiter.pending == 1
        due = limiter.ready_at()
        assert due is not None and due >= taken + 0.05 - 1e-3
        while (item := limiter.pop()) is EMPTY:
            assert time.perf_counter() < due + 1.0
        assert time.perf_counter() >= due and item.stamp.source == "consume.endit"
        assert limiter.counters() == {"written": 2, "read": 2, "dropped": 0, "pending": 0}
        consume.close()
    finally:
        arena.close()


def test_a_merge_joins_inputs_from_another_process_and_from_its_own(tmp_path):
    """One Merge input from another process (its ring fed into the Merge filter on the reader's
    side, in its file place), one from the reader's own: one tuple once each has a message, stamped
    as the first's message, which crossed with its stamp."""
    from coco_core.deployment import plan_deployment
    from coco_core.processes.channels import attach, plan_channels
    from coco_core.processes.filtered import FedFilter
    from coco_core.shm import Arena, ShmWriter

    text = MERGE.format(sink="relay", task="Relay", port="input").replace(
        "</connections>", '</connections><activities><process name="far"><activity name="lefty">'
                          '<schedule type="triggered"/><components><component name="left"/></components>'
                          '</activity></process></activities>')
    spec = parse_application_string(text, filename="app.xml")
    app = build_application(spec)
    arena = Arena(f"merge{time.monotonic_ns()}")
    try:
        plans = plan_channels(arena, plan_deployment(spec).host())
        attach(app, plans, {})
        relay = app.component("relay")
        near, far = relay.input.connections  # type: ignore[attr-defined]  # the channel is attached after the build
        assert isinstance(far, FedFilter) and isinstance(far.filter, Merge) and far.filter.index == 0
        assert isinstance(near, Merge) and near.index == 1 and near.group is far.filter.group
        ShmWriter(plans[0].channel).push(Message(1, 12.5, 1, "left.out", 4))
        assert relay.input.read() == (NO_DATA, None)  # the right one has nothing yet
        app.component("right").out.write(10)  # type: ignore[attr-defined]
        assert relay.input.read() == (NEW_DATA, (1, 10))
        stamp = relay.input.stamp  # type: ignore[attr-defined]
        assert stamp is not None and (stamp.source, stamp.seq, stamp.it, stamp.time) == ("left.out", 1, 4, 12.5)
        assert far.counters() == {"written": 1, "read": 1, "dropped": 0, "pending": 0}
        assert far.describe() == "Merge(in0 of 2)" and far.label == "left.out -> relay.input"
    finally:
        arena.close()


# --- Merge ----------------------------------------------------------------------------------------

class Taker(Component):
    sample = InputPort(object)


def test_merge_gives_one_tuple_once_each_connection_has_a_message_stamped_as_the_first(make_app):
    app = make_app()
    first, second, taker = app.add(Ticker("first")), app.add(Ticker("second")), app.add(Taker("taker"))
    group = MergeGroup()
    into_first = app.connect(first.out, taker.sample, connection=Merge(ConnectionPolicy(size=4), group))
    into_second = app.connect(second.out, taker.sample, connection=Merge(ConnectionPolicy(size=4), group))
    first.out.write(1)
    first.out.write(2)
    assert taker.sample.read() == (NO_DATA, None)  # the second has nothing yet
    second.out.write(10)
    assert taker.sample.read() == (NEW_DATA, (1, 10))
    stamp = taker.sample.stamp
    assert stamp is not None and (stamp.source, stamp.seq) == ("first.out", 1)
    assert taker.sample.read() == (OLD_DATA, (1, 10))
    second.out.write(20)
    first.out.write(3)
    second.out.write(30)
    assert taker.sample.read_newest() == (NEW_DATA, (3, 30))  # (2, 20) skipped: dropped on both
    assert into_first.counters() == {"written": 3, "read": 2, "dropped": 1, "pending": 0}
    assert into_second.counters() == {"written": 3, "read": 2, "dropped": 1, "pending": 0}
    assert into_first.describe() == "Merge(in0 of 2)" and into_second.describe() == "Merge(in1 of 2)"


MERGE = """<package name="merged">
    <components>
        <component><name>left</name><task>CostlyProducer</task></component>
        <component><name>right</name><task>CostlyProducer</task></component>
        <component><name>{sink}</name><task>{task}</task></component>
    </components>
    <connections>
        <connection buffersize="3"><src task="left" port="out"/><dest task="{sink}" port="{port}"/><filter type="Merge"/></connection>
        <connection buffersize="3"><src task="right" port="out"/><dest task="{sink}" port="{port}"/><filter type="Merge"/></connection>
    </connections>
</package>"""


def test_the_xml_merges_the_connections_into_one_port_in_file_order():
    app = build_application(parse_application_string(MERGE.format(sink="relay", task="Relay", port="input"),
                                                      filename="app.xml"))
    left, right = app.connections
    assert isinstance(left, Merge) and isinstance(right, Merge) and left.group is right.group
    assert (left.index, right.index) == (0, 1) and left.source.qualified_name == "left.out"  # type: ignore[union-attr]


def test_a_merge_into_a_port_that_does_not_take_tuples_is_an_error():
    with pytest.raises(ConfigErrors) as raised:
        build_application(parse_application_string(MERGE.format(sink="consumer", task="CostlyConsumer",
                                                                 port="item"), filename="app.xml"))
    [first, *_] = [str(error) for error in raised.value.errors]
    assert first.startswith("app.xml:8:") and "a Merge gives consumer.item a tuple" in first
    assert "merge into a port of type tuple or object" in first


def test_a_merge_into_a_beginit_is_an_error_since_beginit_waits_for_each_connection_already():
    text = MERGE.format(sink="relay", task="Relay", port="input").replace(
        '<dest task="relay" port="input"/>', '<dest activity="loop" port="beginit"/>').replace(
        "</connections>", "</connections><activities><activity name=\"loop\"><schedule type=\"triggered\"/>"
                          "<components><component name=\"relay\"/></components></activity></activities>")
    with pytest.raises(ConfigErrors) as raised:
        build_application(parse_application_string(text, filename="app.xml"))
    assert "loop.beginit waits for a message on each of its connections already" in str(raised.value)


def test_a_pooled_output_cannot_pass_through_a_filter(make_app):
    from coco_core import PooledOutputPort, WiringError

    class Camera(Component):
        frames = PooledOutputPort(4)

    app = make_app()
    camera, taker = app.add(Camera("camera")), app.add(Taker("taker"))
    with pytest.raises(WiringError, match="camera.frames is a pooled output: .* cannot pass through a Greedy filter"):
        app.connect(camera.frames, taker.sample, connection=Greedy(ConnectionPolicy()))
    assert app.connections == []


def test_a_pooled_output_between_processes_cannot_pass_through_a_filter_either(monkeypatch):
    """Refused at planning with file:line, as in one process (before: refused as any filter between
    processes)."""
    from pathlib import Path

    from coco_core.errors import ConfigError
    from coco_core.deployment import plan_deployment
    from coco_core.processes.channels import plan_channels
    from coco_core.shm import Arena

    monkeypatch.syspath_prepend(str(Path(__file__).parent / "data"))
    text = """<package name="frames">
    <components>
        <component><name>camera</name><task>channel_components:FrameSource</task></component>
        <component><name>viewer</name><task>channel_components:Reader</task></component>
    </components>
    <connections>
        <connection><src task="camera" port="frames"/><dest task="viewer" port="value"/>
            <filter type="Greedy"/></connection>
    </connections>
    <activities>
        <process name="far"><activity name="shoot"><schedule type="periodic" period="10"/>
            <components><component name="camera"/></components></activity></process>
        <activity name="view"><schedule type="periodic" period="10"/>
            <components><component name="viewer"/></components></activity>
    </activities>
</package>"""
    spec = parse_application_string(text, filename="app.xml")
    arena = Arena(f"poolfilter{time.monotonic_ns()}")
    try:
        with pytest.raises(ConfigError, match="camera.frames is a pooled output: .* cannot pass through a Greedy") \
                as raised:
            plan_channels(arena, plan_deployment(spec).host())
        assert str(raised.value).startswith("app.xml:7:"), str(raised.value)  # the <connection>
    finally:
        arena.close()
