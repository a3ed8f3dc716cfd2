"""A diagnostics server for a transformation graph: REST, WebSocket streams and a small web page.

Standard library only (``http.server``), bound to 127.0.0.1 by default::

    server = TransformServer(graph).start()
    print(server.url)          # open it in a browser
    ...
    server.stop()

REST (GET, JSON unless said otherwise)

- ``/api/graph``: the whole graph (:func:`.export.graph_dict`), serialised once per graph version
  and at most every ``GRAPH_MAX_AGE`` s while it changes, shared by concurrent requests
- ``/api/frames``: ``{"frames": [...]}``
- ``/api/edges``: ``{"edges": [...]}``
- ``/api/lookup?target=a&source=b[&time=t]``: ``T_a_b`` as ``matrix``, ``translation``, ``quaternion``
  (x, y, z, w) and the ``path`` walked; 404 with the error text and the valid frames when a frame is
  unknown or no path joins them; 409 with the error text when the path has no value (a dynamic edge
  without a sample, or a time outside its history); 400 when a parameter is missing or malformed
- ``/api/graph.dot``: graphviz DOT (text)

WebSocket (text messages, JSON)

- ``/ws/transforms?target=a&source=b[&target=c&source=d...][&rate=hz]``: first the current value of
  every pair, then each pair again whenever a change on its path gives it a new value, coalesced so
  that a client gets at most ``rate`` messages a second (default and maximum: the server's ``rate``):
  ``{"type": "transforms", "time": ..., "changes": n, "transforms": [{"target", "source", "matrix",
  "translation", "quaternion"} | {"target", "source", "error"}]}``. ``changes`` counts the updates
  coalesced into the message. Unknown frames or pairs without a path are refused (404) before the
  upgrade; a pair whose path has no value yet (a dynamic edge without a sample) is reported with an
  ``error`` and retried until it has one.
- ``/ws/graph[?rate=hz]``: the whole graph, again whenever it changed, at most ``rate`` times a second:
  ``{"type": "graph", "graph": {...}}``.

``rate`` is at least ``MIN_RATE`` (0.01) messages a second; a lower one, a negative one or not a
number is refused with 400 before the upgrade. A client's frames are bounded (see
:mod:`.websocket`): a message over 1 MiB or 64 frames is closed with 1009, more than 1,000 frames at
once or 200 a second on average with 1008.

Updates are driven by :meth:`Query.on_change` callbacks, which run in the thread that wrote the
graph: the callback only stores the new value and wakes the connection's sender thread (about 1 us
added to the write), so a 1 kHz joint loop is not slowed by clients and clients are not flooded.
Structure changes (an edge added or removed) do not call back; each sender notices them from the
graph's ``structure_version`` and looks its pairs up again, so a new shorter path takes over and a
vanished one is reported as an ``error`` entry.

``/`` serves the web page (files in ``web/`` beside this module): the frames as a tree with the
edges' kinds and live values, and live lookups chosen on the page or in its URL
(``/?target=a&source=b``, several pairs allowed).

Load: at most :data:`REQUEST_THREADS` clients are served at once (the others wait in the kernel's
listen queue), their requests read and answered one at a time, each followed by a pause as long as
it took (:data:`REQUEST_PAUSE`), so that however many clients ask at once, the server holds the GIL
at most about half of the time and never with more than one thread: the application's activities,
which share the GIL, are not held up by a flood (a thread per client, all parsing at once, stalled
a 5 ms replay for 227 ms). WebSocket streams run on their own threads once open.

Security: the server only reads the graph. Bound to a loopback address it answers only requests
whose ``Host`` is a loopback name (no DNS rebinding), and it accepts a WebSocket only from a page of
the same origin (any web site could otherwise open a socket to localhost).
"""

from __future__ import annotations

import ipaddress
import json
import logging
import math
import socket
import threading
import time as _time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import TYPE_CHECKING, Any, Callable
from urllib.parse import parse_qs, urlsplit

import numpy as np

from ..errors import AttributeValueError, CocoError, UsageError
from . import export
from .websocket import CLOSE_GOING_AWAY, WebSocket, WebSocketError, handshake_headers

if TYPE_CHECKING:
    from .graph import TransformGraph

log = logging.getLogger("coco.transforms.server")

WEB_FILES = {
    "index.html": "text/html; charset=utf-8",
    "app.js": "text/javascript; charset=utf-8",
    "style.css": "text/css; charset=utf-8",
}
"""The page's files (in ``web/`` beside this module) and their content types."""

ENDPOINTS = ["/", "/api/graph", "/api/frames", "/api/edges", "/api/lookup?target=A&source=B[&time=T]",
             "/api/graph.dot", "/ws/transforms?target=A&source=B[&rate=HZ]", "/ws/graph[?rate=HZ]"]

BACKLOG = 1024
"""Listen queue length: a burst of hundreds of clients waits in the kernel instead of being refused
(the default of 5 overflowed thousands of times under 200 concurrent requests)."""

MIN_RATE = 0.01
"""The lowest rate a server or a client may ask for (a message every 100 s): the interval between
messages is ``1 / rate`` seconds, and one of 10^300 s is no interval a timer can wait."""

REQUEST_THREADS = 8
"""Client connections served at once, each on a thread of its own (a WebSocket stream gives its
place back once open); the serving loop accepts no more meanwhile, and the others wait in the
kernel's listen queue (:data:`BACKLOG`). Why: 500 threads started at once, each parsing its request,
took the GIL from the application's activities in turns. A client that connects and says nothing
keeps its place until the read timeout (10 s)."""

TURN_READ_TIMEOUT = 1.0
"""Seconds each read of a request may wait while the request holds the turn: a client that sends
part of a request and stops keeps the others waiting this long, not the 10 s read timeout."""

REQUEST_PAUSE = 1.0
"""After answering a request, the server pauses this many times the time the request took before it
answers the next one. Requests are read and answered one at a time (each connection still has a
thread of its own, but it waits for its turn blocked, holding no GIL), and the pause leaves the GIL
to the application's activities at least half of the time: 500 requests answered together took it
from them in turns (a 5 ms replay stalled 227 ms). See ``bench/bench_transforms_server.py``."""

GRAPH_MAX_AGE = 0.1
"""Seconds a serialised ``/api/graph`` is served again while the graph changes (a replay changes it
every few ms): under a flood, one serialisation per 0.1 s instead of one per request."""

_LOOPBACK_NAMES = {"localhost", "localhost.localdomain", "ip6-localhost"}


class _RequestError(CocoError):
    """An HTTP error answer: status and JSON body."""

    def __init__(self, status: HTTPStatus, message: str, **extra: Any) -> None:
        super().__init__(message)
        self.status = status
        self.body = {"error": message, **extra}


def _is_loopback(host: str) -> bool:
    host = host.strip("[]").lower()
    if host in _LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _hostname(authority: str) -> str:
    """``host`` of ``host:port`` / ``[v6]:port`` / ``scheme://host:port``."""
    if "://" in authority:
        return (urlsplit(authority).hostname or "").lower()
    return (urlsplit("//" + authority).hostname or "").lower()


class TransformServer:
    """REST + WebSocket + web page over one :class:`TransformGraph`, in background threads.

    ``port=0`` picks a free port (see :attr:`url` after :meth:`start`); ``rate`` is the most
    messages a second one WebSocket client gets.
    """

    def __init__(self, graph: TransformGraph, host: str = "127.0.0.1", port: int = 0, rate: float = 30.0) -> None:
        if not MIN_RATE <= rate < math.inf:  # NaN too
            raise AttributeValueError(f"rate must be a finite number of at least {MIN_RATE:g} messages per second, "
                                      f"got {rate}")
        self.graph = graph
        self.host = host
        self.port = port
        self.rate = float(rate)
        self._httpd: _HTTPServer | None = None
        self._thread: threading.Thread | None = None
        self._connections: set[_Connection] = set()
        self._lock = threading.Lock()
        self._stopping = False
        self._web_cache: dict[str, bytes] = {}
        self._graph_cache: tuple[int, float, bytes] | None = None
        """(graph version, monotonic time, JSON) of the last ``/api/graph`` serialisation."""
        self._graph_lock = threading.Lock()

    # --- life cycle -----------------------------------------------------------------------------
    def start(self) -> TransformServer:
        """Bind and serve in a background thread; returns ``self``."""
        if self._httpd is not None:
            raise UsageError(f"the transform server already runs at {self.url}")
        httpd = (_HTTPServer6 if ":" in self.host else _HTTPServer)((self.host, self.port), _Handler)
        httpd.owner = self
        self._httpd = httpd
        self.port = httpd.server_address[1]
        self._stopping = False
        self._thread = threading.Thread(target=httpd.serve_forever, kwargs={"poll_interval": 0.05},
                                        name=f"coco-transform-server:{self.port}", daemon=True)
        self._thread.start()
        log.info("transform server at %s", self.url)
        return self

    def stop(self, timeout: float = 1.0) -> None:
        """Close every WebSocket (close frame 1001), stop serving and join the threads."""
        httpd, thread = self._httpd, self._thread
        if httpd is None or thread is None:
            return
        deadline = _time.monotonic() + timeout
        with self._lock:
            self._stopping = True
            connections = list(self._connections)
        httpd.shutdown()
        for connection in connections:
            connection.close(CLOSE_GOING_AWAY, "server stopping")
        for connection in connections:
            connection.join(max(0.0, deadline - _time.monotonic()))
        httpd.server_close()
        thread.join(max(0.0, deadline - _time.monotonic()))
        if thread.is_alive() or any(connection.alive for connection in connections):
            log.warning("transform server at %s: threads still running %.1f s after stop", self.url, timeout)
        self._httpd = self._thread = None

    def __enter__(self) -> TransformServer:
        return self.start() if self._httpd is None else self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def url(self) -> str:
        """``http://host:port/`` of the running server."""
        if self._httpd is None:
            raise UsageError("the transform server is not started: call start() first")
        host = self.host if ":" not in self.host else f"[{self.host}]"
        return f"http://{host}:{self.port}/"

    @property
    def clients(self) -> int:
        """Number of open WebSocket connections."""
        with self._lock:
            return len(self._connections)

    # --- helpers for the handler ------------------------------------------------------------------
    def _web_file(self, name: str) -> bytes:
        data = self._web_cache.get(name)
        if data is None:
            data = (resources.files(__package__) / "web" / name).read_bytes()
            self._web_cache[name] = data
        return data

    def _graph_json(self) -> bytes:
        """``/api/graph`` as JSON bytes, serialised once per graph version: a flood of requests for
        an unchanged graph costs one serialisation, not one (tens of kB, under the graph's lock)
        per request, which kept the application's threads waiting on the graph's lock and the GIL."""
        with self._graph_lock:  # concurrent requests wait for one serialisation, then share it
            version, now = self.graph.version, _time.monotonic()
            cached = self._graph_cache
            if cached is not None and (cached[0] == version or now - cached[1] < GRAPH_MAX_AGE):
                return cached[2]
            body = json.dumps(export.jsonable(export.graph_dict(self.graph)), allow_nan=False).encode("utf-8")
            self._graph_cache = (version, now, body)
            return body

    def _register(self, connection: _Connection) -> bool:
        with self._lock:
            if self._stopping:
                return False
            self._connections.add(connection)
            return True

    def _unregister(self, connection: _Connection) -> None:
        with self._lock:
            self._connections.discard(connection)

    def __repr__(self) -> str:
        state = self.url if self._httpd is not None else "stopped"
        return f"<TransformServer {state}>"


class _HTTPServer(ThreadingHTTPServer):
    daemon_threads = True
    request_queue_size = BACKLOG
    block_on_close = False  # stop() joins the WebSocket threads itself, with a time limit
    owner: TransformServer

    def __init__(self, address: tuple[str, int], handler: type[BaseHTTPRequestHandler]) -> None:
        super().__init__(address, handler)
        self.turn = threading.Lock()
        """Held by the request being read and answered (:data:`REQUEST_PAUSE`)."""
        self._places = threading.BoundedSemaphore(REQUEST_THREADS)
        self._holding = threading.local()
        """``place``: whether this handler thread holds one of the :attr:`_places`."""

    def process_request(self, request: Any, client_address: Any) -> None:
        """In the serving loop: wait for a place (:data:`REQUEST_THREADS`), then serve ``request``
        on a thread of its own; a request still waiting when the server stops is closed."""
        while not self._places.acquire(timeout=0.05):
            if self.owner._stopping:
                self.shutdown_request(request)
                return
        super().process_request(request, client_address)

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        self._holding.place = True
        try:
            super().process_request_thread(request, client_address)
        finally:
            self.leave_place()

    def leave_place(self) -> None:
        """Give this handler thread's place back (once): at its end, or when its WebSocket stream
        opens (it lives on, mostly waiting)."""
        if getattr(self._holding, "place", False):
            self._holding.place = False
            self._places.release()

    def handle_error(self, request: Any, client_address: Any) -> None:
        log.debug("transform server: error with client %s", client_address, exc_info=True)


class _HTTPServer6(_HTTPServer):
    address_family = socket.AF_INET6


# --- streams --------------------------------------------------------------------------------------
def _entry(target: str, source: str, value: np.ndarray | str) -> dict[str, Any]:
    if isinstance(value, str):
        return {"target": target, "source": source, "error": value}
    return {"target": target, "source": source, **export.pose(value)}


def _same(a: np.ndarray | str | None, b: np.ndarray | str | None) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and (a is b or bool(np.array_equal(a, b)))
    return a == b


class _Connection:
    """One WebSocket client: the handler thread reads its frames, a sender thread writes updates."""

    def __init__(self, server: TransformServer, ws: WebSocket, sock: socket.socket, rate: float) -> None:
        self.server = server
        self.ws = ws
        self.socket = sock
        self.interval = 1.0 / rate
        self.wake = threading.Event()
        self.reader: threading.Thread = threading.current_thread()
        self.sender = threading.Thread(target=self._send_loop, name=f"coco-transform-ws-{id(self):x}", daemon=True)
        self.sent = 0

    @property
    def alive(self) -> bool:
        return self.reader.is_alive() or self.sender.is_alive()

    def run(self) -> None:
        """In the handler thread: start sending, read until the client closes, then clean up."""
        self.sender.start()
        try:
            while self.ws.receive() is not None:
                pass  # clients have nothing to say yet; pings are answered by receive()
        finally:
            self.ws.closed.set()
            self.wake.set()
            self.sender.join()
            self.cleanup()
            self.server._unregister(self)

    def close(self, code: int, reason: str) -> None:
        """From another thread (server stop): send a close frame and unblock the reader."""
        self.ws.close(code, reason, timeout=0.2)  # the sender may be stuck on a client that stopped reading
        self.wake.set()
        try:
            self.socket.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass

    def join(self, timeout: float) -> None:
        deadline = _time.monotonic() + timeout
        for thread in (self.sender, self.reader):
            if thread is not threading.current_thread() and thread.ident is not None:
                thread.join(max(0.0, deadline - _time.monotonic()))

    def _send_loop(self) -> None:
        try:
            self.send_loop()
        except Exception:  # a bug here must not pass silently, nor take the server down
            log.exception("transform server: WebSocket sender failed")
            self.close(1011, "server error")
        finally:  # the client closed, or a send failed: either way the reader must not wait on
            self.ws.closed.set()
            try:
                self.socket.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def _throttle(self, last: float) -> bool:
        """Sleep until ``interval`` after ``last``; False when the connection closed meanwhile."""
        delay = last + self.interval - _time.monotonic()
        if delay > 0:
            self.ws.closed.wait(delay)
        return not self.ws.closed.is_set()

    def send(self, message: dict[str, Any]) -> bool:
        ok = self.ws.send_text(json.dumps(export.jsonable(message), allow_nan=False))
        self.sent += ok
        return ok

    def send_loop(self) -> None:
        raise NotImplementedError

    def cleanup(self) -> None:
        pass


class _TransformStream(_Connection):
    """Values of some ``(target, source)`` lookups, pushed when they change, throttled."""

    def __init__(self, server: TransformServer, ws: WebSocket, sock: socket.socket, rate: float,
                 pairs: list[tuple[str, str]]) -> None:
        super().__init__(server, ws, sock, rate)
        self.pairs = pairs
        self._lock = threading.Lock()
        self._pending: dict[tuple[str, str], np.ndarray | str] = {}  # a value, or why there is none
        self._changes = 0
        self._unsubscribers: list[Callable[[], None]] = []
        self._waiting: dict[tuple[str, str], str] = {}  # pairs without a value yet, and why
        self._sent: dict[tuple[str, str], np.ndarray | str] = {}  # the last value sent of each pair

    def _callback(self, pair: tuple[str, str]) -> Callable[[np.ndarray], None]:
        def changed(value: np.ndarray) -> None:  # runs in the writer's thread: keep it tiny
            with self._lock:
                self._pending[pair] = value
                self._changes += 1
            self.wake.set()
        return changed

    def _subscribe(self, pair: tuple[str, str]) -> bool:
        graph = self.server.graph
        try:  # fails while there is no path between the two frames
            unsubscribe = graph.query(*pair).on_change(self._callback(pair))
        except LookupError as error:
            self._waiting[pair] = str(error)
            return False
        with self._lock:
            self._unsubscribers.append(unsubscribe)
        self._waiting.pop(pair, None)
        value: np.ndarray | str
        try:
            value = graph.lookup(*pair)
        except LookupError as error:  # e.g. a dynamic edge without a sample yet: the first one calls back
            value = str(error)
        with self._lock:
            self._pending.setdefault(pair, value)
        return True

    def _structure_changed(self) -> None:
        """Look the subscribed pairs up again after frames or edges were added: a lookup moves a
        query's callbacks to its new path (a shorter one may exist now), and may change its value."""
        graph = self.server.graph
        for pair in dict.fromkeys(self.pairs):
            if pair in self._waiting:
                continue
            value: np.ndarray | str
            try:
                value = graph.lookup(*pair)
            except LookupError as error:  # e.g. an edge of its path was removed
                value = str(error)
            with self._lock:
                if pair not in self._pending and not _same(value, self._sent.get(pair)):
                    self._pending[pair] = value

    def send_loop(self) -> None:
        graph = self.server.graph
        structure = graph.structure_version
        for pair in dict.fromkeys(self.pairs):
            self._subscribe(pair)
        last = 0.0
        first = True
        while not self.ws.closed.is_set():
            if not first:
                # wake on a change, or every interval to retry pairs without a value and to notice
                # structure changes (which do not call back)
                self.wake.wait(self.interval)
                if not self._throttle(last):
                    break
            self.wake.clear()
            for pair in list(self._waiting):
                self._subscribe(pair)
            if graph.structure_version != structure:
                structure = graph.structure_version
                self._structure_changed()
            with self._lock:
                pending, self._pending = self._pending, {}
                changes, self._changes = self._changes, 0
            self._sent.update(pending)
            entries = [_entry(*pair, value) for pair, value in pending.items()]
            if first:
                entries += [{"target": t, "source": s, "error": why} for (t, s), why in self._waiting.items()]
            if entries:
                if not self.send({"type": "transforms", "time": _time.time(), "changes": changes,
                                  "transforms": entries}):
                    break
                last = _time.monotonic()
            first = False

    def cleanup(self) -> None:
        with self._lock:
            unsubscribers, self._unsubscribers = self._unsubscribers, []
        for unsubscribe in unsubscribers:
            unsubscribe()


class _GraphStream(_Connection):
    """The whole graph, sent again whenever its version changed, throttled."""

    def send_loop(self) -> None:
        graph = self.server.graph
        version = None
        while True:
            if graph.version != version:
                version = graph.version
                if not self.send({"type": "graph", "graph": export.graph_dict(graph)}):
                    break
            if self.ws.closed.wait(self.interval):
                break


# --- HTTP ---------------------------------------------------------------------------------------
class _Handler(BaseHTTPRequestHandler):
    server: _HTTPServer
    protocol_version = "HTTP/1.1"  # a 101 answer must say HTTP/1.1; every other answer closes
    timeout = 10.0  # for reading a request; lifted once a WebSocket is open
    server_version = "CoCoTransforms/1.0"
    _turn = False
    """Whether this request holds :attr:`_HTTPServer.turn`."""

    @property
    def owner(self) -> TransformServer:
        return self.server.owner

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (the base class's name)
        log.debug("%s %s", self.address_string(), format % args)

    def handle(self) -> None:
        """Wait for the request's first bytes (blocked, no GIL held), then for the turn, and only
        then read and answer it (:data:`TURN_READ_TIMEOUT`), and pause (:data:`REQUEST_PAUSE`): a
        client that connects and sends nothing holds no turn. A WebSocket gives the turn back once open, without a pause
        (:meth:`_give_turn_back`)."""
        try:
            if not self.connection.recv(1, socket.MSG_PEEK):
                return  # closed before saying anything
        except OSError:  # the read timeout, or a reset
            return
        self.server.turn.acquire()
        self._turn = True
        self.connection.settimeout(TURN_READ_TIMEOUT)
        began = _time.perf_counter()
        try:
            super().handle()
        finally:
            if self._turn:
                _time.sleep(REQUEST_PAUSE * (_time.perf_counter() - began))
            self._give_turn_back()

    def _give_turn_back(self) -> None:
        if self._turn:
            self._turn = False
            self.server.turn.release()

    def do_GET(self) -> None:  # noqa: N802 (the base class's name)
        parts = urlsplit(self.path)
        query = parse_qs(parts.query, keep_blank_values=True)
        try:
            self._check_host()
            route = parts.path.rstrip("/") or "/"
            if route in ("/", "/index.html"):
                self._send(HTTPStatus.OK, self.owner._web_file("index.html"), WEB_FILES["index.html"])
            elif route.lstrip("/") in WEB_FILES:
                name = route.lstrip("/")
                self._send(HTTPStatus.OK, self.owner._web_file(name), WEB_FILES[name])
            elif route == "/api":
                self._json({"endpoints": ENDPOINTS})
            elif route == "/api/graph":
                self._send(HTTPStatus.OK, self.owner._graph_json(), "application/json; charset=utf-8")
            elif route == "/api/frames":
                self._json({"frames": self.owner.graph.frames})
            elif route == "/api/edges":
                self._json({"edges": export.graph_dict(self.owner.graph)["edges"]})
            elif route == "/api/lookup":
                self._json(self._lookup(query))
            elif route == "/api/graph.dot":
                self._send(HTTPStatus.OK, export.to_dot(self.owner.graph).encode("utf-8"),
                           "text/vnd.graphviz; charset=utf-8")
            elif route == "/ws/transforms":
                self._websocket(query, self._pairs(query))
            elif route == "/ws/graph":
                self._websocket(query, None)
            else:
                raise _RequestError(HTTPStatus.NOT_FOUND, f"no such endpoint {parts.path!r}", endpoints=ENDPOINTS)
        except _RequestError as error:
            self._json(error.body, error.status)

    # --- REST -----------------------------------------------------------------------------------
    def _check_host(self) -> None:
        if _is_loopback(self.owner.host) and not _is_loopback(_hostname(self.headers.get("Host", "localhost"))):
            raise _RequestError(HTTPStatus.FORBIDDEN,
                                f"this server answers only local names (localhost, 127.0.0.1), not "
                                f"{self.headers.get('Host')!r}")

    @staticmethod
    def _one(query: dict[str, list[str]], name: str, required: bool = True) -> str | None:
        values = query.get(name)
        if not values or values[0] == "":
            if required:
                raise _RequestError(HTTPStatus.BAD_REQUEST, f"missing query parameter {name!r}; "
                                    "expected e.g. /api/lookup?target=world&source=tool")
            return None
        return values[0]

    def _lookup(self, query: dict[str, list[str]]) -> dict[str, Any]:
        target, source = self._one(query, "target"), self._one(query, "source")
        assert target is not None and source is not None
        text = self._one(query, "time", required=False)
        try:
            time = None if text is None else float(text)
        except ValueError:
            time = math.nan
        if time is not None and not math.isfinite(time):
            raise _RequestError(HTTPStatus.BAD_REQUEST, f"time must be a finite number of seconds, got {text!r}")
        graph = self.owner.graph
        try:
            path = graph.path(target, source)
        except LookupError as error:  # an unknown frame, or no path
            raise _RequestError(HTTPStatus.NOT_FOUND, str(error), frames=graph.frames) from None
        try:
            value = graph.lookup(target, source, time)
        except LookupError as error:  # the path has no value (yet, or at that time)
            raise _RequestError(HTTPStatus.CONFLICT, str(error), path=path) from None
        return {"target": target, "source": source, "time": time, "path": path, **export.pose(value)}

    def _pairs(self, query: dict[str, list[str]]) -> list[tuple[str, str]]:
        targets, sources = query.get("target", []), query.get("source", [])
        if not targets or len(targets) != len(sources):
            raise _RequestError(HTTPStatus.BAD_REQUEST,
                                f"expected one or more target/source pairs (got {len(targets)} target(s), "
                                f"{len(sources)} source(s)), e.g. /ws/transforms?target=world&source=tool")
        pairs = list(zip(targets, sources))
        graph = self.owner.graph
        for target, source in pairs:
            try:
                graph.path(target, source)
            except LookupError as error:
                raise _RequestError(HTTPStatus.NOT_FOUND, str(error), frames=graph.frames) from None
        return pairs

    def _send(self, status: HTTPStatus, body: bytes, content_type: str, headers: dict[str, str] | None = None) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-cache")
        for name, value in (headers or {}).items():
            self.send_header(name, value)
        self.send_header("Connection", "close")
        self.end_headers()
        self.wfile.write(body)

    def _json(self, body: Any, status: HTTPStatus = HTTPStatus.OK) -> None:
        self._send(status, json.dumps(export.jsonable(body), allow_nan=False).encode("utf-8"),
                   "application/json; charset=utf-8")

    # --- WebSocket ------------------------------------------------------------------------------
    def _rate(self, query: dict[str, list[str]]) -> float:
        text = self._one(query, "rate", required=False)
        if text is None:
            return self.owner.rate
        try:
            rate = float(text)
        except ValueError:
            rate = math.nan
        if not rate >= MIN_RATE:  # NaN too; an infinite rate is the server's
            raise _RequestError(HTTPStatus.BAD_REQUEST, f"rate must be at least {MIN_RATE:g} messages per "
                                f"second, got {text!r}")
        return min(rate, self.owner.rate)

    def _websocket(self, query: dict[str, list[str]], pairs: list[tuple[str, str]] | None) -> None:
        rate = self._rate(query)
        try:
            response = handshake_headers(self.headers)
        except WebSocketError as error:
            raise _RequestError(HTTPStatus.UPGRADE_REQUIRED, str(error)) from None
        origin = self.headers.get("Origin")
        if origin and urlsplit(origin).netloc.lower() != self.headers.get("Host", "").lower():
            raise _RequestError(HTTPStatus.FORBIDDEN, f"WebSocket from another origin ({origin}) refused")
        ws = WebSocket(self.rfile, self.wfile.write)
        if pairs is None:
            connection: _Connection = _GraphStream(self.owner, ws, self.connection, rate)
        else:
            connection = _TransformStream(self.owner, ws, self.connection, rate, pairs)
        if not self.owner._register(connection):
            raise _RequestError(HTTPStatus.SERVICE_UNAVAILABLE, "the server is stopping")
        self.close_connection = True
        try:
            self.send_response(HTTPStatus.SWITCHING_PROTOCOLS)
            for name, value in response.items():
                self.send_header(name, value)
            self.end_headers()
            self.connection.settimeout(None)
        except OSError:
            self.owner._unregister(connection)
            return
        self._give_turn_back()  # the stream lives on its own threads, mostly waiting
        self.server.leave_place()
        connection.run()
