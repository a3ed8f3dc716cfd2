"""Window input events, and how they reach the components that react to them.

A window (GLFW in :mod:`.context`) turns its callbacks into :class:`InputEvent` values; GLManager
hands each frame's events to every component it runs (its peers, at any depth) that is an
:class:`EventHandler`, before stepping them. Camera controllers are such handlers. Tests feed events
through :func:`dispatch`, the same function the window path uses, so no window is needed to test a
controller. Keys are GLFW's names without the ``KEY_`` prefix (``"W"``, ``"LEFT_SHIFT"``,
``"ESCAPE"``), so controllers do not depend on GLFW.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Iterable

from coco_core.component import Component


class EventKind(enum.Enum):
    KEY = "key"
    MOUSE_BUTTON = "mouse_button"
    CURSOR = "cursor"
    SCROLL = "scroll"
    RESIZE = "resize"
    CLOSE = "close"


class Action(enum.Enum):
    """What happened to a key or a button (GLFW's PRESS, RELEASE, REPEAT)."""

    PRESS = "press"
    RELEASE = "release"
    REPEAT = "repeat"


class MouseButton(enum.IntEnum):
    """GLFW's button numbers."""

    LEFT = 0
    RIGHT = 1
    MIDDLE = 2


@dataclass(frozen=True, slots=True)
class InputEvent:
    """One input event of a window.

    ``x``, ``y`` are the cursor position in window pixels (origin top-left, y down, as GLFW reports
    it) for CURSOR and MOUSE_BUTTON events, the offsets for SCROLL; ``size`` is the window's size when
    the event happened, so that handlers can normalise positions without asking the window.
    """

    kind: EventKind
    size: tuple[int, int]
    key: str = ""
    action: Action | None = None
    button: int = -1
    mods: int = 0
    x: float = 0.0
    y: float = 0.0


class EventHandler:
    """Mixin of components that react to window events (camera controllers)."""

    def handle_event(self, event: InputEvent) -> None:
        """React to one event; called in the render thread before the handler's ``step()``."""
        raise NotImplementedError(f"{type(self).__name__} must implement handle_event()")


def dispatch(events: Iterable[InputEvent], components: Iterable[Component]) -> None:
    """Give every event, in order, to every enabled :class:`EventHandler` among ``components``.

    A handler that raises is reported through its component's error policy, like a failed update,
    so that one broken controller cannot stop the window.
    """
    handlers = [c for c in components if isinstance(c, EventHandler)]
    for event in events:
        for handler in handlers:
            if not handler.enabled:  # stopped, possibly by its error policy on an earlier event
                continue
            try:
                handler.handle_event(event)
            except Exception:
                handler.report_error("handle_event")
