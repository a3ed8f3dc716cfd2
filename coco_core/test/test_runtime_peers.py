"""Peers: components nested inside a component, run by their owner in its activity, at any depth."""

from __future__ import annotations

import threading

import pytest

from coco_core import (
    BufferPolicy,
    CocoError,
    Component,
    ConnectionPolicy,
    InputPort,
    OutputPort,
    PeriodicActivity,
    SyncPolicy,
    TriggeredActivity,
)


class Node(Component):
    """Appends ``(phase, name, thread)`` to a log shared by the whole tree."""

    def __init__(self, name, log, **attributes):
        super().__init__(name, **attributes)
        self.log = log
        self.updates = 0

    def _record(self, phase):
        self.log.append((phase, self.name, threading.get_ident()))

    def init(self):
        self._record("init")

    def on_config(self):
        self._record("config")

    def on_update(self):
        self.updates += 1
        self._record("update")

    def on_stop(self):
        self._record("stop")


def tree(log):
    """root -> (a -> (a1 -> a11), b)"""
    root = Node("root", log)
    a = root.add_peer(Node("a", log))
    a1 = a.add_peer(Node("a1", log))
    a1.add_peer(Node("a11", log))
    root.add_peer(Node("b", log))
    return root


def phase(log, name):
    return [who for what, who, _ in log if what == name]


def run_cycles(make_app, wait_until, root, cycles=3, activity=None):
    app = make_app("peers")
    activity = activity or PeriodicActivity("periodic", 0.01)
    app.add(root, activity)
    app.start()
    assert wait_until(lambda: root.updates >= cycles)
    assert app.stop()
    return app, activity


def test_config_update_and_stop_orders(make_app, wait_until):
    log: list = []
    root = tree(log)
    app, activity = run_cycles(make_app, wait_until, root)
    assert phase(log, "config") == ["a11", "a1", "a", "b", "root"], "peers are configured before their owner"
    updates = phase(log, "update")
    order = ["root", "a", "a1", "a11", "b"]
    assert len(updates) % len(order) == 0 and len(updates) >= 3 * len(order)
    assert updates == order * (len(updates) // len(order)), "owner first, then its peers, depth first"
    assert phase(log, "stop") == ["root", "a", "a1", "a11", "b"], "owner stopped first, then its peers"


def test_peers_share_the_owners_activity_and_thread(make_app, wait_until):
    log: list = []
    root = tree(log)
    app, activity = run_cycles(make_app, wait_until, root)
    members = root.walk()
    assert [m.name for m in members] == ["root", "a", "a1", "a11", "b"]
    assert all(member.activity is activity for member in members)
    assert activity.components == [root], "only the owner is scheduled"
    threads = {thread for what, _, thread in log if what != "init"}
    assert len(threads) == 1 and threading.get_ident() not in threads
    assert set(app.components) == {"root", "a", "a1", "a11", "b"}
    assert app.unscheduled() == []
    assert sorted(phase(log, "init")) == ["a", "a1", "a11", "b", "root"]


def test_depth_three_peer_runs_every_cycle(make_app, wait_until):
    log: list = []
    root = Node("root", log)
    middle = root.add_peer(Node("middle", log))
    leaf = middle.add_peer(Node("leaf", log))
    deepest = leaf.add_peer(Node("deepest", log))
    run_cycles(make_app, wait_until, root, cycles=4)
    assert deepest.updates == root.updates >= 4
    assert deepest.owner is leaf and leaf.owner is middle and middle.owner is root


def test_manages_peers_runs_them_only_when_the_owner_steps_them(make_app, wait_until):
    class Renderer(Node):
        manages_peers = True

        def on_update(self):
            super().on_update()
            for peer in reversed(self.peers):  # its own order: back to front
                peer.step()
            if self.updates % 2 == 0:
                self.peers[0].step()  # and the first one once more every other cycle

    log: list = []
    root = Renderer("renderer", log)
    first = root.add_peer(Node("first", log))
    second = root.add_peer(Node("second", log))
    run_cycles(make_app, wait_until, root, cycles=4)
    updates = phase(log, "update")
    assert updates[:7] == ["renderer", "second", "first", "renderer", "second", "first", "first"]
    assert second.updates == root.updates
    assert first.updates == root.updates + root.updates // 2, "peers run exactly as the owner says"


def test_peer_event_port_wakes_the_owners_triggered_activity(make_app, wait_until):
    class Source(Component):
        out = OutputPort(int)

    class Listener(Node):
        inp = InputPort(int, event=True)

        def init(self):
            super().init()
            self.values: list[int] = []

        def on_update(self):
            super().on_update()
            self.values += self.inp.read_all()

    log: list = []
    root = Node("root", log)
    listener = root.add_peer(Node("middle", log)).add_peer(Listener("listener", log))
    app = make_app("peer-events")
    source = app.add(Source("source"))
    activity = TriggeredActivity("triggered")
    app.add(root, activity)
    app.connect("source.out", "listener.inp", ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 10))
    app.start()
    source.out.write(5)
    assert wait_until(lambda: listener.values == [5])
    assert root.updates == 1, "the owner (and so the whole tree) ran once for the peer's event"


def test_peer_added_after_its_owner_was_scheduled_still_wakes_the_activity(make_app, wait_until):
    class Source(Component):
        out = OutputPort(int)

    class Listener(Component):
        inp = InputPort(int, event=True)

        def init(self):
            self.values: list[int] = []

        def on_update(self):
            self.values += self.inp.read_all()

    log: list = []
    root = Node("root", log)
    app = make_app("late-peer")
    app.add(root, TriggeredActivity("triggered"))
    listener = root.add_peer(Listener("listener"))  # nested after scheduling, before start
    app.add(listener)
    source = app.add(Source("source"))
    app.connect("source.out", "listener.inp", ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 10))
    assert listener.activity is app.activity("triggered")
    app.start()
    source.out.write(3)
    assert wait_until(lambda: listener.values == [3], timeout=1.0), "the late peer's event port never woke"


def test_operation_on_a_peer_runs_in_the_owners_thread(make_app, wait_until):
    log: list = []
    root = Node("root", log)
    peer = root.add_peer(Node("peer", log, ))
    app = make_app("peer-op")
    app.add(root, TriggeredActivity("triggered"))
    threads = []
    peer.add_operation("where", lambda: threads.append(threading.get_ident()))
    app.start()
    assert wait_until(lambda: ("config", "root") in [(w, n) for w, n, _ in log])
    peer.call("where").result(timeout=2.0)
    owner_thread = next(t for w, n, t in log if (w, n) == ("config", "root"))
    assert threads == [owner_thread]


def test_peer_rules():
    log: list = []
    owner, other = Node("owner", log), Node("other", log)
    peer = owner.add_peer(Node("peer", log))
    with pytest.raises(CocoError, match="already a peer of owner"):
        other.add_peer(peer)
    with pytest.raises(ValueError, match="peer of owner"):
        TriggeredActivity("t").add(peer)
