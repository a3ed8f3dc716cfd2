"""POSIX shared-memory segments of one launch, and the sweep that removes what a dead launch left.

Segments are opened with ``shm_open`` and mapped with ``mmap`` directly rather than through
``multiprocessing.shared_memory``: Python 3.11's ``SharedMemory`` registers every *attached* segment
with the resource tracker of the attaching process, which then unlinks it (and warns) when that
process exits, although other processes still use it. Here only the launcher (or, when the launcher
was killed, its orphaned children) unlinks, and every segment of a launch shares the name prefix
``coco.<launch id>.``, so that :func:`sweep` finds them all in ``/dev/shm``.
"""

from __future__ import annotations

import fcntl
import mmap
import os
import threading
from pathlib import Path

import _posixshmem

SHM_DIR = Path("/dev/shm")
SHM_PATH = "/dev/shm/"
"""The same, for building paths on the large values' path (pathlib costs microseconds)."""
PREFIX = "coco."


def free_bytes() -> int:
    """Bytes that new segments may still take (``/dev/shm``'s free space): a segment is sparse until
    written, so one larger than this is made, then fails when its pages are touched."""
    status = os.statvfs(SHM_DIR)
    return status.f_bavail * status.f_frsize


def segment_name(launch: str, index: int | str) -> str:
    """The name of a launch's segment (without the leading slash shm_open takes)."""
    return f"{PREFIX}{launch}.{index}"


class Segment:
    """One mapped shared-memory segment."""

    def __init__(self, name: str, size: int | None = None) -> None:
        """Create ``name`` with ``size`` bytes (zeroed), or attach to it when ``size`` is None."""
        self.name = name
        if size is not None:
            fd = _posixshmem.shm_open("/" + name, os.O_CREAT | os.O_EXCL | os.O_RDWR, mode=0o600)
            try:
                os.ftruncate(fd, size)
            except OSError:
                os.close(fd)
                _posixshmem.shm_unlink("/" + name)
                raise
        else:
            fd = _posixshmem.shm_open("/" + name, os.O_RDWR, mode=0o600)
        try:
            self.size = os.fstat(fd).st_size
            self.map = mmap.mmap(fd, self.size)
            self.fd = os.dup(fd)
            """Kept open for file locks (``fcntl.flock``) on the segment."""
        finally:
            os.close(fd)
        self.view = memoryview(self.map)

    def close(self) -> None:
        """Unmap (views into it must be gone: numpy arrays over it keep it mapped until collected)."""
        try:
            self.view.release()
            self.map.close()
        except BufferError:  # a numpy view still uses it: the mapping goes with the last view
            pass
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


def shm_open(name: str, create: bool = False, write: bool = True) -> int:
    """A descriptor of segment ``name``: a new one (it must not exist yet), or an existing one."""
    flags = (os.O_CREAT | os.O_EXCL if create else 0) | (os.O_RDWR if write else os.O_RDONLY)
    return _posixshmem.shm_open("/" + name, flags, mode=0o600)


def rename(old: str, new: str) -> bool:
    """Give segment ``old`` the name ``new`` (replacing a segment of that name); False when there
    is no ``old``."""
    try:
        os.rename(SHM_PATH + old, SHM_PATH + new)
    except FileNotFoundError:
        return False
    return True


def unlink(name: str) -> None:
    """Remove a segment's name (mappings stay valid until unmapped); a missing one is fine."""
    try:
        _posixshmem.shm_unlink("/" + name)
    except FileNotFoundError:
        pass


def leftovers(launch: str) -> list[str]:
    """The segments of ``launch`` still in /dev/shm."""
    prefix = segment_name(launch, "")
    try:
        return sorted(entry.name for entry in SHM_DIR.iterdir() if entry.name.startswith(prefix))
    except OSError:
        return []


def sweep(launch: str) -> list[str]:
    """Unlink every segment of ``launch`` (what a launcher killed with SIGKILL left); their names."""
    names = leftovers(launch)
    for name in names:
        unlink(name)
    return names


class SegmentLock:
    """A critical section over one segment, between processes and between the threads of one: a
    thread lock, then an exclusive ``flock`` on the segment's descriptor. A ``flock`` belongs to
    the open file, which the threads of a process share, hence the thread lock; each process (each
    :class:`Segment`) opens the segment itself, so their ``flock`` calls exclude each other. The
    kernel's lock is a full barrier: what one holder stored is what the next one loads, on any CPU
    (which the rings' unlocked path cannot promise where stores may be reordered, see
    :mod:`.ordering`)."""

    __slots__ = ("fd", "_threads")

    def __init__(self, segment: Segment) -> None:
        self.fd = segment.fd
        self._threads = threading.Lock()

    def __enter__(self) -> None:
        self._threads.acquire()
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX)
        except BaseException:
            self._threads.release()
            raise

    def __exit__(self, *exc: object) -> None:
        fcntl.flock(self.fd, fcntl.LOCK_UN)
        self._threads.release()
