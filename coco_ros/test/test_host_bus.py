"""The launch's messages between hosts (coco_ros.hosts.bus) over real DDS: two hosts' buses, each on
a HostBridge of its own (two DDS participants, as two hosts have). A host's stop must reach the
others: its heartbeats are best effort, so the one that says it stops goes on the reliable topic as
well (where the host's close waits for it to be acknowledged). Domain 202, localhost only."""

from __future__ import annotations

import threading
import time
from typing import Callable, Iterator

import pytest

from coco_core.hosts.auth import Refusals
from coco_core.hosts.key import AppKey
from coco_core.hosts.messages import Heartbeat, Stage
from coco_core.messages import Message
from coco_core.wire import Decoder
from coco_interfaces.msg import HostMessage
from coco_ros.hosts.bridge import HostBridge
from coco_ros.hosts.bus import QOS, DdsBus, bus_topic

DOMAIN = "202"  # its own: no other test uses it
KEY = AppKey(bytes(range(32)), "the tests' key")
APP, HOSTS = "bus_test", ["alpha", "beta"]


def wait_for(predicate: Callable[[], object], timeout: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return bool(predicate())
        time.sleep(0.005)
    return True


@pytest.fixture(autouse=True)
def dds_domain(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", DOMAIN)  # read by rclpy.init
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


class Heard:
    """What one host's bus received, by sender."""

    def __init__(self) -> None:
        self.messages: list[tuple[str, Message]] = []
        self._lock = threading.Lock()

    def __call__(self, sender: str, message: Message) -> None:
        with self._lock:
            self.messages.append((sender, message))

    def stops(self) -> int:
        with self._lock:
            return sum(isinstance(m, Heartbeat) and m.stage is Stage.STOPPING for _, m in self.messages)


@pytest.fixture
def buses() -> Iterator[tuple[DdsBus, DdsBus, Heard, HostBridge]]:
    """Host alpha's bus, host beta's, what beta heard, and alpha's bridge."""
    alpha, beta = HostBridge("coco_test_bus_alpha"), HostBridge("coco_test_bus_beta")
    heard = Heard()
    released: list[str] = []
    sending = DdsBus(alpha, APP, "alpha", HOSTS, lambda sender, message: None, lambda: released.append("alpha"), KEY,
                     Refusals())
    receiving = DdsBus(beta, APP, "beta", HOSTS, heard, lambda: released.append("beta"), KEY, Refusals())
    try:
        # Each bus listens to its own topics too: two readers of each, alpha's own and beta's.
        assert wait_for(lambda: sending.publisher.get_subscription_count() >= 2
                        and sending.beats.get_subscription_count() >= 2), "the buses never matched"
        yield sending, receiving, heard, alpha
    finally:
        for bus in (sending, receiving):
            if bus.host not in released:
                bus.close()
        alpha.close()
        beta.close()


def test_a_stop_goes_on_the_reliable_topic_as_well(buses: tuple[DdsBus, DdsBus, Heard, HostBridge]) -> None:
    sending, _, heard, alpha = buses
    on_reliable: list[Message] = []
    decoder = Decoder()
    alpha.subscribe(HostMessage, bus_topic(APP), lambda out: on_reliable.append(decoder.decode(out.body)), QOS)
    assert wait_for(lambda: sending.publisher.get_subscription_count() >= 3)
    sending.send("", Heartbeat(Stage.RUNNING))
    sending.send("", Heartbeat(Stage.STOPPING, "test: stop", hard=True))
    assert wait_for(lambda: any(isinstance(m, Heartbeat) and m.stage is Stage.STOPPING for m in on_reliable)), \
        "the stop was not on the reliable topic"
    assert all(isinstance(m, Heartbeat) and m.stage is Stage.STOPPING for m in on_reliable), \
        "only the stop goes there, not every heartbeat"
    # The best-effort beats may be lost (here often both, sent right after the buses matched): the
    # other host hears the stop anyway, from the reliable topic.
    assert wait_for(lambda: heard.stops() >= 1), f"the other host did not hear the stop: {heard.messages}"

