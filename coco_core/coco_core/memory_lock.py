"""Memory locked in RAM for a real-time process (``<process lock_memory="true">``).

A page of a 1 kHz loop's memory that the kernel swapped out, or a new page touched for the first
time, costs a page fault in the middle of a cycle: microseconds, or milliseconds from disk.
``mlockall(MCL_CURRENT | MCL_FUTURE)`` makes every page the process has, and every page it maps
later, resident at once and keeps it so, as real-time Linux guides prescribe. It needs
``CAP_IPC_LOCK`` (root) or a memory-lock limit (``ulimit -l``) as large as the process; without
them the process runs as before, with one warning that says so.
"""

from __future__ import annotations

import ctypes
import os

MCL_CURRENT = 1
MCL_FUTURE = 2


def lock_memory() -> str | None:
    """Lock the process's memory now and in future; None, or why the OS refused."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        result = libc.mlockall(MCL_CURRENT | MCL_FUTURE)
    except (OSError, AttributeError) as error:
        return f"mlockall is not available here ({error})"
    if result != 0:
        code = ctypes.get_errno()
        return (f"mlockall refused by the OS: {os.strerror(code)} (it needs CAP_IPC_LOCK, e.g. root, or a "
                "memory-lock limit as large as the process: ulimit -l); the process runs unlocked")
    return None
