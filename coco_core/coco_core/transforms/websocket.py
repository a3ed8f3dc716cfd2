"""The server side of WebSocket (RFC 6455), small enough for the diagnostics server.

What a read-mostly diagnostics stream needs and no more: the opening handshake
(``Sec-WebSocket-Accept``), unmasked text frames from the server, and reading the client's masked
frames so that pings are answered and a close is echoed. No extensions (no compression), no
subprotocols. Messages from the client are handed to the caller as whole (reassembled) payloads.

A client is not trusted to be gentle: a message is reassembled in linear time and may have at most
:data:`MAX_MESSAGE` bytes in at most :data:`MAX_FRAGMENTS` frames (40,000 empty continuation frames
otherwise kept the reader busy for half a minute, taking the GIL from the application's activities),
and a connection may send at most :data:`FRAME_BURST` frames at once and :data:`FRAME_RATE` a second
on average, pings included: beyond, it is closed (1009 too big, 1008 policy violation), so the
server's reading stays a small, bounded share of the process.
"""

from __future__ import annotations

import base64
import hashlib
import struct
import threading
import time
from typing import Callable, Protocol
from ..errors import ConnectionClosedError, WebSocketError

GUID = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11"

OP_CONTINUATION, OP_TEXT, OP_BINARY = 0x0, 0x1, 0x2
OP_CLOSE, OP_PING, OP_PONG = 0x8, 0x9, 0xA

CLOSE_NORMAL, CLOSE_GOING_AWAY, CLOSE_PROTOCOL_ERROR = 1000, 1001, 1002
CLOSE_NOT_UTF8, CLOSE_POLICY, CLOSE_TOO_BIG = 1007, 1008, 1009

MAX_MESSAGE = 1 << 20
"""Largest client message accepted (1 MiB); clients of a diagnostics stream send little."""

MAX_FRAGMENTS = 64
"""Frames one client message may be split into (browsers send one)."""

FRAME_RATE = 200.0
"""Frames a second a client may send on average (pings, pongs, messages: it has little to say)."""

FRAME_BURST = 1000
"""Frames a client may send at once before :data:`FRAME_RATE` applies."""


class FrameBudget:
    """A token bucket over a connection's frames: ``burst`` at once, ``rate`` a second after that."""

    def __init__(self, rate: float = FRAME_RATE, burst: int = FRAME_BURST) -> None:
        self.rate, self.burst = rate, float(burst)
        self.tokens = float(burst)
        self.last = time.monotonic()

    def take(self) -> bool:
        """Spend one frame; False when the client is over its budget."""
        now = time.monotonic()
        self.tokens = min(self.burst, self.tokens + (now - self.last) * self.rate)
        self.last = now
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True


def accept_key(key: str) -> str:
    """``Sec-WebSocket-Accept`` for a client's ``Sec-WebSocket-Key``."""
    return base64.b64encode(hashlib.sha1((key.strip() + GUID).encode("ascii")).digest()).decode("ascii")


class Headers(Protocol):
    """What the handshake reads of a request's headers: a dict in tests, http.server's Message when served."""

    def get(self, name: str, default: str, /) -> str: ...


class ByteReader(Protocol):
    """The socket's buffered reader (``rfile`` of http.server), or any stream of bytes in tests."""

    def read(self, size: int, /) -> bytes: ...


def handshake_headers(headers: Headers) -> dict[str, str]:
    """Check an upgrade request's headers; return the response headers of the 101 answer.

    Raises :class:`WebSocketError` naming what is missing.
    """
    if "websocket" not in headers.get("Upgrade", "").lower():
        raise WebSocketError("expected a WebSocket upgrade request (header 'Upgrade: websocket')")
    if "upgrade" not in headers.get("Connection", "").lower():
        raise WebSocketError("expected header 'Connection: Upgrade'")
    if headers.get("Sec-WebSocket-Version", "").strip() != "13":
        raise WebSocketError(f"unsupported Sec-WebSocket-Version {headers.get('Sec-WebSocket-Version', '')!r}; "
                             "supported: 13")
    key = headers.get("Sec-WebSocket-Key", "").strip()
    try:
        decoded = base64.b64decode(key, validate=True)
    except ValueError:  # binascii.Error: not base64
        decoded = b""
    if len(decoded) != 16:
        raise WebSocketError(f"invalid Sec-WebSocket-Key {key!r}: expected 16 bytes in base64")
    return {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Accept": accept_key(key)}


def encode_frame(payload: bytes, opcode: int = OP_TEXT, fin: bool = True) -> bytes:
    """One unmasked frame, as a server sends it."""
    length = len(payload)
    first = (0x80 if fin else 0) | opcode
    if length < 126:
        header = struct.pack("!BB", first, length)
    elif length < 1 << 16:
        header = struct.pack("!BBH", first, 126, length)
    else:
        header = struct.pack("!BBQ", first, 127, length)
    return header + payload


def _read_exactly(read: Callable[[int], bytes], count: int) -> bytes:
    data = read(count) if count else b""
    while len(data) < count:
        more = read(count - len(data))
        if not more:
            raise ConnectionClosedError("the connection closed in the middle of a frame")
        data += more
    return data


def read_frame(read: Callable[[int], bytes], max_size: int = MAX_MESSAGE) -> tuple[bool, int, bytes]:
    """Read one frame from a client: ``(fin, opcode, unmasked payload)``.

    Raises :class:`EOFError` when the connection closes, :class:`WebSocketError` on a protocol error
    (an unmasked client frame, reserved bits set, a control frame that is too long or fragmented,
    a payload over ``max_size``).
    """
    head = read(2)
    if not head:
        raise ConnectionClosedError("the connection closed")
    head += _read_exactly(read, 2 - len(head))
    first, second = head
    fin, opcode = bool(first & 0x80), first & 0x0F
    if first & 0x70:
        raise WebSocketError("reserved bits set, but no extension was negotiated")
    if not second & 0x80:
        raise WebSocketError("client frames must be masked")
    length = second & 0x7F
    if length == 126:
        (length,) = struct.unpack("!H", _read_exactly(read, 2))
    elif length == 127:
        (length,) = struct.unpack("!Q", _read_exactly(read, 8))
    if opcode >= 0x8 and (length > 125 or not fin):
        raise WebSocketError("control frames must be unfragmented with at most 125 bytes")
    if length > max_size:
        raise WebSocketError(f"frame of {length} bytes exceeds the limit of {max_size}")
    mask = _read_exactly(read, 4)
    masked = _read_exactly(read, length)
    return fin, opcode, _unmask(masked, mask)


def _unmask(data: bytes, mask: bytes) -> bytes:
    if not data:
        return data
    key = int.from_bytes((mask * (len(data) // 4 + 1))[:len(data)], "big")
    return (int.from_bytes(data, "big") ^ key).to_bytes(len(data), "big")


class WebSocket:
    """A server-side connection after the handshake: thread-safe sends, a receive loop.

    ``read`` is the buffered reader of the socket (bytes the HTTP parser buffered must not be lost),
    ``write`` writes all bytes it is given.
    """

    def __init__(self, reader: ByteReader, write: Callable[[bytes], object]) -> None:
        self._read = reader.read
        self._write = write
        self._write_lock = threading.Lock()
        self.closed = threading.Event()
        """Set once a close frame was sent or the connection broke: nothing more is sent."""
        self._budget = FrameBudget()

    def send_text(self, text: str) -> bool:
        """Send one text message; False when the connection is closed (or broke while sending)."""
        return self._send(encode_frame(text.encode("utf-8"), OP_TEXT))

    def _send(self, frame: bytes) -> bool:
        with self._write_lock:
            if self.closed.is_set():
                return False
            try:
                self._write(frame)
                return True
            except OSError:
                self.closed.set()
                return False

    def close(self, code: int = CLOSE_NORMAL, reason: str = "", timeout: float = -1) -> None:
        """Send a close frame (once); the caller then closes the socket.

        With a ``timeout``, give up sending when another thread's send blocks that long (a client that
        stopped reading): the connection is marked closed all the same.
        """
        if not self._write_lock.acquire(timeout=timeout):
            self.closed.set()
            return
        try:
            if self.closed.is_set():
                return
            try:  # written before ``closed`` is set: a thread waiting on it shuts the socket down
                self._write(encode_frame(struct.pack("!H", code) + reason.encode("utf-8")[:120], OP_CLOSE))
            except OSError:
                pass
            self.closed.set()
        finally:
            self._write_lock.release()

    def receive(self) -> str | bytes | None:
        """The next message from the client (answering pings meanwhile), or None once it closed or
        was closed for breaking the protocol or its limits."""
        fragments: list[bytes] = []
        size = 0
        message_opcode: int | None = None  # None: no message under way
        budget = self._budget
        while True:
            try:
                fin, opcode, payload = read_frame(self._read, max(MAX_MESSAGE - size, 125))
            except (EOFError, OSError, ValueError):  # ValueError: reading a file closed under us
                self.closed.set()
                return None
            except WebSocketError as error:
                self.close(CLOSE_TOO_BIG if "exceeds" in str(error) else CLOSE_PROTOCOL_ERROR, str(error))
                return None
            if not budget.take():
                self.close(CLOSE_POLICY, f"more than {FRAME_BURST} frames at once or {FRAME_RATE:g} a second")
                return None
            if opcode == OP_PING:
                self._send(encode_frame(payload, OP_PONG))
            elif opcode == OP_PONG:
                pass
            elif opcode == OP_CLOSE:
                code = struct.unpack("!H", payload[:2])[0] if len(payload) >= 2 else CLOSE_NORMAL
                self.close(code if 1000 <= code < 5000 and code not in (1005, 1006, 1015) else CLOSE_NORMAL)
                return None
            elif opcode in (OP_TEXT, OP_BINARY, OP_CONTINUATION):
                if (opcode == OP_CONTINUATION) != (message_opcode is not None):
                    self.close(CLOSE_PROTOCOL_ERROR, "a continuation frame outside a message" if message_opcode
                               is None else "a new message before the last one ended")
                    return None
                if message_opcode is None:
                    message_opcode = opcode
                fragments.append(payload)
                size += len(payload)
                if len(fragments) > MAX_FRAGMENTS or size > MAX_MESSAGE:
                    self.close(CLOSE_TOO_BIG, f"message over {MAX_MESSAGE} bytes or {MAX_FRAGMENTS} frames")
                    return None
                if fin:
                    data = b"".join(fragments)
                    if message_opcode == OP_BINARY:
                        return data
                    try:
                        return data.decode("utf-8")
                    except UnicodeDecodeError:
                        self.close(CLOSE_NOT_UTF8, "text message is not UTF-8")
                        return None
            else:
                self.close(CLOSE_PROTOCOL_ERROR, f"unknown opcode {opcode:#x}")
                return None
