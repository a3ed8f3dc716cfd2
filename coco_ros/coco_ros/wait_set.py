"""One activity's ROS entities waited on by a thread of its own: an executor for one callback group.

rclpy 7.1 has no executor per callback group: an executor waits on all the entities of its nodes. Its
``MultiThreadedExecutor`` rebuilds one wait set of the whole node after every callback, in Python,
and hands each ready callback from the waiting thread to a worker of its pool; at 100 messages/s
through a pipeline of three activities that costs more than the pipeline's own work (issue 12,
``docs/benchmarks.md``, Figure 6). An :class:`ActivityWaitSet` instead waits, in its activity's
thread, on that activity's entities only (its guard condition and timer, the subscriptions, services,
clients and QoS event handlers its components made in its group) and runs each callback right there:
no hand-off, and a wait set of a handful of entities, filled again without being reallocated.

The group is a :class:`WaitSetGroup`: it tells every executor that it cannot execute its entities, so
the node's executor leaves them out of its wait set (rclpy asks ``callback_group.can_execute`` before
it waits on an entity). One thread runs all the group's callbacks, so they never run concurrently:
the group is mutually exclusive by construction.

The QoS event handlers (rclpy makes one per publisher and subscription, to warn of an incompatible QoS
or type) cost half of a wait here (measured: 20 us instead of 9 with two publishers and two
subscriptions). Left to the node's executor instead, they woke it with every message of their
subscription (Fast DDS signals a subscription's events and data on one condition), and its thread
spun on them, holding the GIL, until this thread had taken the message: 60% more CPU per message
and a p90 latency of 6 ms instead of 2 (``bench/bench_latency.py``).
"""

from __future__ import annotations

import inspect
import logging
import threading
from typing import TYPE_CHECKING, Any, Callable

from coco_core import CocoError
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.client import Client
from rclpy.exceptions import InvalidHandle
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.service import Service
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from rclpy.waitable import NumberOfEntities, Waitable

if TYPE_CHECKING:
    from rclpy.context import Context

log = logging.getLogger("coco")

POLL_NS = 100_000_000
"""Longest wait (ns): the thread then looks whether ROS was shut down under it. Waits end earlier for
every callback and for :meth:`ActivityWaitSet.stop`; a timeout costs nothing in rcl (no timer)."""


class WaitSetGroup(MutuallyExclusiveCallbackGroup):
    """The callback group of an activity that an :class:`ActivityWaitSet` serves: no executor may
    execute its entities, so that the node's executor never waits on them (it asks
    ``can_execute`` before it puts an entity into its wait set)."""

    def can_execute(self, entity: object) -> bool:
        return False


class ActivityWaitSet:
    """A thread that waits on the entities of ``group`` and runs their callbacks, until :meth:`stop`.

    An exception from a callback is logged and given to ``on_error`` (the application's stop request),
    as :class:`coco_ros.hosting.ExecutorThread` does for the executor; the thread goes on, so that the
    activity can still finish.
    """

    def __init__(self, group: WaitSetGroup, context: Context, name: str,
                 on_error: Callable[[str], None] | None = None) -> None:
        self.group = group
        self.context = context
        self.on_error = on_error
        self._wake = GuardCondition(None, None, context=context)
        """Ends a wait: :meth:`wake` (a timer's period changed) and :meth:`stop`."""
        self._wake_destroyed = False
        self._stopped = False
        self._wait_set: Any = None
        self._cache: _Entities | None = None
        self._sizes: tuple[int, ...] = ()
        self._thread = threading.Thread(target=self._loop, name=f"coco:{name} (wait set)", daemon=True)

    def start(self) -> None:
        if not self._thread.is_alive() and not self._stopped:
            self._thread.start()

    @property
    def running(self) -> bool:
        """Whether the thread runs (started, not stopped yet)."""
        return self._thread.is_alive()

    def wake(self) -> None:
        """Make the thread wait again: it computes its timeout from the group's timers anew."""
        try:
            self._wake.trigger()
        except InvalidHandle:  # destroyed at shutdown
            pass

    def stop(self, timeout: float = 1.0) -> bool:
        """End the thread; False when it did not end within ``timeout`` seconds (a callback hangs)."""
        self._stopped = True
        self.wake()
        if self._thread.is_alive():
            self._thread.join(timeout)
        alive = self._thread.is_alive()
        if not alive and not self._wake_destroyed:
            self._wake_destroyed = True
            self._wake.destroy()
        return not alive

    # --- the thread -----------------------------------------------------------------------------
    def _loop(self) -> None:
        while not self._stopped:
            if not self.context.ok():
                if self.on_error is not None:
                    self.on_error("ROS was shut down")
                return
            try:
                self._spin_once()
            except Exception:
                log.exception("the wait set of %s failed", self._thread.name)
                if self.on_error is not None:
                    self.on_error(f"a callback in {self._thread.name} failed")

    def _entities(self) -> _Entities:
        """The group's entities by kind, gathered again when one was added to the group (it holds
        weak references; rclpy adds every entity made in the group) or destroyed (a handle that can
        no longer be held)."""
        count = len(self.group.entities)
        if self._cache is None or self._cache.count != count:
            self._cache = _Entities(self.group, count, self._wake, self.context)
        return self._cache

    def _spin_once(self) -> None:
        """Wait once (at most :data:`POLL_NS`) and run the callbacks of what became ready: timers,
        subscriptions, guard conditions, services, clients, then waitables (QoS events), as rclpy's executor.

        Every handle is held during the wait: a ``destroy()`` from another thread then waits until
        the wait ends instead of freeing what rcl waits on."""
        entities = self._entities()
        handles = entities.handles
        held = []
        try:
            for handle in handles:
                handle.__enter__()
                held.append(handle)
        except InvalidHandle:  # destroyed since: gathered again at the next wait
            for handle in held:
                handle.__exit__(None, None, None)
            self._cache = None
            return
        try:
            wait_set = self._reuse(entities)
            for kind in entities.kinds:
                for handle in kind.handles:
                    kind.add(wait_set, handle)
            for waitable in entities.waitables:
                waitable.add_to_wait_set(wait_set)
            wait_set.wait(POLL_NS)
            if self._stopped:
                return
            ready = [(kind, wait_set.get_ready_entities(kind.name)) for kind in entities.kinds if kind.handles]
        finally:
            for handle in held:
                handle.__exit__(None, None, None)
        for kind, pointers in ready:  # what became ready, kind by kind: usually one entity
            for pointer in pointers:
                entity = kind.by_pointer.get(pointer)
                if entity is not None:
                    kind.run(entity)
        # QoS events last: after the data (the wait set keeps its results until it is filled again)
        for waitable in entities.waitables:
            if waitable.is_ready(wait_set):
                _run(waitable.execute, waitable.take_data())

    def _reuse(self, entities: _Entities) -> Any:
        """The wait set, emptied; allocated again only when the group's entities changed in number."""
        if entities.sizes != self._sizes:
            self._wait_set = _rclpy.WaitSet(*entities.sizes, self.context.handle)
            self._sizes = entities.sizes
        else:
            self._wait_set.clear_entities()
        return self._wait_set

    @staticmethod
    def _timer(timer: Timer) -> None:
        try:
            with timer.handle:
                if not timer.handle.is_timer_ready():  # cancelled meanwhile (rcl's cancelled timers)
                    return
                timer.handle.call_timer()
        except InvalidHandle:  # destroyed meanwhile
            return
        _run(timer.callback)

    @staticmethod
    def _subscription(subscription: Subscription) -> None:
        try:
            with subscription.handle:
                taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
        except InvalidHandle:
            return
        if taken is None:
            return
        if subscription._callback_type is Subscription.CallbackType.MessageOnly:
            _run(subscription.callback, taken[0])
        else:
            _run(subscription.callback, *taken)

    @staticmethod
    def _service(service: Service) -> None:
        kind: Any = service.srv_type  # a generated service class (rclpy types it as a protocol)
        try:
            with service.handle:
                request, header = service.handle.service_take_request(kind.Request)
        except InvalidHandle:
            return
        if header is not None:
            service.send_response(_run(service.callback, request, kind.Response()), header)

    @staticmethod
    def _client(client: Client) -> None:
        kind: Any = client.srv_type
        try:
            with client.handle:
                header, response = client.handle.take_response(kind.Response)
        except InvalidHandle:
            return
        if header is None:
            return
        try:
            future = client.get_pending_request(header.request_id.sequence_number)
        except KeyError:  # the request was cancelled
            return
        future.set_result(response)


class _Kind:
    """The group's entities of one kind (in rclpy's executor order), as the wait set takes them: how
    to add a handle, the name it reports them by when ready, the entity behind each ready pointer,
    and how to run one."""

    def __init__(self, name: str, add: Callable[[Any, Any], None], run: Callable[[Any], None],
                 entities: list[Any]) -> None:
        self.name = name
        self.add = add
        self.run = run
        self.handles = [entity.handle for entity in entities]
        self.by_pointer = {handle.pointer: entity for handle, entity in zip(self.handles, entities)}


class _Entities:
    """The live entities of a group by kind, the handles to hold while waiting on them (the
    context's too) and the sizes of a wait set for them (one more guard condition: the wake-up)."""

    def __init__(self, group: WaitSetGroup, count: int, wake: GuardCondition, context: Context) -> None:
        self.count = count
        found: dict[type, list[Any]] = {Timer: [], Subscription: [], GuardCondition: [wake], Service: [],
                                        Client: [], Waitable: []}
        for reference in list(group.entities):
            entity = reference()
            kind = next((kind for kind in found if isinstance(entity, kind)), None)  # None: a dead reference
            if kind is not None and _alive(entity):
                found[kind].append(entity)
        ws = _rclpy.WaitSet
        self.kinds = [_Kind("timer", ws.add_timer, ActivityWaitSet._timer, found[Timer]),
                      _Kind("subscription", ws.add_subscription, ActivityWaitSet._subscription, found[Subscription]),
                      _Kind("guard_condition", ws.add_guard_condition, _guard, found[GuardCondition]),
                      _Kind("service", ws.add_service, ActivityWaitSet._service, found[Service]),
                      _Kind("client", ws.add_client, ActivityWaitSet._client, found[Client])]
        self.waitables: list[Waitable] = found[Waitable]
        self.handles: list[Any] = [handle for kind in self.kinds for handle in kind.handles] + self.waitables \
            + [context.handle]
        count_ = NumberOfEntities(len(found[Subscription]), len(found[GuardCondition]), len(found[Timer]),
                                  len(found[Client]), len(found[Service]))
        for waitable in self.waitables:
            count_ += waitable.get_num_entities()
        self.sizes = (count_.num_subscriptions, count_.num_guard_conditions, count_.num_timers,
                      count_.num_clients, count_.num_services, count_.num_events)


def _guard(guard: GuardCondition) -> None:
    if guard.callback is not None:  # the wake-up has none: it only ends the wait
        _run(guard.callback)


def _alive(entity: Any) -> bool:
    """Whether ``entity`` was not destroyed (its handle can still be held)."""
    handle = entity if isinstance(entity, Waitable) else entity.handle
    try:
        with handle:
            return True
    except InvalidHandle:
        return False


def _run(callback: Callable[..., Any], *args: Any) -> Any:
    """Call ``callback``; a coroutine it returns is run to its end here, when it does not wait."""
    result = callback(*args)
    if not inspect.iscoroutine(result):
        return result
    try:
        result.send(None)
    except StopIteration as done:
        return done.value
    result.close()
    raise CocoError(f"{getattr(callback, '__qualname__', callback)}: a coroutine callback that awaits cannot run in "
                    "an activity's wait set; host the activity in the executor (--executor-threads N)")
