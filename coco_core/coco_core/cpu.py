"""CPU share: the CPU time a process or a thread used over the wall time it has lived, in cores.

Why: an application of several processes on a small machine (the palpation app: six processes on
two cores) has the machine's cores as its whole budget, and a figure per process shows who spends
it. Per thread it shows *what* spends it: a thread near one core is busy all the time, which only
the haptic loop (it spins before each deadline) should be; any other is a busy wait or an activity
that cannot keep up.

Both come from Linux's /proc (``/proc/PID/stat`` and ``/proc/self/task/TID/stat``: user + system
ticks and the start time; ``/proc/uptime``): the share is over the whole life, start-up included,
since nothing else knows when a process's "run" began. Off Linux, :func:`process_cpu` falls back to
this process's ``os.times`` over the time since ``since`` and :func:`thread_cpu` has no threads.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass

TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
"""Clock ticks per second of /proc's times (100 on Linux: a 10 ms resolution)."""


@dataclass(frozen=True)
class CpuUse:
    """CPU seconds (user + system) used over ``wall`` seconds lived."""

    seconds: float
    wall: float

    @property
    def cores(self) -> float:
        """The share in cores: 1.0 is one core busy all the time (a process of threads may exceed it)."""
        return self.seconds / self.wall if self.wall > 0 else 0.0


def _stat(path: str) -> list[str] | None:
    """The fields of a /proc stat file after the command name (which may hold spaces and parentheses)."""
    try:
        with open(path) as stat:
            return stat.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None


def _uptime() -> float | None:
    try:
        with open("/proc/uptime") as uptime:
            return float(uptime.read().split()[0])
    except (OSError, ValueError, IndexError):
        return None


def _use(fields: list[str], uptime: float) -> CpuUse:
    """utime and stime are the 14th and 15th fields of stat, starttime the 22nd (after pid and comm:
    indices 11, 12 and 19)."""
    return CpuUse((int(fields[11]) + int(fields[12])) / TICKS, max(uptime - int(fields[19]) / TICKS, 0.0))


def process_cpu(pid: int | None = None, since: float | None = None) -> CpuUse | None:
    """The CPU use of process ``pid`` (None: this one) over its life; None when it is gone. Off Linux,
    this process's only, over the time since ``since`` (a ``perf_counter`` time; None: unknown)."""
    fields = _stat(f"/proc/{'self' if pid is None else pid}/stat")
    uptime = _uptime()
    if fields is not None and uptime is not None:
        return _use(fields, uptime)
    if pid is not None and pid != os.getpid():
        return None
    times = os.times()
    return CpuUse(times.user + times.system, time.perf_counter() - since if since is not None else 0.0)


def thread_cpu() -> list[tuple[str, CpuUse]]:
    """The CPU use of every thread of this process over its life, busiest first, each named by its
    Python name (``coco:ACTIVITY`` for an activity's thread, ``MainThread``) or, for a thread that
    Python did not start (DDS's, ZeroMQ's), by the OS's name in brackets."""
    uptime = _uptime()
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return []
    if uptime is None:
        return []
    names = {thread.native_id: thread.name for thread in threading.enumerate()}
    rows = []
    for tid in tids:
        fields = _stat(f"/proc/self/task/{tid}/stat")
        if fields is None:  # the thread ended meanwhile
            continue
        name = names.get(int(tid))
        if name is None:
            try:
                with open(f"/proc/self/task/{tid}/comm") as comm:
                    name = f"[{comm.read().strip()}]"
            except OSError:
                continue
        rows.append((name, _use(fields, uptime)))
    return sorted(rows, key=lambda row: -row[1].seconds)


def _children() -> dict[int, list[int]]:
    """Parent pid -> the pids of its children, from every process's stat (no kernel option needed)."""
    children: dict[int, list[int]] = {}
    try:
        pids = [int(entry) for entry in os.listdir("/proc") if entry.isdigit()]
    except OSError:
        return children
    for pid in pids:
        fields = _stat(f"/proc/{pid}/stat")
        if fields is not None:
            children.setdefault(int(fields[1]), []).append(pid)
    return children


def _name(pid: int, processes: Iterable[str]) -> str:
    """A child process of the process level calls itself ``coco:<process>`` (its comm, which the OS
    cuts at 15 bytes: the one of ``processes`` it begins); another by its comm in brackets."""
    try:
        with open(f"/proc/{pid}/comm") as comm:
            name = comm.read().strip()
    except OSError:
        return f"[{pid}]"
    if not name.startswith("coco:"):
        return f"[{name}]"
    name = name[len("coco:"):]
    matches = [process for process in processes if process.startswith(name)]
    return matches[0] if len(matches) == 1 else name


def application_cpu(launcher: int, processes: Iterable[str] = ()) -> dict[str, float]:
    """The cores of the launcher (pid ``launcher``) and of each process under it (the process
    level's children by their ``<process>`` name, one of ``processes``; any other, such as an
    encoder a component started, by its command in brackets): the application's whole budget on
    this host. Empty off Linux."""
    use = process_cpu(launcher)
    if use is None:
        return {}
    shares = {"launcher": use.cores}
    tree = _children()
    waiting = list(tree.get(launcher, []))
    while waiting:
        pid = waiting.pop(0)
        child = process_cpu(pid)
        if child is not None:
            name = _name(pid, processes)
            shares[name if name not in shares else f"{name} {pid}"] = child.cores
        waiting += tree.get(pid, [])
    return shares
