"""Authenticated messages between hosts: who sent it, that nobody changed it, that it is new.

Any participant of a DDS domain can publish on any topic of it. So every message between the hosts
of an application (the launch's heartbeats and calls, every sample of a connection) carries a
:class:`Seal`: the sending host's name, a random ``session`` number of the sending end's launch, a
``counter`` that the end increments for every message, its wall-clock time, and a MAC (keyed
BLAKE2b-256) over all of these, the topic and the message's own fields, keyed with the
application's key (:mod:`.key`). The receiving end (:class:`Verifier`, one per topic) refuses:

- a message whose MAC is wrong (sent without the key, or changed on the way);
- one from a host that the application file does not declare, or that should not write on that
  topic (a connection's samples come from its writer's host alone);
- a replay: a counter already seen, or older than the last :data:`WINDOW` (a best-effort topic may
  reorder a few), or a wall time more than :data:`FRESH` seconds from the receiver's (a message
  recorded during an earlier run of the application);
- a second session for the same host and topic: two launches claim the same host name (both with
  the key: a host started twice), which is reported once and refused from then on.

Refused messages never reach the application and never stop anything: each is counted by topic,
claimed sender and reason (:class:`Refusals`, in the profile's "refused from the network" table),
the first of each kind logged with a warning.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import math
import secrets
import struct
import threading
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from .key import AppKey

log = logging.getLogger("coco.hosts")

FRESH = 30.0
"""Seconds a message's wall-clock time may differ from its receiver's: the hosts' clocks must agree
within this (NTP does to milliseconds); a message recorded and sent again later is refused."""
WINDOW = 64
"""How many counters before the highest seen are still accepted once each (reordering)."""
MAX_NAME = 64
"""Characters of a claimed host name quoted in a log or a profile (the rest is cut)."""
MAX_ROWS = 64
"""Distinct (topic, claimed sender, reason) rows kept; past them, refusals are counted in one row
per topic and reason under ``(other senders)``: a flood of made-up names must not grow memory or
the log."""
OTHER_SENDERS = "(other senders)"

MAC_BYTES = 32
PERSON = b"coco host msg"
"""BLAKE2b's personalisation: a MAC made here is of no use to any other protocol that shares the key."""
_HEADER = struct.Struct("<QQd")
_LENGTH = struct.Struct("<Q")


@dataclass(frozen=True, slots=True)
class Seal:
    """What authenticates one message (the fields of ``coco_interfaces`` Sample and HostMessage)."""

    host: str
    session: int
    counter: int
    wall: float
    mac: bytes


def mac(key: AppKey, topic: str, host: str, session: int, counter: int, wall: float, parts: Iterable[Any]) -> bytes:
    """The MAC of a message: keyed BLAKE2b-256 (RFC 7693's keyed mode, a MAC by design) over its
    topic, sender, session, counter and time, then each of ``parts`` (buffers or ``str``), each led
    by its length so that no two messages share an input.

    Why BLAKE2b and one call over the joined bytes: HMAC-SHA256 fed part by part cost a Python call
    each, and OpenSSL's one-shot HMAC lets the interpreter lock go even for a few hundred bytes, so
    that the writing thread waited for the reading one at every sample (a small sample's way between
    hosts took twice as long). hashlib's BLAKE2b keeps the lock below 2 KiB, and is twice as fast."""
    chunks: list[Any] = []
    for text in (topic, host):
        encoded = text.encode()
        chunks += (_LENGTH.pack(len(encoded)), encoded)
    chunks.append(_HEADER.pack(session, counter, wall))
    for part in parts:
        data = part.encode() if type(part) is str else part
        chunks += (_LENGTH.pack(memoryview(data).nbytes), data)
    return hashlib.blake2b(b"".join(chunks), key=key.secret, digest_size=MAC_BYTES, person=PERSON).digest()


class Sealer:
    """The sending side of one end (a publisher): seals each message it sends on ``topic`` as
    ``host``. One thread at a time (the end's)."""

    def __init__(self, key: AppKey, topic: str, host: str) -> None:
        self.key = key
        self.topic = topic
        self.host = host
        self.session = secrets.randbits(63) | 1
        self.counter = 0

    def seal(self, parts: Iterable[Any]) -> Seal:
        self.counter += 1
        wall = time.time()
        return Seal(self.host, self.session, self.counter, wall,
                    mac(self.key, self.topic, self.host, self.session, self.counter, wall, parts))


@dataclass
class _Window:
    """What one sender's messages on one topic said so far: its session, its highest counter and
    which of the :data:`WINDOW` before it came."""

    session: int
    highest: int = 0
    seen: int = 0
    """Bit ``i``: counter ``highest - i`` came."""


class Refusals:
    """Messages from the network refused, by topic, claimed sender and reason (the profile's
    "refused from the network" table). Thread-safe: each bridge's thread counts its own."""

    def __init__(self) -> None:
        self._counts: dict[tuple[str, str, str], int] = {}
        self._lock = threading.Lock()

    def count(self, topic: str, sender: str, why: str) -> None:
        """Count one refusal; ``why`` is one of a few fixed reasons (the rows stay few)."""
        key = (topic, quoted(sender), why)
        with self._lock:
            if key not in self._counts and len(self._counts) >= MAX_ROWS:
                key = (topic, OTHER_SENDERS, why)
            count = self._counts.get(key, 0) + 1
            self._counts[key] = count
        if count == 1:
            log.warning("refused a message on %s claiming to come from host %s: %s (further ones are counted in the "
                        "profile)", topic, key[1], why)

    @property
    def total(self) -> int:
        with self._lock:
            return sum(self._counts.values())

    def rows(self) -> list[list[str]]:
        with self._lock:
            return [[topic, sender, why, str(count)] for (topic, sender, why), count in sorted(self._counts.items())]


def quoted(name: str) -> str:
    """A claimed host name as a log may show it: printable, at most :data:`MAX_NAME` characters."""
    shown = name[:MAX_NAME].encode("unicode_escape").decode("ascii")
    return repr(shown) if len(name) <= MAX_NAME else repr(shown) + f" (+{len(name) - MAX_NAME} characters)"


class Verifier:
    """The receiving side of one topic: checks each message's :class:`Seal` (see the module's
    docstring). ``senders`` are the hosts that may write on the topic; ``hosts`` every host of the
    application (a sender outside it is named as such)."""

    def __init__(self, key: AppKey, topic: str, senders: Sequence[str], hosts: Sequence[str],
                 refusals: Refusals, own: str = "") -> None:
        self.key = key
        self.own = own
        """The receiving host: an authentic message that claims its name comes from a second launch
        of it (its own messages, heard back, are left out before they reach here)."""
        self.topic = topic
        self.senders = frozenset(senders)
        self.hosts = frozenset(hosts)
        self.refusals = refusals
        self._windows: dict[str, _Window] = {}
        self._claimed: set[str] = set()

    def accept(self, seal: Seal, parts: Iterable[Any]) -> bool:
        """Whether the message is authentic, new and from a host that may send it; a refusal is
        counted (:class:`Refusals`)."""
        why = self._problem(seal, parts)
        if why:
            self.refusals.count(self.topic, seal.host, why)
            return False
        return True

    def _problem(self, seal: Seal, parts: Iterable[Any]) -> str:
        expected = mac(self.key, self.topic, seal.host, seal.session, seal.counter, seal.wall, parts)
        if not hmac.compare_digest(expected, bytes(seal.mac)):
            return "not authenticated (no key, another key, or changed on the way)"
        if seal.host == self.own and self.own:
            return self._claimed_twice(seal.host, "this host's own launch", seal.session)
        if seal.host not in self.senders:
            return ("a host this application does not declare" if seal.host not in self.hosts
                    else "a host that does not write on this topic")
        if not math.isfinite(seal.wall) or abs(time.time() - seal.wall) > FRESH:
            return f"stale (a replay, or clocks more than {FRESH:g} s apart)"
        window = self._windows.get(seal.host)
        if window is None:
            window = self._windows[seal.host] = _Window(seal.session)
        elif window.session != seal.session:
            return self._claimed_twice(seal.host, f"session {window.session:x}", seal.session)
        return _replayed(window, seal.counter)

    def _claimed_twice(self, host: str, first: str, session: int) -> str:
        """Report once that two launches with the key claim ``host``; the second is refused."""
        if host not in self._claimed:
            self._claimed.add(host)
            log.error("host %s is claimed by two launches on %s (%s and session %x): is it started twice? The "
                      "second one's messages are refused", host, self.topic, first, session)
        return "a second launch claiming this host name"


def _replayed(window: _Window, counter: int) -> str:
    """"" and ``counter`` recorded as seen, or why it is a replay."""
    if counter < 1:
        return "a counter of 0 (counters start at 1)"
    if counter > window.highest:
        shift = counter - window.highest
        window.seen = ((window.seen << shift) | 1) & ((1 << WINDOW) - 1) if shift < WINDOW else 1
        window.highest = counter
        return ""
    back = window.highest - counter
    if back >= WINDOW or window.seen >> back & 1:
        return f"a replay (a counter seen already, or more than {WINDOW} behind the newest)"
    window.seen |= 1 << back
    return ""
