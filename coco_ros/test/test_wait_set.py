"""ActivityWaitSet (coco_ros.wait_set): the entities of one callback group waited on by a thread of its
own, over real DDS and rcl wait sets, beside the node's executor that must leave them alone."""

from __future__ import annotations

import threading
import time

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import Float64
from std_srvs.srv import SetBool

from coco_ros.hosting import ExecutorThread
from coco_ros.wait_set import ActivityWaitSet, WaitSetGroup
from test_launcher_hosting import wait_until


class Rig:
    """A context, a node spun by its own executor, and the wait sets a test starts."""

    def __init__(self) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node("coco_test_wait_set", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.spinner = ExecutorThread(self.executor).start()
        self.errors: list[str] = []
        self.wait_sets: list[ActivityWaitSet] = []

    def wait_set(self, name: str, group: WaitSetGroup | None = None) -> tuple[WaitSetGroup, ActivityWaitSet]:
        group = group or WaitSetGroup()
        server = ActivityWaitSet(group, self.context, name, on_error=self.errors.append)
        self.wait_sets.append(server)
        return group, server

    def close(self) -> None:
        for server in self.wait_sets:
            server.stop()
        self.spinner.stop()
        self.node.destroy_node()
        self.context.try_shutdown()
        self.context.destroy()


@pytest.fixture
def rig(monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "83")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rig = Rig()
    yield rig
    rig.close()


def test_the_group_s_subscription_runs_in_its_wait_set_and_never_in_the_node_s_executor(rig: Rig) -> None:
    group, server = rig.wait_set("sub")
    received: list[tuple[float, str]] = []
    rig.node.create_subscription(Float64, "/coco_wait_set/value",
                                 lambda msg: received.append((msg.data, threading.current_thread().name)), 10,
                                 callback_group=group)
    publisher = rig.node.create_publisher(Float64, "/coco_wait_set/value", 10)
    assert wait_until(lambda: publisher.get_subscription_count() == 1)
    publisher.publish(Float64(data=1.0))
    time.sleep(0.3)
    assert received == [], "the node's executor ran a callback of a wait set's group"
    server.start()
    assert wait_until(lambda: len(received) == 1), "the wait set took the message waiting since before it started"
    for value in (2.0, 3.0):
        publisher.publish(Float64(data=value))
    assert wait_until(lambda: len(received) == 3)
    assert received == [(1.0, "coco:sub (wait set)"), (2.0, "coco:sub (wait set)"), (3.0, "coco:sub (wait set)")]
    assert server.stop() and rig.errors == []


def test_a_service_and_a_client_in_two_wait_sets_answer_each_other(rig: Rig) -> None:
    serving, server = rig.wait_set("service")
    calling, caller = rig.wait_set("client")
    threads: list[str] = []

    def invert(request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        threads.append(threading.current_thread().name)
        response.success = not request.data
        response.message = "inverted"
        return response

    rig.node.create_service(SetBool, "/coco_wait_set/invert", invert, callback_group=serving)
    client = rig.node.create_client(SetBool, "/coco_wait_set/invert", callback_group=calling)
    server.start()
    caller.start()
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(SetBool.Request(data=False))
    assert wait_until(future.done), "the client's wait set did not complete the call"
    assert future.result().success and future.result().message == "inverted"
    assert threads == ["coco:service (wait set)"]
    assert rig.errors == []


def test_a_destroyed_entity_leaves_the_wait_set_and_a_new_one_joins_it(rig: Rig) -> None:
    group, server = rig.wait_set("timers")
    first: list[int] = []
    second: list[int] = []
    timer = rig.node.create_timer(0.005, lambda: first.append(1), callback_group=group)
    server.start()
    assert wait_until(lambda: len(first) >= 3)
    rig.node.destroy_timer(timer)
    time.sleep(0.05)
    count = len(first)
    rig.node.create_timer(0.005, lambda: second.append(1), callback_group=group)
    assert wait_until(lambda: len(second) >= 3), "a timer created while the wait set runs was never waited on"
    assert len(first) == count, "a destroyed timer still ran"
    assert server.stop() and rig.errors == []


def test_a_coroutine_callback_runs_unless_it_waits_and_then_the_error_says_what_to_do(rig: Rig) -> None:
    group, server = rig.wait_set("coroutines")
    done: list[str] = []
    pending = Future()

    async def quick() -> None:
        done.append("quick")

    async def waits() -> None:
        await pending
        done.append("never")

    rig.node.create_guard_condition(quick, callback_group=group).trigger()
    server.start()
    assert wait_until(lambda: done == ["quick"])
    rig.node.create_guard_condition(waits, callback_group=group).trigger()
    assert wait_until(lambda: rig.errors != [])
    assert rig.errors == ["a callback in coco:coroutines (wait set) failed"]
    assert done == ["quick"]


def test_stop_ends_the_thread_within_a_second_and_reports_a_callback_that_hangs(rig: Rig) -> None:
    group, server = rig.wait_set("idle")
    server.start()
    time.sleep(0.05)
    started = time.monotonic()
    assert server.stop() and time.monotonic() - started < 1.0
    hung, stuck = rig.wait_set("hung")
    release = threading.Event()
    rig.node.create_guard_condition(lambda: release.wait(5.0), callback_group=hung).trigger()
    stuck.start()
    time.sleep(0.1)
    assert not stuck.stop(timeout=0.2), "a wait set whose callback hangs must not report a clean stop"
    release.set()
    assert stuck.stop()
