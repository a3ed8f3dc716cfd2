"""Thread placement: CPU affinity, real-time class and priority, nice value.

Applied by each activity's thread to itself at start. The OS may refuse (no CAP_SYS_NICE, a core that
does not exist, a container's cpuset): the activity still runs, and each refusal becomes one warning
that says what was asked, what the OS said and how to get it.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .model import ScheduleSpec

REALTIME_CLASSES = ("FIFO", "RR")
"""The real-time scheduling classes a ``<schedule realtime=...>`` may ask for."""


@dataclass
class SchedulingRequest:
    """What an activity asks of the OS for its thread."""

    affinity: list[int] = field(default_factory=list)
    """Cores this thread may run on; empty: any core not reserved exclusively by another activity."""
    exclusive: bool = False
    """Whether ``affinity`` cores are reserved for this thread (others are kept off them)."""
    realtime: str = "none"
    """``none``, ``FIFO`` or ``RR``."""
    priority: int | None = None
    """Real-time priority (1-99); only meaningful with ``realtime`` FIFO or RR."""
    nice: int | None = None
    """Nice value (-20..19) of a normal, non-real-time thread."""

    @classmethod
    def of(cls, schedule: ScheduleSpec) -> SchedulingRequest:
        """What the file's ``<schedule>`` asks of the OS (the builder and the deployment plan read it)."""
        return cls(affinity=list(schedule.exclusive_affinity or schedule.affinity),
                   exclusive=bool(schedule.exclusive_affinity), realtime=schedule.realtime or "none",
                   priority=schedule.priority, nice=schedule.nice)

    def describe(self) -> list[str]:
        """What it asks, in the words ``--check`` and each process's log print beside the schedule
        (nothing when it asks nothing): a real-time loop's settings are what its user checks first."""
        words = []
        if self.realtime != "none":
            words.append(f"SCHED_{self.realtime}" + (f" priority {self.priority}" if self.priority is not None else ""))
        if self.nice is not None:
            words.append(f"nice {self.nice}")
        if self.affinity:
            words.append(("exclusive " if self.exclusive else "") + f"cores {','.join(map(str, self.affinity))}")
        return words


def available_cores() -> set[int]:
    """Cores this process may use."""
    if hasattr(os, "sched_getaffinity"):
        return set(os.sched_getaffinity(0))
    return set(range(os.cpu_count() or 1))


def apply_to_current_thread(request: SchedulingRequest, reserved: set[int]) -> list[str]:
    """Apply ``request`` to the calling thread; return one warning per thing the OS refused.

    ``reserved`` are cores other activities hold exclusively: a thread without its own affinity is
    kept off them.
    """
    warnings: list[str] = []
    cores = available_cores()
    if request.affinity:
        wanted = set(request.affinity)
        missing = wanted - cores
        if missing:
            warnings.append(f"affinity: core(s) {sorted(missing)} not available to this process "
                            f"(available: {sorted(cores)}); using {sorted(wanted & cores) or 'any core'}")
        wanted &= cores
    else:
        wanted = cores - reserved
        if not wanted:
            warnings.append(f"affinity: every core {sorted(cores)} is reserved exclusively by other "
                            "activities; this one shares them")
            wanted = cores
    if wanted and wanted != cores and hasattr(os, "sched_setaffinity"):
        try:
            os.sched_setaffinity(0, wanted)  # 0: the calling thread on Linux
        except OSError as error:
            warnings.append(f"affinity {sorted(wanted)} refused by the OS: {error.strerror}")
    if request.realtime in REALTIME_CLASSES:
        warnings.extend(set_realtime(request.realtime, request.priority))
    elif request.priority is not None:
        warnings.append(f"priority {request.priority} ignored: it needs realtime=\"FIFO\" or \"RR\" "
                        "(use nice for normal threads)")
    if request.nice is not None:
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), request.nice)
        except OSError as error:
            warnings.append(f"nice {request.nice} refused by the OS: {error.strerror} "
                            "(negative values need CAP_SYS_NICE)")
    return warnings


def set_realtime(kind: str, priority: int | None) -> list[str]:
    """Put the calling thread in real-time class ``kind`` (FIFO or RR) at ``priority`` (the lowest when
    None); the OS's refusal as a warning. Threads it starts afterwards inherit the class."""
    if not hasattr(os, "sched_setscheduler"):
        return [f"realtime {kind} is not available on this OS"]
    policy = os.SCHED_FIFO if kind == "FIFO" else os.SCHED_RR
    low, high = os.sched_get_priority_min(policy), os.sched_get_priority_max(policy)
    value = low if priority is None else priority
    if not low <= value <= high:
        return [f"realtime {kind} priority {value} out of range {low}..{high}; not applied"]
    try:
        os.sched_setscheduler(0, policy, os.sched_param(value))
    except OSError as error:
        return [f"realtime {kind} priority {value} refused by the OS: {error.strerror} "
                "(needs root or CAP_SYS_NICE, and a real-time budget in containers)"]
    return []
