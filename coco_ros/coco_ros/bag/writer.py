"""Writing rosbag2 bags: a folder with ``<name>_0.mcap`` and ``metadata.yaml``, as ``ros2 bag record`` makes.

The MCAP file follows the ``ros2`` profile the way rosbag2's MCAP storage plugin writes it: one
``ros2msg`` schema per type holding the complete message definition, one ``cdr`` channel per topic
whose metadata carries ``offered_qos_profiles`` and ``topic_type_hash``, a ``rosbag2`` metadata record,
and the summary (chunk indexes, statistics) at the end. ``metadata.yaml`` is version 9 (Jazzy).

Message objects are stored as *canonical* CDR: rclpy's ``serialize_message`` (Fast CDR) leaves the
alignment padding uninitialised and pads the end to 8 bytes, so two serialisations of equal messages
can differ, and ``rosbags`` rejects e.g. a JointState ending with an empty ``effort`` ("CDR message
size mismatch"). Each message is therefore converted field by field to its ``rosbags`` class (Jazzy
type store; a type it lacks is registered from the definition written in the schema) and serialised
by rosbags, which zeroes the padding and ends the buffer at the last field: the same messages give
the same bytes, which rclpy, rosbag2 and rosbags all read. CDR bytes handed in are written as they are.

Interruption: chunks are written out when full and at least every ``flush_interval`` seconds, so a
process that dies loses at most that much; :class:`~coco_ros.bag.reader.BagReader` reads such a file
(no summary, no metadata.yaml) by scanning it. ``close()`` finishes the file and writes metadata.yaml;
it is idempotent, called by the context manager, and also when the writer is garbage collected or
the interpreter exits (e.g. after Ctrl-C), so a clean stop never leaves a half-written bag.
"""

from __future__ import annotations

import operator
import os
import threading
import time
import weakref
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from coco_core.errors import BagError, ReplayError
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, IndexType, Writer

from .message_types import normalize_type, type_name_of
from .metadata import FileRecord, dump_metadata, metadata_document, write_metadata
from .topic import TopicInfo
from .qos import TF_STATIC, Qos, dump_profiles_string
from .schema import ENCODING, DefinitionSource

LIBRARY = f"coco_ros.bag; {LIBRARY_IDENTIFIER}"

_COMPRESSION = {"none": CompressionType.NONE, "zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}

_DTYPES = {
    "double": np.float64, "float": np.float32, "int8": np.int8, "uint8": np.uint8, "int16": np.int16,
    "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
    "octet": np.uint8, "char": np.uint8, "boolean": np.bool_,
}
"""rclpy field types of primitive arrays -> the numpy dtype rosbags expects for them."""

_STORE_LOCK = threading.Lock()


@lru_cache(maxsize=1)
def _store() -> Any:
    """The rosbags type store (Jazzy), shared: building one takes a while."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def _rosbags_message(message: Any, store: Any) -> Any:
    """The rosbags object of an rclpy message, field by field (nested messages recursively)."""
    values: dict[str, Any] = {}
    for name, kind in message.get_fields_and_field_types().items():
        value = getattr(message, name)
        base = kind.split("<", 1)[1].rstrip(">") if kind.startswith("sequence<") else kind.split("[", 1)[0]
        base = base.split(",", 1)[0]
        if "/" in base and base != kind:
            values[name] = [_rosbags_message(v, store) for v in value]
        elif "/" in base:
            values[name] = _rosbags_message(value, store)
        elif base in _DTYPES and base != kind:
            values[name] = np.asarray(value, dtype=_DTYPES[base])
        elif base.startswith("string") and base != kind:
            values[name] = list(value)
        else:
            values[name] = value
    return store.types[type_name_of(message)](**values)


def canonical_cdr(message: Any, definitions: DefinitionSource) -> bytes:
    """Zero-padded little-endian CDR of a message object, ending at its last field (see the module
    docstring); ``definitions`` gives the text of a type the rosbags store does not know yet."""
    from rosbags.typesys import get_types_from_msg

    store = _store()
    type_name = type_name_of(message)
    if type_name not in store.types:
        with _STORE_LOCK:
            if type_name not in store.types:
                found = get_types_from_msg(definitions.full_text(type_name), type_name)
                store.register({name: fields for name, fields in found.items() if name not in store.fielddefs})
    return bytes(store.serialize_cdr(_rosbags_message(message, store), type_name))


@dataclass
class _Topic:
    name: str
    type: str
    channel_id: int
    profiles: tuple[Qos, ...]
    type_hash: str
    count: int = 0


@dataclass
class _State:
    """Everything ``close`` needs, apart from the writer object (so a finalizer can close it)."""

    folder: Path
    file_path: Path
    stream: Any
    mcap: Writer
    sync: bool
    lock: threading.RLock = field(default_factory=threading.RLock)
    topics: dict[str, _Topic] = field(default_factory=dict)
    schemas: dict[str, int] = field(default_factory=dict)
    count: int = 0
    start: int | None = None
    end: int | None = None
    closed: bool = False
    custom_data: dict[str, str] = field(default_factory=dict)

    def flush(self) -> None:
        with self.lock:
            if self.closed:
                return
            self.mcap.flush()
            self.stream.flush()
            if self.sync:
                os.fsync(self.stream.fileno())

    def document(self) -> dict[str, Any]:
        start = self.start if self.start is not None else 0
        duration = (self.end - start) if self.end is not None else 0
        files = [FileRecord(self.file_path.name, start, duration, self.count)]
        topics = [
            TopicInfo(name=t.name, type=t.type, serialization_format="cdr", offered_qos_profiles=t.profiles,
                      message_count=t.count, type_description_hash=t.type_hash) for t in self.topics.values()
        ]
        return metadata_document(files, topics, self.custom_data)

    def close(self) -> None:
        with self.lock:
            if self.closed:
                return
            self.closed = True
            try:
                document = self.document()
                info = dump_metadata(document["rosbag2_bagfile_information"])
                self.mcap.add_metadata("rosbag2", {"serialized_metadata": info})
                self.mcap.finish()
                self.stream.flush()
                if self.sync:
                    os.fsync(self.stream.fileno())
            finally:
                self.stream.close()
            write_metadata(self.folder, document)


class BagWriter:
    """Record messages into a new rosbag2 bag folder.

    ``folder`` must not exist or be empty; the storage file is ``<folder name>_0.mcap`` in it.
    ``compression``: ``none`` (rosbag2's default), ``zstd`` or ``lz4`` per chunk.
    ``flush_interval``: seconds between forced writes of the current chunk (None: only when full).
    ``sync``: also fsync on each flush (survives a power cut, costs disk latency).
    """

    def __init__(
        self,
        folder: str | Path,
        *,
        compression: str = "none",
        chunk_size: int = 1 << 20,
        flush_interval: float | None = 1.0,
        sync: bool = False,
        custom_data: dict[str, str] | None = None,
    ) -> None:
        folder = Path(folder)
        if compression not in _COMPRESSION:
            raise ReplayError(f"compression must be one of {', '.join(_COMPRESSION)}, got {compression!r}")
        if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
            raise BagError(
                folder, "cannot record here: expected a new or empty folder (a bag is never overwritten)"
            )
        folder.mkdir(parents=True, exist_ok=True)
        file_path = folder / f"{folder.name}_0.mcap"
        stream = open(file_path, "wb")
        try:
            mcap = Writer(
                stream,
                chunk_size=chunk_size,
                compression=_COMPRESSION[compression],
                index_types=IndexType.ALL,
                repeat_channels=True,
                repeat_schemas=True,
                use_chunking=True,
                use_statistics=True,
                use_summary_offsets=True,
                enable_crcs=True,
            )
            mcap.start(profile="ros2", library=LIBRARY)
            stream.flush()
        except BaseException:
            stream.close()
            raise
        self._state = _State(folder, file_path, stream, mcap, sync, custom_data=dict(custom_data or {}))
        self._definitions = DefinitionSource()
        self._flush_interval = flush_interval
        self._last_flush = time.monotonic()
        # Closes the bag at garbage collection or interpreter exit if close() was never called.
        self._finalizer = weakref.finalize(self, self._state.close)

    @property
    def folder(self) -> Path:
        return self._state.folder

    @property
    def file_path(self) -> Path:
        """The ``.mcap`` file being written."""
        return self._state.file_path

    @property
    def message_count(self) -> int:
        return self._state.count

    @property
    def closed(self) -> bool:
        return self._state.closed

    def topic_counts(self) -> dict[str, int]:
        """Messages written so far per topic."""
        return {name: topic.count for name, topic in self._state.topics.items()}

    def add_topic(
        self,
        topic: str,
        type_name: str,
        qos: Qos | Sequence[Qos] | None = None,
        *,
        definition: str | None = None,
    ) -> None:
        """Declare a topic before its first message (``write`` does it on first use).

        ``qos``: the profile(s) the publishers offered; default: rclpy's default profile, or the
        transient-local profile of tf2's static broadcaster for ``/tf_static``.
        ``definition``: the complete ``ros2msg`` text, when the type's package is not installed.
        """
        state = self._state
        with state.lock:
            self._check_open()
            if topic in state.topics:
                known = state.topics[topic].type
                raise BagError(state.folder, f"topic {topic!r} is already declared (type {known})")
            self._declare(topic, type_name, qos, definition)

    def _declare(
        self, topic: str, type_name: str, qos: Qos | Sequence[Qos] | None, definition: str | None
    ) -> _Topic:
        state = self._state
        if not isinstance(topic, str) or not topic.startswith("/"):
            raise BagError(
                state.folder, f"expected a fully qualified topic name like '/joint_states', got {topic!r}"
            )
        try:
            full_type = normalize_type(type_name)
        except ValueError as error:
            raise BagError(state.folder, f"topic {topic}: {error}") from None
        if qos is None:
            profiles: tuple[Qos, ...] = (TF_STATIC,) if topic.endswith("/tf_static") else (Qos(),)
        elif isinstance(qos, Qos):
            profiles = (qos,)
        else:
            profiles = tuple(qos)
            if not all(isinstance(p, Qos) for p in profiles):
                raise BagError(state.folder, f"topic {topic}: expected Qos profiles, got {qos!r}")
        schema_id = state.schemas.get(full_type)
        if schema_id is None:
            try:
                text = definition if definition is not None else self._definitions.full_text(full_type)
            except BagError as error:
                raise BagError(state.folder, f"topic {topic}: {error}") from None
            data = text.encode("utf-8")
            schema_id = state.mcap.register_schema(name=full_type, encoding=ENCODING, data=data)
            state.schemas[full_type] = schema_id
        type_hash = self._definitions.type_hash(full_type)
        channel_id = state.mcap.register_channel(
            topic=topic,
            message_encoding="cdr",
            schema_id=schema_id,
            metadata={"offered_qos_profiles": dump_profiles_string(profiles), "topic_type_hash": type_hash},
        )
        declared = _Topic(topic, full_type, channel_id, profiles, type_hash)
        state.topics[topic] = declared
        return declared

    def write(
        self,
        topic: str,
        message: Any,
        log_time_ns: int,
        type_name: str | None = None,
        qos: Qos | Sequence[Qos] | None = None,
        *,
        publish_time_ns: int | None = None,
    ) -> None:
        """Append one message: a message object (serialized here) or its CDR bytes.

        ``log_time_ns``: receive time in ns since the epoch (the time replays follow).
        ``type_name`` is needed for bytes on a topic not declared yet; ``qos`` only counts when the
        topic is first seen. Thread-safe.
        """
        state = self._state
        try:
            log_time = operator.index(log_time_ns)
            publish_time = log_time if publish_time_ns is None else operator.index(publish_time_ns)
        except TypeError:
            times = f"{log_time_ns!r} / {publish_time_ns!r}"
            raise BagError(state.folder, f"topic {topic}: expected integer nanoseconds, got {times}") from None
        if log_time < 0 or publish_time < 0:
            times = f"{log_time} / {publish_time}"
            raise BagError(state.folder, f"topic {topic}: times must be >= 0 ns, got {times}")
        if isinstance(message, (bytes, bytearray, memoryview)):
            data = bytes(message)
            actual_type = normalize_type(type_name) if type_name else None
        else:
            actual_type = type_name_of(message)
            if type_name and normalize_type(type_name) != actual_type:
                detail = f"topic {topic}: type_name {type_name!r} but the message is a {actual_type}"
                raise BagError(state.folder, detail)
            data = canonical_cdr(message, self._definitions)
        with state.lock:
            self._check_open()
            declared = state.topics.get(topic)
            if declared is None:
                if actual_type is None:
                    detail = f"topic {topic}: raw bytes on a new topic need type_name (e.g. 'std_msgs/msg/String')"
                    raise BagError(state.folder, detail)
                declared = self._declare(topic, actual_type, qos, None)
            elif actual_type is not None and actual_type != declared.type:
                raise BagError(
                    state.folder, f"topic {topic} holds {declared.type} messages, got a {actual_type}"
                )
            state.mcap.add_message(
                channel_id=declared.channel_id,
                log_time=log_time,
                data=data,
                publish_time=publish_time,
                sequence=declared.count & 0xFFFFFFFF,
            )
            declared.count += 1
            state.count += 1
            state.start = log_time if state.start is None else min(state.start, log_time)
            state.end = log_time if state.end is None else max(state.end, log_time)
            interval = self._flush_interval
            if interval is not None and time.monotonic() - self._last_flush >= interval:
                self.flush()

    def flush(self) -> None:
        """Write the current chunk and hand everything to the OS (readable if the process dies now)."""
        self._state.flush()
        self._last_flush = time.monotonic()

    def close(self) -> Path:
        """Finish the MCAP file (summary) and write metadata.yaml; safe to call again. Returns the folder."""
        self._finalizer()
        return self._state.folder

    def _check_open(self) -> None:
        if self._state.closed:
            raise BagError(self._state.folder, "the bag writer is closed")

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        status = "closed" if self.closed else "open"
        return f"<BagWriter {self.folder} {status} {self.message_count} messages>"
