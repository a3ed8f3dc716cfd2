"""The platform's floor for a 1 kHz real-time loop, without CoCo: what ``bench_haptics.py`` sets
beside the haptic process's figures in the same loaded run, to tell the runtime's misses from the
machine's.

One thread, the process's only one, does what a CoCo periodic driver does with the haptic file's
real-time settings, and nothing else: ``SCHED_FIFO`` at ``priority``, memory locked (``mlockall``),
the garbage collector off; each period it sleeps on an event until ``spin`` seconds before the
deadline, spins to it, and does about as much work as the haptic components (``work`` seconds of
arithmetic). It prints one JSON line: cycles, the deadlines missed (a wake-up later than the next
deadline), and the wake-up lateness p50/p99/max in microseconds, the runtime's own figure (spin exit
minus deadline).

    python bench/_bare_loop.py SECONDS SPIN WORK PRIORITY
"""

from __future__ import annotations

import ctypes
import gc
import json
import os
import sys
import threading
import time

import numpy as np

MCL_CURRENT, MCL_FUTURE = 1, 2


def main() -> None:
    seconds, spin, work, priority = (float(word) for word in sys.argv[1:5])
    granted = []
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
        granted.append("SCHED_FIFO")
    except OSError:
        pass
    if ctypes.CDLL(None, use_errno=True).mlockall(MCL_CURRENT | MCL_FUTURE) == 0:
        granted.append("mlockall")
    gc.disable()
    event = threading.Event()
    period = 1e-3
    lateness = np.empty(int(seconds / period) + 10)
    cycles = missed = 0
    deadline = time.perf_counter() + period
    end = deadline + seconds
    while deadline < end and cycles < lateness.size:
        remaining = deadline - time.perf_counter()
        if remaining > spin:
            event.wait(remaining - spin)
        while (now := time.perf_counter()) < deadline:
            pass
        lateness[cycles] = now - deadline
        cycles += 1
        busy = now + work
        total = 0.0
        while time.perf_counter() < busy:
            total += 1.0
        deadline += period
        while deadline <= time.perf_counter():  # a deadline passed while working or waking: skipped
            deadline += period
            missed += 1
    late = lateness[:cycles] * 1e6
    print(json.dumps({"cycles": cycles, "missed": missed, "p50_us": float(np.percentile(late, 50)),
                      "p99_us": float(np.percentile(late, 99)), "max_us": float(late.max()), "granted": granted}))


if __name__ == "__main__":
    main()
