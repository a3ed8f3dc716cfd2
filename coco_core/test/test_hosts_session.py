"""The launch of one application over several hosts: barriers, clock, operations, stops, a lost host.

Two hosts' parts run in this process, each with its own :class:`HostSession`, joined by a network
in memory (a delivery thread per host, like a DDS subscription's): what is checked is the session's
logic. The same sessions over real DDS between network namespaces are tested in the workspace's
``test/test_hosts_netns.py``.
"""

from __future__ import annotations

import queue
import threading
import time
from concurrent.futures import Future
from pathlib import Path
from typing import Any, Callable, Iterator

import pytest

from coco_core.application import Application
from coco_core.builder import build_application
from coco_core.errors import HostError, RemoteError
from coco_core.hosts.clock import ClockOffset, best, exchange
from coco_core.deployment import plan_deployment
from coco_core.hosts.session import HostSession
from coco_core.messages import Call, Message, Outcome
from coco_core.processes.messages import Stop
from coco_core.wire import Decoder, Encoder
from coco_core.xml import load_application

APP = """<package name="pair" on_error="{on_error}">
  <components>
    <component><name>generator</name><task>SignalGenerator</task></component>
    <component><name>filter</name><task>MovingAverage</task>
      <attributes><attribute name="window" value="8"/></attributes></component>
    <component><name>frames</name><task>TransformationInterface</task></component>
  </components>
  <transforms>
    <static parent="world" child="camera" xyz="0.1 -0.2 1.2" rpy="0 0 0"/>
  </transforms>
  <activities>
    <host name="robot">
      <activity name="acquisition"><schedule type="periodic" period="20"/>
        <components><component name="generator"/></components></activity>
    </host>
    <host name="graphics">
      <activity name="filtering"><schedule type="periodic" period="20"/>
        <components><component name="filter"/></components></activity>
    </host>
  </activities>
</package>
"""


class Network:
    """Hosts' messages in memory: each host's are delivered by a thread of its own, in order."""

    def __init__(self) -> None:
        self.inboxes: dict[str, queue.Queue[tuple[str, Message] | None]] = {}
        self.cut: set[str] = set()
        """Hosts whose messages no longer go anywhere (unplugged)."""
        self.threads: list[threading.Thread] = []

    def endpoint(self, host: str, receive: Callable[[str, Message], None]) -> Endpoint:
        inbox: queue.Queue[tuple[str, Message] | None] = queue.Queue()
        self.inboxes[host] = inbox

        def deliver() -> None:
            while (item := inbox.get()) is not None:
                receive(*item)

        thread = threading.Thread(target=deliver, daemon=True)
        thread.start()
        self.threads.append(thread)
        return Endpoint(self, host)

    def close(self) -> None:
        for inbox in self.inboxes.values():
            inbox.put(None)


class Endpoint:
    def __init__(self, network: Network, host: str) -> None:
        self.network, self.host = network, host

    def send(self, recipient: str, message: Message) -> None:
        """As the DDS bus does, in the typed encoding between hosts: a message or a value in it
        that cannot cross raises here, in the sender's thread."""
        message = Decoder().decode(Encoder().encode(message))
        if self.host in self.network.cut:
            return
        for name, inbox in self.network.inboxes.items():
            if name != self.host and recipient in ("", name):
                inbox.put((self.host, message))

    def close(self) -> None:
        pass


class Hosts:
    """Both hosts' parts built, each with its session."""

    def __init__(self, tmp_path: Path, on_error: str = "continue", lost_after: float = 3.0) -> None:
        path = tmp_path / "pair.xml"
        path.write_text(APP.format(on_error=on_error))
        spec = load_application(str(path))
        self.network = Network()
        self.apps: dict[str, Application] = {}
        self.sessions: dict[str, HostSession] = {}
        for name in ("robot", "graphics"):
            part = plan_deployment(spec, host=name).host(name).spec
            app = self.apps[name] = build_application(part)
            session = self.sessions[name] = HostSession(part, app, timeout=20, lost_after=lost_after)
            app.router = session

    def each(self, step: Callable[[str, HostSession], Any]) -> None:
        """Run ``step`` for both hosts at once (each waits for the other), and wait for both."""
        errors: list[BaseException] = []

        def run(name: str) -> None:
            try:
                step(name, self.sessions[name])
            except BaseException as error:  # reported by the test
                errors.append(error)

        threads = [threading.Thread(target=run, args=(name,)) for name in self.sessions]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(30)
        if errors:
            raise errors[0]

    def start(self) -> None:
        self.each(lambda name, session: session.join(self.network.endpoint(name, session.receive)))
        self.each(lambda name, session: session.built(None))
        for app in self.apps.values():
            app.start()
        for app in self.apps.values():
            assert wait_until(lambda app=app: app.gate.is_open), "the hosts never started"

    def close(self) -> None:
        for app in self.apps.values():
            app.request_stop("test ends", hard=True)
            app.stop()
        for session in self.sessions.values():
            session.close()
        self.network.close()


def wait_until(condition: Callable[[], bool], timeout: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return condition()


@pytest.fixture
def hosts(tmp_path: Path) -> Iterator[Hosts]:
    made = Hosts(tmp_path)
    yield made
    made.close()


def test_one_exchange_gives_the_offset_and_the_shortest_round_trip_wins() -> None:
    # The first host's clock is 5 s ahead; out 10 ms, 1 ms there, back 30 ms.
    offset, round_trip = exchange(100.0, 105.010, 105.011, 100.041)
    assert offset == pytest.approx(5.0 - 0.010, abs=1e-9) and round_trip == pytest.approx(0.040)
    chosen = best([(4.99, 0.040), (5.0005, 0.002), (5.02, 0.100)])
    assert (chosen.offset, chosen.uncertainty, chosen.exchanges) == (5.0005, 0.001, 3)
    assert ClockOffset(2.0).to_app(1.0) == 3.0 and ClockOffset(2.0).from_app(3.0) == 1.0


def test_hosts_wait_for_each_other_then_share_one_clock(hosts: Hosts) -> None:
    hosts.start()
    robot, graphics = hosts.sessions["robot"], hosts.sessions["graphics"]
    assert robot.clock.exchanges == 0  # the first host's clock is the application's
    assert graphics.clock.exchanges == 8
    # One machine, one clock: the measured offset is 0 within what the exchanges can tell.
    assert abs(graphics.clock.offset) <= graphics.clock.uncertainty + 1e-4


def test_an_operation_of_another_host_is_called_by_name(hosts: Hosts) -> None:
    hosts.start()
    set_window = hosts.apps["robot"].operation("filter", "set_window")
    future: Future[Any] = set_window(3)
    assert future.result(10) == 8  # the previous window, from the component on the other host
    assert hosts.apps["graphics"].component("filter").window == 3
    with pytest.raises(RemoteError, match="no_such"):
        hosts.apps["robot"].operation("filter", "no_such")().result(10)


def test_a_call_or_a_result_that_cannot_cross_is_answered_with_why(hosts: Hosts) -> None:
    """An argument or a result that the typed encoding between hosts cannot carry fails the call
    with the reason, instead of leaving its caller waiting for an answer that never comes."""
    hosts.start()
    with pytest.raises(RemoteError, match="the call cannot be sent to host graphics: a builtins.object cannot cross"):
        hosts.apps["robot"].operation("filter", "set_window")(object()).result(10)
    answers: list[Outcome] = []
    robot, graphics = hosts.sessions["robot"], hosts.sessions["graphics"]
    robot._waiting[999] = ("graphics", answers.append)  # a call robot made, and graphics' answer to it
    graphics._answer("robot", Call(id=999), Outcome(True, object()))
    assert wait_until(lambda: bool(answers))
    assert not answers[0].ok and "the result cannot be sent to host robot" in answers[0].message


def test_a_host_without_the_transformation_interface_looks_up_through_its_operation(hosts: Hosts) -> None:
    """The graph is whole on the first host (whose TransformationInterface no activity runs); another
    host asks it by name, as a child process does."""
    hosts.start()
    assert "frames" not in hosts.apps["graphics"].components
    pose = hosts.apps["graphics"].operation("frames", "lookup")("world", "camera").result(10)
    assert pose[:3, 3].tolist() == pytest.approx([0.1, -0.2, 1.2])


def test_a_stop_on_one_host_stops_the_others_with_its_reason(hosts: Hosts) -> None:
    hosts.start()
    hosts.apps["robot"].request_stop("duration elapsed", hard=False)
    graphics = hosts.apps["graphics"]
    assert wait_until(lambda: graphics.stop_requested)
    assert graphics.stop_reason == "host robot: duration elapsed" and not graphics.stop_is_hard
    assert not hosts.sessions["graphics"].failure


def test_damage_found_on_one_host_reaches_the_others(hosts: Hosts) -> None:
    """As between processes: every host's summary reports it, and every host exits with status 1."""
    hosts.start()
    hosts.apps["graphics"].report_damage("bag truncated at 12 s")
    assert wait_until(lambda: hosts.apps["robot"].damage == ["bag truncated at 12 s"])
    assert hosts.apps["graphics"].damage == ["bag truncated at 12 s"]  # once: not sent back


def test_a_host_that_does_not_come_is_named(tmp_path: Path) -> None:
    alone = Hosts(tmp_path)
    session = alone.sessions["graphics"]
    session.timeout = 0.5
    try:
        with pytest.raises(HostError, match=r"host robot \(not seen\) did not come within 0.5 s to start"):
            session.join(alone.network.endpoint("graphics", session.receive))
    finally:
        alone.close()


@pytest.mark.parametrize("on_error", ["stop_app", "continue"])
def test_a_host_that_disappears_is_reported_and_on_error_decides(tmp_path: Path, on_error: str,
                                                                  caplog: pytest.LogCaptureFixture) -> None:
    made = Hosts(tmp_path, on_error=on_error, lost_after=0.6)
    try:
        made.start()
        made.network.cut.add("robot")  # unplugged: not a word more from it
        graphics, session = made.apps["graphics"], made.sessions["graphics"]
        assert wait_until(lambda: "host robot disappeared (no heartbeat for" in caplog.text)
        assert session.peers["robot"].lost
        if on_error == "stop_app":
            assert wait_until(lambda: graphics.stop_requested)
            assert graphics.stop_reason.startswith("host robot disappeared") and session.failure
        else:
            assert wait_until(lambda: "going on without host robot" in caplog.text)
            assert not graphics.stop_requested and not session.failure
            call = made.apps["graphics"].operation("generator", "set_attribute")("frequency", 2.0)
            with pytest.raises(RemoteError, match="unreachable|disappeared"):
                call.result(5)
    finally:
        made.close()


def test_a_message_the_hosts_do_not_send_each_other_is_counted_and_logged(tmp_path: Path,
                                                                          caplog: pytest.LogCaptureFixture) -> None:
    """The link between hosts has one dispatcher: an unknown message type is never dropped silently."""
    path = tmp_path / "pair.xml"
    path.write_text(APP.format(on_error="continue"))
    part = plan_deployment(load_application(str(path)), host="robot").host("robot").spec
    session = HostSession(part, build_application(part))
    session.receive("graphics", Stop("a child's word, not a host's"))
    assert session.unexpected == 1
    assert "unexpected Stop from host graphics" in caplog.text
