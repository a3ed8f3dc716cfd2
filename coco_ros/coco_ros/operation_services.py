"""The application's operations as ROS services of the launcher's node.

A CoCo operation (``@operation``: BagReplay's ``pause``/``seek``, MovingAverage's ``set_window``,
every component's ``set_attribute``/``get_attribute``) runs in its component's own activity and
answers through a Future; in-process code and other processes call it by name. A ROS tool reaches it
through two kinds of services of the launcher's node (``~`` is the node's name):

- ``~/call_operation`` (``coco_interfaces/srv/CallOperation``): any operation of any component of
  the application, in any of its processes: the component's and the operation's names, the arguments
  as YAML (a list, a mapping of keywords, or one value), the result back as YAML or the error (an
  unknown name lists the valid ones);
- ``~/<component>/<operation>`` (``std_srvs/srv/Trigger``) for every operation that takes no
  argument (``ros2 service call /baxter_teleop_replay/replay/pause std_srvs/srv/Trigger``): the
  result's text as the message.

The services are served by a thread of their own (an :class:`~coco_ros.wait_set.ActivityWaitSet` on
a group of their own), never by the node's executor: a call waits until the owning activity has run
the operation, at most :data:`CALL_TIMEOUT` seconds, and that wait must not hold up the executor,
which may host the very activity that is to run it (``--executor-threads 1``).

Anyone on the DDS domain may call them, so a request is bounded before it is read: names of at most
:data:`MAX_NAME` characters, arguments of at most :data:`MAX_ARGUMENTS` bytes (refused with the
limit), and what a reply or the log quotes of a request is cut (:data:`MAX_REASON`).
"""

from __future__ import annotations

import inspect
import logging
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any

import yaml

from coco_core import Application, CocoError, registry
from coco_core.errors import bounded, excerpt
from coco_core.model import AppSpec

from .wait_set import ActivityWaitSet, WaitSetGroup

log = logging.getLogger("coco.operations")

CALL_TIMEOUT = 10.0
"""Seconds a service call waits for its operation's result: an operation runs at its activity's
next cycle, so a slow periodic activity answers late, and a stopped one never."""
MAX_ARGUMENTS = 64 * 1024
"""Bytes of YAML a call's arguments may have: an operation takes a few values (a window, a frame's
name, a pose); a larger text is refused before it is parsed (20 MB kept pure-Python YAML busy past
any timeout, then went whole into the log)."""
MAX_NAME = 256
"""Characters a component's or an operation's name in a call may have (an application's are short
identifiers): a longer one is refused before it is looked up."""
MAX_REASON = 1000
"""Characters of an error passed back to the caller and into the log (an operation's error may
quote the value it refused)."""


def takes_no_argument(function: Any) -> bool:
    """Whether ``function`` (an operation's method, unbound) can be called without arguments."""
    parameters = list(inspect.signature(function).parameters.values())[1:]  # self
    return all(p.default is not p.empty or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD) for p in parameters)


def check_name(what: str, name: str) -> None:
    """Refuse a ``what`` ("component", "operation") name longer than :data:`MAX_NAME`."""
    if len(name) > MAX_NAME:
        raise CocoError(f"{what} name {excerpt(name, 40)} is longer than the limit of {MAX_NAME} characters")


def arguments_of(text: str) -> tuple[tuple[Any, ...], dict[str, Any]]:
    """(positional, keywords) from the request's YAML: a list, a mapping or one value; empty: none.
    More than :data:`MAX_ARGUMENTS` bytes are refused unread."""
    size = len(text.encode("utf-8", errors="replace"))
    if size > MAX_ARGUMENTS:
        raise CocoError(f"arguments {excerpt(text, 40)} have {size} bytes, more than the limit of {MAX_ARGUMENTS}")
    try:
        value = yaml.safe_load(text) if text.strip() else None
    except yaml.YAMLError as error:
        raise CocoError(f"arguments {excerpt(text)} are not YAML: {error}") from None
    if value is None:
        return (), {}
    if isinstance(value, list):
        return tuple(value), {}
    if isinstance(value, dict):
        if not all(isinstance(key, str) for key in value):
            raise CocoError(f"arguments {excerpt(text)}: the keys of a mapping name keyword arguments")
        return (), value
    return (value,), {}


def result_text(value: Any) -> str:
    """An operation's result as YAML; what YAML cannot write (numpy arrays, objects) as its repr."""
    try:
        return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("...").strip()
    except yaml.YAMLError:
        return repr(value)


class OperationServices:
    """Serves ``app``'s operations (every process's, from ``spec``) as services of ``node``."""

    def __init__(self, node: Any, app: Application, spec: AppSpec) -> None:
        from coco_interfaces.srv import CallOperation
        from std_srvs.srv import Trigger

        self.app = app
        self.group = WaitSetGroup()
        self.services = [node.create_service(CallOperation, "~/call_operation", self._call, callback_group=self.group)]
        for component in spec.all_components():
            try:
                cls = registry.load(component.task, component.library)
            except CocoError:  # the build reported it already; the application would not run
                continue
            for name, method in sorted(cls._operation_decls.items()):
                if takes_no_argument(getattr(cls, method)):
                    self.services.append(node.create_service(
                        Trigger, f"~/{component.name}/{name}", self._trigger(component.name, name),
                        callback_group=self.group))
        self._waiter = ActivityWaitSet(self.group, node.context, "coco:operations")

    def __enter__(self) -> OperationServices:
        self._waiter.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._waiter.stop()

    def call(self, component: str, name: str, args: tuple[Any, ...] = (), kwargs: dict[str, Any] | None = None) -> Any:
        """Run the operation and wait for its result (raises what it raised, or why it could not run)."""
        future = self.app.operation(component, name)(*args, **(kwargs or {}))
        try:
            return future.result(CALL_TIMEOUT)
        except FutureTimeout:
            raise CocoError(f"{component}.{name} did not answer within {CALL_TIMEOUT:g} s (its activity did not "
                            "run it: is the application running?)") from None

    def _call(self, request: Any, response: Any) -> Any:
        try:
            check_name("component", request.component)
            check_name("operation", request.operation)
            args, kwargs = arguments_of(request.arguments)
            response.result = result_text(self.call(request.component, request.operation, args, kwargs))
            response.success = True
        except Exception as error:  # the caller gets the reason, the application goes on
            response.success, response.error = False, _reason(error)
            log.warning("service call of %s.%s failed: %s", excerpt(request.component, 40),
                        excerpt(request.operation, 40), response.error)
        return response

    def _trigger(self, component: str, name: str) -> Any:
        def serve(request: Any, response: Any) -> Any:
            try:
                response.message = result_text(self.call(component, name))
                response.success = True
            except Exception as error:
                response.success, response.message = False, _reason(error)
            return response

        return serve


def _reason(error: BaseException) -> str:
    """The text a caller reads: CoCo's errors say what to do; others name their type. Cut to
    :data:`MAX_REASON` characters: it may quote what the caller sent."""
    return bounded(str(error) if isinstance(error, CocoError) else f"{type(error).__name__}: {error}", MAX_REASON)
