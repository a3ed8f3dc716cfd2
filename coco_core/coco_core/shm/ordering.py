"""Which path the value rings take between processes: unlocked where the CPU keeps stores in order,
locked everywhere else.

A ring (:mod:`.channel`) is a sequence lock: the writer stores the value, then the slot's stamp,
then the ``stored`` counter; the reader loads them the other way round, and a stamp that changed
during its copy makes it read again. That is only sound when another CPU sees the stores in the
order they were made: x86-64 guarantees it (total store order), and CPython's single stores
through a memoryview are made in program order. ARM (aarch64: a Jetson), POWER and RISC-V may
reorder stores, and CPython exposes no memory fence, so there a reader could see the new counter
before the value it counts. On those CPUs each ring takes the *locked* path instead: every access
to its shared words, on both sides, inside a :class:`~.segment.SegmentLock` (whose kernel lock is a
full barrier), as the pooled frames' slots always do.

The launcher decides once per launch (:class:`~coco_core.shm.Arena`) and every process follows the
channel's description, so both ends of a ring always take the same path. ``COCO_SHM_LOCKED=1``
forces the locked path on any CPU (to test it on x86-64, or to rule the unlocked path out);
unset, empty or ``0`` leave the choice to the CPU.
"""

from __future__ import annotations

import os
import platform
from collections.abc import Mapping

from ..errors import ConfigError

FORCE_LOCKED = "COCO_SHM_LOCKED"
"""The environment variable that forces the locked path (``1``)."""
STORE_ORDERED = frozenset({"x86_64", "amd64", "i386", "i486", "i586", "i686", "x86"})
"""``platform.machine()`` names of CPUs whose stores reach other CPUs in program order (x86's total
store order): the rings' unlocked path is sound there only."""


def rings_locked(machine: str | None = None, environ: Mapping[str, str] = os.environ) -> bool:
    """Whether the rings of a launch take the locked path: on a CPU outside :data:`STORE_ORDERED`
    (``machine``: ``platform.machine()``), or when ``COCO_SHM_LOCKED=1``."""
    forced = environ.get(FORCE_LOCKED, "").strip()
    if forced not in ("", "0", "1"):
        raise ConfigError(f"{FORCE_LOCKED}={forced!r}: expected 1 (the locked path on any CPU), or 0 or nothing "
                          "(chosen by the CPU)")
    cpu = (machine if machine is not None else platform.machine()).lower()
    return forced == "1" or cpu not in STORE_ORDERED
