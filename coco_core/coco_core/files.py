"""Reading a file named by a user: a regular file of bounded size, or a clear error.

An application file, an include, a URDF or a mesh is named by whoever writes the application, so
the name may point anywhere: ``/dev/zero`` and ``/dev/urandom`` never end, a FIFO blocks its reader
for ever, and a huge file exhausts memory before any parser complains. Every such read goes through
:func:`read_regular_file`, which opens without blocking, refuses what is not a regular file, and
stops reading past the limit (the size is checked again while reading, since a file may grow).
"""

from __future__ import annotations

import os
import stat

from .errors import FileReadError, FileWriteError

MiB = 1024 * 1024
APPLICATION_FILE_LIMIT = 16 * MiB
"""Largest application file (or include) read: hand-written XML is a few kB."""
URDF_LIMIT = 64 * MiB
"""Largest URDF read: robot descriptions with inline geometry reach a few MB."""
MESH_LIMIT = 512 * MiB
"""Largest mesh file read: the Baxter meshes total about 30 MB."""
DATA_FILE_LIMIT = 64 * MiB
"""Largest table or description a component attribute names (a hand trajectory or poses CSV, camera
intrinsics, a TUM sequence's lists): read whole and parsed in Python, so a wrong path to a large
file must stop here (an hour of a 1 kHz trajectory is about 150 MB: give a recording as a bag)."""


def read_regular_file(path: str | os.PathLike[str], limit: int, what: str = "file") -> bytes:
    """The bytes of the regular file at ``path``, at most ``limit`` of them.

    ``what`` names the file in errors ("application file", "URDF", ...).
    """
    name = os.fspath(path)
    descriptor = _open_checked(name, limit, what)
    try:
        os.set_blocking(descriptor, True)
        chunks: list[bytes] = []
        size = 0
        while chunk := os.read(descriptor, min(MiB, limit + 1 - size)):
            chunks.append(chunk)
            size += len(chunk)
            if size > limit:
                raise FileReadError(f"{what} {name} grew past the limit of {limit} bytes while it was read")
        return b"".join(chunks)
    except OSError as error:
        if isinstance(error, FileReadError):
            raise
        raise FileReadError(f"cannot read {what} {name}: {error.strerror}") from None
    finally:
        os.close(descriptor)


def check_regular_file(path: str | os.PathLike[str], limit: int, what: str = "file") -> None:
    """Raise :class:`FileReadError` unless ``path`` is a regular file of at most ``limit`` bytes
    that can be opened for reading: the checks of :func:`read_regular_file` without the read, for a
    loader that checks a name long before the file is read (``<urdf>`` in an application, a file
    attribute under ``--check``)."""
    os.close(_open_checked(os.fspath(path), limit, what))


def _open_checked(name: str, limit: int, what: str) -> int:
    """A descriptor open for reading on ``name``, once it is known to be a regular file within
    ``limit``. ``O_NONBLOCK`` keeps ``open`` from waiting for a FIFO's writer; the type is checked
    on the open descriptor, so that what is read is what was checked."""
    try:
        descriptor = os.open(name, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as error:
        raise FileReadError(f"cannot read {what} {name}: {error.strerror}") from None
    try:
        _check(os.fstat(descriptor), name, limit, what)
    except BaseException:
        os.close(descriptor)
        raise
    return descriptor


def check_writable_file(path: str | os.PathLike[str], what: str = "file") -> None:
    """Raise :class:`FileWriteError` unless ``path`` can be opened for appending: an existing file
    (or device, such as ``/dev/null``) that may be written, or a new name in a folder that exists
    and may be written. For ``--check``, which must find what the run would refuse, without
    creating the file."""
    name = os.fspath(path)
    if os.path.exists(name):
        if os.path.isdir(name):
            raise FileWriteError(f"{what} {name} is a directory; expected a file name")
        if not os.access(name, os.W_OK):
            raise FileWriteError(f"{what} {name} cannot be written (permission denied)")
        return
    folder = os.path.dirname(os.path.abspath(name))
    if not os.path.isdir(folder):
        raise FileWriteError(f"{what} {name}: its folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise FileWriteError(f"{what} {name}: its folder {folder} cannot be written (permission denied)")


def _check(status: os.stat_result, name: str, limit: int, what: str) -> None:
    if not stat.S_ISREG(status.st_mode):
        raise FileReadError(f"{what} {name} is {_kind(status.st_mode)}, not a regular file")
    if status.st_size > limit:
        raise FileReadError(f"{what} {name} has {status.st_size} bytes, more than the limit of {limit}")


def _kind(mode: int) -> str:
    for test, kind in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return kind
    return "a special file"
