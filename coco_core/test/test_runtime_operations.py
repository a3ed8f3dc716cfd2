"""Operations: direct calls inside one activity, queued calls across activities, futures, send."""

from __future__ import annotations

import threading
import time
from concurrent.futures import Future

import pytest

from coco_core import (
    Component,
    PeriodicActivity,
    TriggeredActivity,
    UnknownNameError,
    current_activity,
    operation,
)


class Server(Component):
    """Logs its operations and updates (with threads) so their interleaving can be checked."""

    def init(self):
        self.log: list[tuple[str, int, object]] = []
        self.updates = 0
        self.configured = threading.Event()
        self.thread: int | None = None

    def on_config(self):
        self.thread = threading.get_ident()
        self.configured.set()

    @operation
    def echo(self, value):
        self.log.append(("op", threading.get_ident(), value))
        return value * 2

    @operation(name="explode")
    def fail(self, message="boom"):
        raise ValueError(message)

    def on_update(self):
        self.log.append(("update-start", threading.get_ident(), None))
        self.updates += 1
        self.log.append(("update-end", threading.get_ident(), None))

    def on_stop(self):
        self.log.append(("on_stop", threading.get_ident(), None))


class Client(Component):
    """Calls ``server.echo`` once, from its first update, the way ``mode`` says."""

    def init(self):
        self.mode = "call"
        self.server: Server | None = None
        self.results: list = []
        self.done = threading.Event()
        self.thread: int | None = None
        self.updates = 0

    def on_update(self):
        self.updates += 1
        self.thread = threading.get_ident()
        if self.updates != 1:
            return
        echo = self.server.operation("echo")
        if self.mode == "call":
            future = echo(21)
            self.results.append(("done-at-return", future.done()))
            self.results.append(("future", future))
            self.done.set()
        else:
            def callback(future: Future):
                self.results.append(("callback", threading.get_ident(), current_activity(), future.result()))
                self.done.set()

            echo.send(21, callback=callback)


def assert_ops_between_updates(log):
    """Every operation ran outside an update, and an update follows it when there is one."""
    inside = False
    for index, (event, _, _) in enumerate(log):
        if event == "update-start":
            inside = True
        elif event == "update-end":
            inside = False
        elif event == "op":
            assert not inside, f"an operation ran in the middle of on_update: {log}"


def test_same_activity_call_runs_synchronously_in_the_callers_thread(make_app, wait_until):
    app = make_app("same")
    activity = PeriodicActivity("shared", 0.01)
    client = app.add(Client("client"), activity)
    server = app.add(Server("server"), activity)
    client.server = server
    app.start()
    assert client.done.wait(2.0)
    results = dict(client.results)
    assert results["done-at-return"] is True, "a call inside the callee's activity completes before returning"
    assert results["future"].result(0) == 42
    op_threads = {thread for event, thread, _ in server.log if event == "op"}
    assert op_threads == {client.thread}
    assert wait_until(lambda: server.updates >= 1)
    assert server.thread == client.thread


def test_cross_activity_call_runs_in_the_callees_thread_before_its_next_update(make_app, wait_until):
    app = make_app("cross")
    server = app.add(Server("server"), PeriodicActivity("server", 0.02))
    app.start()
    assert wait_until(lambda: server.updates >= 2)
    futures = [server.call("echo", value) for value in range(5)]
    assert [f.result(timeout=2.0) for f in futures] == [0, 2, 4, 6, 8]
    assert wait_until(lambda: server.log[-1][0] == "update-end" and
                      [e for e, _, _ in server.log].count("op") == 5)
    ops = [(index, entry) for index, entry in enumerate(server.log) if entry[0] == "op"]
    assert [value for _, (_, _, value) in ops] == [0, 1, 2, 3, 4], "queued calls run in order"
    assert {thread for _, (_, thread, _) in ops} == {server.thread}
    assert server.thread != threading.get_ident()
    last_op = ops[-1][0]
    assert server.log[last_op + 1][0] == "update-start", "the queued calls run just before an update"
    assert_ops_between_updates(server.log)


def test_call_from_another_activity_is_queued_to_the_callee(make_app, wait_until):
    app = make_app("cross-activity")
    server = app.add(Server("server"), TriggeredActivity("server"))
    client = app.add(Client("client"), PeriodicActivity("client", 0.01))
    client.server = server
    app.start()
    assert client.done.wait(2.0)
    future = dict(client.results)["future"]
    assert future.result(timeout=2.0) == 42
    op_threads = {thread for event, thread, _ in server.log if event == "op"}
    assert op_threads == {server.thread} and server.thread != client.thread
    # The call woke the triggered server: it runs its update right after the queued call.
    assert wait_until(lambda: server.updates >= 1)
    assert [e for e, _, _ in server.log][:2] == ["op", "update-start"]


def test_future_carries_the_operations_exception(make_app, wait_until):
    app = make_app("exception")
    server = app.add(Server("server"), TriggeredActivity("server"))
    app.start()
    assert server.configured.wait(1.0)
    future = server.call("explode", "kaput")
    error = future.exception(timeout=2.0)
    assert isinstance(error, ValueError) and str(error) == "kaput"
    with pytest.raises(ValueError, match="kaput"):
        future.result()
    assert server.stats.errors == 0, "an operation's error belongs to its caller, not the component"
    # The activity is alive and keeps serving.
    assert server.call("echo", 4).result(timeout=2.0) == 8


def test_direct_call_carries_exceptions_too():
    server = Server("server")
    server.init()
    future = server.call("explode")
    assert future.done()
    assert isinstance(future.exception(), ValueError)


def test_send_callback_runs_in_the_callers_activity(make_app):
    app = make_app("send")
    server = app.add(Server("server"), TriggeredActivity("server"))
    client = app.add(Client("client"), PeriodicActivity("client", 0.01))
    client.server = server
    client.mode = "send"
    app.start()
    assert client.done.wait(2.0)
    (kind, thread, activity, result), = client.results
    assert kind == "callback" and result == 42
    assert thread == client.thread, "the result callback runs in the caller's activity thread"
    assert activity is app.activity("client")
    assert {t for e, t, _ in server.log if e == "op"} == {server.thread} != {client.thread}


def test_send_without_callback_runs_the_operation(make_app, wait_until):
    app = make_app("send-only")
    server = app.add(Server("server"), TriggeredActivity("server"))
    app.start()
    assert server.configured.wait(1.0)
    assert server.operation("echo").send(5) is None
    assert wait_until(lambda: ("op", server.thread, 5) in server.log)


def test_send_from_outside_any_activity_calls_back_in_the_callees_thread(make_app):
    app = make_app("send-outside")
    server = app.add(Server("server"), TriggeredActivity("server"))
    app.start()
    assert server.configured.wait(1.0)
    called = threading.Event()
    seen = []

    def callback(future):
        seen.append((threading.get_ident(), future.result()))
        called.set()

    server.operation("echo").send(7, callback=callback)
    assert called.wait(2.0)
    assert seen == [(server.thread, 14)]


def test_send_inside_the_callees_activity_calls_back_at_once(make_app):
    app = make_app("send-same")
    activity = PeriodicActivity("shared", 0.01)
    client = app.add(Client("client"), activity)
    server = app.add(Server("server"), activity)
    client.server = server
    client.mode = "send"
    app.start()
    assert client.done.wait(2.0)
    (kind, thread, current, result), = client.results
    assert (thread, current, result) == (client.thread, activity, 42)


def test_queued_call_waits_for_the_next_deadline_and_runs_before_on_stop(make_app, wait_until):
    app = make_app("queued")
    server = app.add(Server("server"), PeriodicActivity("slow", 10.0))
    app.start()
    assert wait_until(lambda: server.updates == 1)
    future = server.call("echo", 1)
    time.sleep(0.1)
    assert not future.done(), "a periodic activity runs queued calls at its next deadline, 10 s away"
    assert app.stop()
    assert future.result(timeout=0) == 2
    events = [e for e, _, _ in server.log]
    assert events[-2:] == ["op", "on_stop"], "pending calls are served before on_stop"
    assert {t for _, t, _ in server.log} == {server.thread}


def test_call_to_a_component_that_is_not_running_runs_at_once():
    server = Server("server")
    server.init()
    future = server.call("echo", 3)
    assert future.done() and future.result() == 6
    assert server.log == [("op", threading.get_ident(), 3)]


def test_call_after_stop_runs_in_the_callers_thread(make_app, wait_until):
    app = make_app("after-stop")
    server = app.add(Server("server"), TriggeredActivity("server"))
    app.start()
    assert server.configured.wait(1.0)
    assert app.stop()
    assert server.call("echo", 2).result(timeout=1.0) == 4
    assert server.log[-1] == ("op", threading.get_ident(), 2)


def test_operation_names_and_unknown_names():
    server = Server("server")
    assert set(server.operations) >= {"echo", "explode", "set_attribute", "get_attribute"}
    assert "fail" not in server.operations, "@operation(name=...) renames the operation"
    with pytest.raises(UnknownNameError) as info:
        server.operation("ecco")
    message = str(info.value)
    assert "ecco" in message and "did you mean 'echo'" in message
    for name in ("echo", "explode", "set_attribute"):
        assert name in message


def test_add_operation_binds_a_plain_function(make_app):
    app = make_app("plain")
    server = app.add(Server("server"), TriggeredActivity("server"))
    threads = []
    server.add_operation("where", lambda: threads.append(threading.get_ident()) or "here")
    app.start()
    assert server.configured.wait(1.0)
    assert server.call("where").result(timeout=2.0) == "here"
    assert threads == [server.thread]
