"""Operations of components that another process runs: called by name, answered by a Future.

A component in one process calls ``self.find_operation("ticker", "scale")`` exactly as it would for
a component of its own process; when ``ticker`` runs in another process, it gets a
:class:`RemoteOperation`, which the launcher routes to that process. There the call is queued to the
component's activity like any call from another thread, and the result, or the exception's type,
message and traceback (:class:`~coco_core.errors.RemoteError`), comes back to the caller's Future.
Arguments and results cross the boundary pickled.
"""

from __future__ import annotations

import traceback
from concurrent.futures import Future
from typing import TYPE_CHECKING, Any, Callable, Protocol

from ..errors import CocoError, RemoteError
from ..operations import current_activity
from .messages import Call, Outcome

if TYPE_CHECKING:
    from ..application import Application
    from .control import ControlLink


class Router(Protocol):
    """What carries a call to the process that runs its component: the launcher's supervisor, or a
    child's control link to the launcher."""

    def call(self, process: str, component: str, operation: str, args: tuple[Any, ...],
             kwargs: dict[str, Any]) -> Future[Any]: ...


class RemoteOperation:
    """An operation of a component in another process, with :class:`~coco_core.operations.Operation`'s
    interface: calling it returns a Future; ``send`` runs a callback in the caller's activity."""

    def __init__(self, app: Application, process: str, component: str, name: str) -> None:
        self.app = app
        self.process = process
        self.component = component
        self.name = name

    def __call__(self, *args: Any, **kwargs: Any) -> Future[Any]:
        router = self.app.router
        if router is None:
            raise CocoError(f"component {self.component} runs in process {self.process or 'launcher'}, "
                            "which is not running (operations across processes need the launcher)")
        return router.call(self.process, self.component, self.name, args, kwargs)

    def send(self, *args: Any, callback: Callable[[Future[Any]], None] | None = None, **kwargs: Any) -> None:
        """Enqueue-only call; ``callback(future)`` runs in the caller's activity once the result is in."""
        caller = current_activity()
        future = self(*args, **kwargs)
        if callback is None:
            return
        if caller is not None and caller.running:
            future.add_done_callback(lambda done: caller.enqueue(lambda: callback(done)))
        else:
            future.add_done_callback(callback)

    def __repr__(self) -> str:
        return f"<RemoteOperation {self.component}.{self.name} in process {self.process or 'launcher'}>"


def outcome(future: Future[Any]) -> Outcome:
    """A finished local call's outcome: the value, or the exception as text."""
    error = future.exception()
    if error is None:
        return Outcome(True, future.result())
    text = "".join(traceback.format_exception(type(error), error, error.__traceback__))
    return Outcome(False, type=type(error).__name__, message=str(error), traceback=text)


def settle(future: Future[Any], result: Outcome, process: str, target: str) -> None:
    """Complete the caller's ``future`` from the outcome of its call."""
    if result.ok:
        future.set_result(result.value)
    else:
        future.set_exception(RemoteError(process, target, result.type, result.message, result.traceback))


def call_over(link: ControlLink, process: str, component: str, operation: str, args: tuple[Any, ...],
              kwargs: dict[str, Any]) -> Future[Any]:
    """Ask the other end of ``link`` for an operation of ``component`` in ``process`` (the
    :class:`Router` protocol of the launcher and of a child alike)."""
    future: Future[Any] = Future()
    target = f"{component}.{operation}"
    link.request(Call(process=process, component=component, operation=operation, args=args, kwargs=kwargs),
                 lambda result: settle(future, result, process, target))
    return future


def serve_call(app: Application, call: Call, reply: Callable[[Outcome], object]) -> None:
    """Run a call that arrived from another process on a component of this one; ``reply`` gets the
    outcome once the component's activity ran it."""
    try:
        future = app.operation(call.component, call.operation)(*call.args, **call.kwargs)
    except Exception as error:  # an unknown name: the caller gets the explanation
        failed: Future[Any] = Future()
        failed.set_exception(error)
        reply(outcome(failed))
        return
    future.add_done_callback(lambda done: reply(_picklable(outcome(done))))


def _picklable(result: Outcome) -> Outcome:
    """``result``, or an error saying the value cannot cross the process boundary."""
    import pickle

    if result.ok:
        try:
            pickle.dumps(result.value)
        except Exception as error:
            return Outcome.failure(type(error).__name__, f"the result cannot be sent to another process: {error}")
    return result
