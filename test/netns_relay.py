"""The impaired link of the simulated network: a hub between TAP devices that delays and drops frames.

Why not ``tc qdisc ... netem``: the kernel of the machines this project is tested on is built without
it (``CONFIG_NET_SCH_NETEM is not set``) and there is no other packet scheduler that adds delay and
loss. TAP devices need only ``/dev/net/tun``, which a user namespace may use, so the impairment is
done in user space instead: every host of an impaired network gets a TAP device (its ``eth0``)
whose other end, a file descriptor, is a port of this hub. A frame read from one port is written to
every other port (a hub, not a switch: ARP, broadcast and multicast, which DDS discovery needs, pass
like anything else) ``delay_s`` later, or dropped with probability ``loss``, drawn from a seeded RNG
per frame and destination, so a run can be repeated. What it forwarded and dropped is counted per
direction: a test reads that traffic really went through the link and was really impaired.

It runs in the keeper's select loop (``netns_keeper.py``): :meth:`Hub.fds` to wait on,
:meth:`Hub.timeout` until the next delayed frame is due, :meth:`Hub.readable` and :meth:`Hub.flush`.
"""

from __future__ import annotations

import errno
import fcntl
import heapq
import itertools
import os
import random
import struct
import time
from dataclasses import dataclass, field

TUNSETIFF = 0x400454CA
IFF_TAP = 0x0002
IFF_NO_PI = 0x1000
MAX_FRAME = 65536


def open_tap(name: str) -> int:
    """A new TAP device ``name`` in the caller's network namespace, and its file descriptor (the device
    lives as long as the descriptor; ``ip link set NAME netns PID`` moves it with the descriptor kept)."""
    fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK | os.O_CLOEXEC)
    try:
        fcntl.ioctl(fd, TUNSETIFF, struct.pack("16sH", name.encode(), IFF_TAP | IFF_NO_PI))
    except OSError:
        os.close(fd)
        raise
    return fd


@dataclass
class Impairment:
    """What the link does to every frame: a fixed one-way delay and an independent drop probability."""

    delay_s: float = 0.0
    loss: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.delay_s < 0:
            raise ValueError(f"delay_s must be >= 0, got {self.delay_s}")
        if not 0.0 <= self.loss < 1.0:
            raise ValueError(f"loss must be in [0, 1), got {self.loss}")


@dataclass
class Direction:
    """The frames of one direction (``robot->graphics``)."""

    forwarded: int = 0
    dropped: int = 0
    bytes: int = 0
    failed: int = 0
    """Frames the destination refused (its interface down): lost too, but not by the impairment."""


@dataclass
class Hub:
    """Ports by host name (TAP file descriptors); frames from one go, delayed or dropped, to the others."""

    ports: dict[str, int]
    impairment: Impairment = field(default_factory=Impairment)
    directions: dict[str, Direction] = field(init=False)

    def __post_init__(self) -> None:
        self._rng = random.Random(self.impairment.seed)
        self._queue: list[tuple[float, int, str, str, bytes]] = []
        self._order = itertools.count()
        self._names = {fd: name for name, fd in self.ports.items()}
        self.directions = {f"{a}->{b}": Direction() for a in self.ports for b in self.ports if a != b}

    def set_impairment(self, impairment: Impairment) -> None:
        """Change what the link does from now on (frames already delayed keep their time)."""
        self.impairment = impairment
        self._rng = random.Random(impairment.seed)

    def fds(self) -> list[int]:
        return list(self._names)

    def timeout(self, now: float) -> float | None:
        """Seconds until the next delayed frame is due (None: nothing waits)."""
        return max(0.0, self._queue[0][0] - now) if self._queue else None

    def readable(self, fd: int, now: float) -> None:
        """Take every frame waiting on ``fd`` and queue (or drop) a copy for each other port."""
        source = self._names[fd]
        while True:
            try:
                frame = os.read(fd, MAX_FRAME)
            except BlockingIOError:
                return
            for dest in self.ports:
                if dest == source:
                    continue
                direction = self.directions[f"{source}->{dest}"]
                if self.impairment.loss and self._rng.random() < self.impairment.loss:
                    direction.dropped += 1
                    continue
                heapq.heappush(self._queue, (now + self.impairment.delay_s, next(self._order), source, dest, frame))

    def flush(self, now: float) -> None:
        """Write every frame that is due."""
        while self._queue and self._queue[0][0] <= now:
            _, _, source, dest, frame = heapq.heappop(self._queue)
            direction = self.directions[f"{source}->{dest}"]
            try:
                os.write(self.ports[dest], frame)
            except OSError as error:
                if error.errno not in (errno.EIO, errno.EAGAIN, errno.ENOBUFS, errno.EINVAL):
                    raise
                direction.failed += 1
                continue
            direction.forwarded += 1
            direction.bytes += len(frame)

    def counters(self) -> dict[str, dict[str, int]]:
        return {name: vars(direction).copy() for name, direction in self.directions.items()}

    @staticmethod
    def now() -> float:
        return time.monotonic()
