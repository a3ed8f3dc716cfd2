"""Operations: functions of a component that other components (and tools) call safely from any thread.

A call from inside the callee's own activity runs at once. A call from anywhere else is queued to the
callee's activity, which runs it before its next ``on_update``, so the component's state is only
ever touched by its own thread and needs no locks. Either way the caller gets a
``concurrent.futures.Future``; ``send`` is the enqueue-only form whose result callback runs back in
the caller's activity.
"""

from __future__ import annotations

import threading
from concurrent.futures import Future
from typing import TYPE_CHECKING, Any, Callable, TypeVar

if TYPE_CHECKING:
    from .activity import Activity
    from .component import Component

F = TypeVar("F", bound=Callable[..., Any])

_context = threading.local()


def current_activity() -> Activity | None:
    """The activity running on this thread, or None outside any activity."""
    return getattr(_context, "activity", None)


def set_current_activity(activity: Activity | None) -> None:
    """Called by an activity's thread when it starts and ends."""
    _context.activity = activity


def operation(function: F | None = None, *, name: str | None = None) -> Any:
    """Mark a component method as an operation, callable by name (``@operation`` or
    ``@operation(name="...")``)."""

    def mark(fn: F) -> F:
        fn._coco_operation = name or fn.__name__  # type: ignore[attr-defined]
        return fn

    return mark(function) if function is not None else mark


def _run_into(future: Future, function: Callable[..., Any], args: tuple, kwargs: dict) -> None:
    if not future.set_running_or_notify_cancel():
        return
    try:
        result = function(*args, **kwargs)
    except BaseException as error:  # delivered to the caller through the future
        future.set_exception(error)
    else:
        future.set_result(result)


class Operation:
    """An operation bound to one component instance."""

    def __init__(self, component: Component, name: str, function: Callable[..., Any]) -> None:
        self.component = component
        self.name = name
        self.function = function

    def __call__(self, *args: Any, **kwargs: Any) -> Future:
        """Run now when the caller is in the callee's activity (or it is not running), else queue it."""
        future: Future = Future()
        activity = self.component.activity
        if activity is None or not activity.running or current_activity() is activity:
            _run_into(future, self.function, args, kwargs)
        else:
            activity.enqueue(lambda: _run_into(future, self.function, args, kwargs))
        return future

    def send(self, *args: Any, callback: Callable[[Future], None] | None = None, **kwargs: Any) -> None:
        """Enqueue-only call; ``callback(future)`` runs in the caller's activity once the result is in
        (in the callee's thread when the caller is not an activity)."""
        caller = current_activity()
        future = self(*args, **kwargs)
        if callback is None:
            return
        if caller is not None and caller is not self.component.activity and caller.running:
            future.add_done_callback(lambda done: caller.enqueue(lambda: callback(done)))
        else:
            future.add_done_callback(callback)

    def __repr__(self) -> str:
        return f"<Operation {self.component.name}.{self.name}>"
