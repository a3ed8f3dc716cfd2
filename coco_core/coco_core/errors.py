"""Errors that point at their cause: the file and line, or the component, and what was expected."""

from __future__ import annotations

from collections.abc import Iterable
import signal
from dataclasses import dataclass


@dataclass(frozen=True)
class Location:
    """Where a piece of an application came from (an XML element), so errors can point at it."""

    file: str
    line: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}"


class CocoError(Exception):
    """Base of every error the runtime raises on purpose."""


class ConfigError(CocoError):
    """A wrong application description: says where (when known) and what was expected."""

    def __init__(self, message: str, location: Location | None = None) -> None:
        self.message = message
        self.location = location
        super().__init__(f"{location}: {message}" if location else message)


class ConfigErrors(CocoError):
    """Several configuration errors found in one pass, reported together so one run shows them all."""

    def __init__(self, errors: list[ConfigError]) -> None:
        self.errors = list(errors)
        noun = "error" if len(self.errors) == 1 else "errors"
        lines = "\n".join(f"  {error}" for error in self.errors)
        super().__init__(f"{len(self.errors)} {noun} in the application:\n{lines}")


def did_you_mean(name: str, valid: "Iterable[str]") -> str:
    """Phrase the list of valid names for an unknown-name error, closest match first."""
    import difflib

    names = sorted(valid)
    if not names:
        return "there are none"
    close = difflib.get_close_matches(name, names, n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return f"{hint}valid: {', '.join(names)}"


class ActivityError(CocoError, ValueError):
    """A wrong use of an activity: a component scheduled twice, a bad period, a second start."""


class ProcessError(CocoError):
    """A child process of the launcher could not be started or built, or died."""


class RemoteError(CocoError):
    """An operation that ran in another process raised: its type, message and traceback come along
    as text (the exception itself may not exist, or not be picklable, in the caller's process)."""

    def __init__(self, process: str, target: str, type_name: str, message: str, remote_traceback: str) -> None:
        self.process = process
        self.target = target
        self.type_name = type_name
        self.message = message
        self.remote_traceback = remote_traceback
        super().__init__(f"{target} in process {process or 'launcher'} raised {type_name}: {message}")


class AttributeValueError(CocoError, ValueError):
    """A value that does not fit the attribute's declaration."""


class UnknownNameError(CocoError, KeyError):
    """An unknown port, attribute or operation name; the message lists the valid ones."""

    def __str__(self) -> str:
        return str(self.args[0])


class UnknownComponentError(CocoError):
    """A task name that no installed package registers; the message lists the known ones."""


class WiringError(CocoError):
    """A connection that cannot be made: wrong direction, incompatible types, wrong policy."""


class FileReadError(CocoError, OSError):
    """A file that is not a regular file, is larger than its limit, or cannot be read."""


class Interrupted(CocoError):
    """The launch was interrupted before the application ran."""

    def __init__(self, signum: int) -> None:
        self.status = 128 + signum
        super().__init__(f"interrupted by {signal.Signals(signum).name} before the application started")


class SubstitutionError(CocoError, ValueError):
    """A substitution that cannot be expanded; the message says which one and why."""


class ExpressionError(CocoError, ValueError):
    """An expression that is not allowed or cannot be evaluated; the text says why."""


class TransformError(CocoError, LookupError):
    """An unknown frame, no path, or a write the declared structure forbids."""


class ExtrapolationError(CocoError, LookupError):
    """A time outside an edge's history; names the edge and the time range it holds."""


class RegistrationError(TransformError, ValueError):
    """A registration that cannot proceed: frames already joined, a temporary path that does not join
    them, too few samples, or samples without a meaningful mean. Both a :class:`TransformError` and a
    :class:`ValueError`, so callers of the graph and of the plain averaging functions catch it alike."""


class ResourceNotFoundError(CocoError, FileNotFoundError):
    """A ``package://`` URL or a file that cannot be found; the message lists where it was looked for."""


class UrdfError(CocoError, ValueError):
    """A URDF that cannot be read or used; names the file and what is wrong with it."""


class WebSocketError(CocoError):
    """A handshake the server cannot accept, or a frame that breaks the protocol."""


class ChannelError(CocoError):
    """A value that cannot cross the channel (it cannot be pickled)."""
