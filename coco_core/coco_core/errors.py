"""Errors that point at their cause: the file and line, or the component, and what was expected."""

from __future__ import annotations

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


def did_you_mean(name: str, valid: "list[str] | set[str] | dict[str, object]") -> str:
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
