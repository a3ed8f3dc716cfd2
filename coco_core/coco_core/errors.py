"""Errors that point at their cause: the file and line, or the component, and what was expected."""

from __future__ import annotations

from collections.abc import Iterable
import signal
from dataclasses import dataclass
from pathlib import Path


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


class CommandLineError(ConfigError):
    """A wrong command line rather than a wrong file: a word that is not ``name:=value``, a given
    arg that no file declares, an option the application cannot take (``--host``, ``--threads``
    naming what it does not have). The launchers exit with 2 for it, as for an option argparse
    refuses (the README's exit statuses), and with 1 when the file is wrong too."""


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
    # A name twice as long as every valid one is no typo of them; comparing a huge one (a 5 MB name
    # sent to a service) would take seconds.
    close = difflib.get_close_matches(name, names, n=1) if len(name) <= 2 * max(map(len, names)) else []
    hint = f"did you mean {close[0]!r}? " if close else ""
    return f"{hint}valid: {', '.join(names)}"


def excerpt(text: str, limit: int = 120) -> str:
    """``text`` quoted for an error message, cut to ``limit`` characters with its length said: what
    came from outside (a value, a name) is never echoed whole into a log or a reply."""
    return repr(text) if len(text) <= limit else f"{text[:limit - 3]!r}... ({len(text)} characters)"


def bounded(text: str, limit: int) -> str:
    """``text`` (an error's message) cut to ``limit`` characters, its length said: for a reason
    passed on to a caller or a log line, whatever it quotes."""
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters in all)"


class ActivityError(CocoError, ValueError):
    """A wrong use of an activity: a component scheduled twice, a bad period, a second start."""


class ProcessError(CocoError):
    """A child process of the launcher could not be started or built, or died."""


class HostError(CocoError):
    """Another host of the application did not come in time, or cannot be reached (``coco_core.hosts``)."""


class GraphError(CocoError):
    """The data-flow graph cannot be written (``--check --graph``): a wrong file name, no Graphviz
    to render it."""


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


class PolicyError(WiringError, ValueError):
    """A connection policy no connection can honour: a buffer without room, a data policy only pooled
    ports make, a pooled output asked to share its frames out, a connection that is not the port's."""


class PoolError(CocoError, ValueError):
    """A frame pool used wrongly: too few slots, a slot from another pool or not being read, nothing
    published yet."""


class MeasurementError(CocoError, ValueError):
    """A measurement that cannot be: a negative or non-finite duration, a quantile of nothing."""


class SetupError(CocoError, ValueError):
    """A component whose attributes or peers cannot work together, found when it is configured
    (``far`` not beyond ``near``, a peer of the wrong kind, a missing camera)."""


class DeclarationError(CocoError, TypeError):
    """A component class that cannot be declared: a port or attribute name that shadows Component's own."""


class WrongTypeError(CocoError, TypeError):
    """A value of the wrong kind where it is given: a message to another converter, a pose input that is
    not a pose, a slot that does not hold a mesh."""


class UsageError(CocoError, RuntimeError):
    """A call at the wrong moment: a server started twice or asked its URL before it started, the
    transformation graph written inside a read of it."""


class ConnectionClosedError(CocoError, EOFError):
    """The other end closed a connection (a process channel, a WebSocket) before a whole message came."""


class FileWriteError(CocoError, OSError):
    """A file that cannot be written (an image, a video)."""


class MissingPackageError(CocoError, ImportError):
    """A Python package a feature needs is not installed or not built; the message says how to get it."""


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


class GeometryError(CocoError, ValueError):
    """Numbers that are not the geometry they should be: not a rotation, not a homogeneous transform, a
    degenerate camera or screen, vertices that do not match their faces."""


class EdgeError(CocoError, ValueError):
    """An edge or a joint value the transformation graph refuses: one frame twice, a zero axis, a history
    capacity below 1, a non-finite stamp or joint value, joint names and positions of different lengths."""


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


class BagError(CocoError):
    """A bag that cannot be read (or written) as asked.

    ``path`` is the file or folder concerned, ``offset`` the byte position in that file where the
    problem was found (None when it is not about a position, e.g. a missing folder), ``detail`` says
    what was expected and what was found.
    """

    def __init__(self, path: str | Path, detail: str, offset: int | None = None) -> None:
        self.path = str(path)
        self.offset = offset
        self.detail = detail
        where = self.path if offset is None else f"{self.path} at byte {offset}"
        super().__init__(f"{where}: {detail}")


class MessageTypeError(BagError):
    """A message type whose Python class cannot be found (its package is not installed)."""


class BagFormatError(CocoError, ValueError):
    """Bag content that cannot be decoded (an MCAP record or chunk, a QoS profile); the reader adds the
    file and the byte where it is, as a :class:`BagError`."""


class MessageError(CocoError, ValueError):
    """A ROS message, message type name or value that cannot be converted: malformed CDR, a layout the
    data does not fill, a time out of range, a type without a converter."""


class SpecError(CocoError, ValueError):
    """A topic spec that cannot be used; the message names the spec and the expected syntax."""


class ReplayError(CocoError, ValueError):
    """A replay or recording option that cannot be used: a negative offset or rate, a bad remapping or
    topic spec, an unknown compression."""


class RecordingError(CocoError, ValueError):
    """A joint_recorder file that cannot be read: says file:line and what was expected."""


class SessionError(CocoError, ValueError):
    """Arguments that cannot give a session (duration too short, no reachable layout...)."""


class DisplayError(CocoError, RuntimeError):
    """A window or an OpenGL context that cannot be created."""


class MeshLoadError(CocoError, ValueError):
    """A mesh file that cannot be found or read, or a primitive with a wrong size."""


class StructureError(CocoError, ValueError):
    """A cloud that the requested structure cannot be built from."""


class SurfaceExpressionError(CocoError, ValueError):
    """A surface expression that cannot be parsed or built; says where and what was expected."""


class HapticDeviceError(CocoError, ValueError):
    """A simulated haptic device that cannot run (a hand trajectory it cannot follow, an empty workspace),
    or a recorded run of a device too short to plot."""


class ImageError(CocoError, ValueError):
    """Image, RGB-D frame or point cloud data that does not match its format, size or intrinsics, or
    lacks the intrinsics its use needs."""


class ConversionError(CocoError, ValueError):
    """A conversion that has no meaning (colour to depth and back)."""


class KeyFileError(CocoError, ValueError):
    """The application's key cannot be had: no such file, a file others can read, not a key."""


class PacketError(CocoError, ValueError):
    """A packet that cannot be decoded or taken; ``kind`` is ``garbage``, ``truncated`` or
    ``out_of_order`` (a sequence number at or before the last one taken)."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


class CameraError(CocoError):
    """A camera or a recording that cannot be opened or read."""
