"""Serving an operation call that came from another part of the launch, and settling its caller.

A :class:`~coco_core.messages.Call` arrives from a child process, the launcher or another host; the
component that runs its operation is here. The call is queued to that component's activity like any
call from another thread, and its :class:`~coco_core.messages.Outcome` (the value, or the
exception's type, message and traceback) goes back the way it came; on the caller's side the outcome
completes the caller's Future (a :class:`~coco_core.errors.RemoteError` for an exception). Both
levels serve and settle calls the same way, so it lives beside neither of them.
"""

from __future__ import annotations

import pickle
import traceback
from concurrent.futures import Future
from typing import TYPE_CHECKING, Any, Callable

from .errors import RemoteError
from .messages import Call, Outcome

if TYPE_CHECKING:
    from .application import Application


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
    if result.ok:
        try:
            pickle.dumps(result.value)
        except Exception as error:
            return Outcome.failure(type(error).__name__, f"the result cannot be sent to another process: {error}")
    return result
