"""The interpreter lock's ceiling in a process that runs a real-time activity.

Why: a thread of CPython runs Python only while it holds the process's one interpreter lock, and the
lock has no priority inheritance. A 1 kHz loop in SCHED_FIFO that wakes while another thread of its
process holds the lock sleeps until that thread lets go, and that thread, in the normal class, waits
for a core behind every normal thread of the machine: on the loaded 2-core machine of issue 34 a
scheduler trace of the palpation app showed the haptic loop asleep 2-9.6 ms at a time, woken each time
by another thread of its own process handing the lock back (most likely the relay that moves the
search structures), a thread that had been runnable but preempted by other processes meanwhile:
9-31 deadlines missed a run with a worst case of 9-20 ms, while the same loop alone in its process
missed none. Two causes add up:

- priority inversion: the holder is preempted by normal work elsewhere while the loop waits for it;
- CPython's switch interval: a waiting thread asks the holder to let go only after 5 ms, so a holder
  that runs Python (unpickling a structure's parts, a relay's cycle) keeps the lock that long.

The remedy is the priority ceiling protocol applied once to the whole process. Before it builds its
part, a process with a real-time activity puts each of its threads in SCHED_FIFO at the lowest
real-time priority, which every thread it starts later inherits (the triggered activities', the
control link's, timers'); each real-time activity raises its own thread above that as before. While
one of those threads holds the lock no normal thread of the machine preempts it, and the loop still
preempts it whenever it does not need the lock. The switch interval goes down to
:data:`SWITCH_INTERVAL`, so the loop that wakes to a held lock has it back within a fraction of its
spin. The cost: what the other threads of such a process do runs ahead of every normal thread of the
machine, so a real-time process keeps beside its loop only short work (a relay's hand-over, a
transform's update); anything long belongs in another process, as the process level has it.

Only a ``<process>`` of the launcher does this: the launcher's own process runs everything else of
the application (and an rclpy executor), which must not become real-time. The deployment plan
decides it once, from the activities (:class:`~coco_core.deployment.RealtimeClass`, which ``--check``
prints on the process's line), and the child applies what the plan says.
"""

from __future__ import annotations

import os
import sys
from typing import Sequence

from .thread_placement import set_realtime

CEILING_PRIORITY = 1
"""The SCHED_FIFO priority of a real-time process's other threads: the lowest, above every normal thread."""

SWITCH_INTERVAL = 100e-6
"""s a thread waits for the held interpreter lock before it asks the holder to let it go (CPython's
default is 5 ms, five periods of a 1 kHz loop; 0.1 ms is a sixth of the haptic loop's spin)."""


def applies(priorities: Sequence[int]) -> bool:
    """Whether a ``<process>`` whose real-time activities ask for ``priorities`` (the deployment
    plan's :class:`~coco_core.deployment.RealtimeClass`) gets the ceiling: it has one, and each
    leaves room below it."""
    return bool(priorities) and min(priorities) > CEILING_PRIORITY


def raise_lock_holders(priorities: Sequence[int]) -> tuple[bool, list[str]]:
    """Apply the ceiling to every thread of the process (and so to every thread started later) when
    ``priorities`` holds a real-time activity's: whether it was applied, and one warning per thing
    that stood in its way (the OS's refusal, or a loop whose priority leaves no room below it)."""
    if not priorities:
        return False, []
    if not applies(priorities):
        return False, [f"a real-time activity at priority {min(priorities)} leaves no real-time priority "
                       f"below it for the other threads of its process: they stay normal, and the loop may "
                       f"wait for the interpreter lock behind the machine's normal threads "
                       f"(give it a priority above {CEILING_PRIORITY})"]
    refused = set_realtime("FIFO", CEILING_PRIORITY)
    if refused:
        return False, refused
    for thread in os.listdir("/proc/self/task"):  # those started already (the signal watcher)
        try:
            os.sched_setscheduler(int(thread), os.SCHED_FIFO, os.sched_param(CEILING_PRIORITY))
        except ProcessLookupError:  # it ended meanwhile
            pass
    sys.setswitchinterval(SWITCH_INTERVAL)
    return True, []


def describe() -> str:
    """What a process with the ceiling applied says in its log."""
    return (f"its other threads in SCHED_FIFO priority {CEILING_PRIORITY} and the interpreter lock's switch "
            f"interval {SWITCH_INTERVAL * 1e3:g} ms (the lock's ceiling for its real-time activity)")
