"""Operations of components that another process runs: called by name, answered by a Future.

A component in one process calls ``self.find_operation("ticker", "scale")`` exactly as it would for
a component of its own process; when ``ticker`` runs in another process, it gets a
:class:`RemoteOperation`, which the launcher routes to that process. There the call is queued to the
component's activity like any call from another thread, and the result, or the exception's type,
message and traceback (:class:`~coco_core.errors.RemoteError`), comes back to the caller's Future
(:mod:`coco_core.calls` serves and settles calls, for the host level too). Arguments and results
cross the boundary pickled.
"""

from __future__ import annotations

from concurrent.futures import Future
from typing import TYPE_CHECKING, Any, Callable, Protocol

from ..calls import settle
from ..errors import CocoError
from ..operations import current_activity
from ..messages import Call

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


def call_over(link: ControlLink, process: str, component: str, operation: str, args: tuple[Any, ...],
              kwargs: dict[str, Any]) -> Future[Any]:
    """Ask the other end of ``link`` for an operation of ``component`` in ``process`` (the
    :class:`Router` protocol of the launcher and of a child alike)."""
    future: Future[Any] = Future()
    target = f"{component}.{operation}"
    link.request(Call(process=process, component=component, operation=operation, args=args, kwargs=kwargs),
                 lambda result: settle(future, result, process, target))
    return future
