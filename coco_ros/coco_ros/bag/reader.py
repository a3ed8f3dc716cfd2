"""Reading rosbag2 bags stored as MCAP or SQLite: topics, messages in log-time order, latched messages.

A bag is a folder with ``metadata.yaml`` and one or more ``.mcap`` or ``.db3`` files (what ``ros2 bag
record`` makes: MCAP from Jazzy on, SQLite before), or a single ``.mcap`` or ``.db3`` file (a
librealsense recording is one ``.db3``). A file is read by its content, not its name: SQLite's
magic bytes make it a :class:`~.sqlite_file.Db3File`, anything else is read as MCAP. Messages keep
their CDR bytes; ``BagMessage.message`` decodes them into rclpy messages on first access
(:mod:`.cdr_decoder`), so filtering and forwarding cost no decoding.

Damage (see :mod:`.mcap_file` and :mod:`.sqlite_file`): whatever is readable is read. Problems are
:class:`BagError`s that name the file and the byte where reading stopped; they are collected in :attr:`BagReader.errors`
and reported by :meth:`BagReader.messages` *after* the last readable message: raised by default, or
handed to the ``on_error`` callback given to the reader (then nothing is raised). A file that is neither
MCAP nor SQLite at all fails at once, when the reader is made. Fewer readable messages than the recorder's
``metadata.yaml`` declares (a file cut exactly at a record boundary leaves no other trace) is damage
too, reported the same way, per topic, and so are more (data copied twice that is not a byte-for-byte
copy of a chunk, which the file reader skips itself). So is whatever a finished recording has and
this one lacks, even where every message is readable: a data section that ends without its DataEnd
record (a file cut at a record boundary, a recorder killed; the error says whether metadata.yaml's
counts show that nothing is missing), a footer or summary that is gone or damaged, a bag folder
without a readable ``metadata.yaml`` (its storage files are read, but nothing says how much was
recorded). A bag that is not what its recorder wrote must not pass for a sound one.
"""

from __future__ import annotations

import heapq
import re
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

from coco_core.errors import BagError, MessageTypeError, did_you_mean

from .mcap_file import McapFile, RawMessage
from .sqlite_file import Db3File, is_sqlite
from .message_types import TF_MESSAGE, TypeResolver
from .metadata import BagMetadata, read_metadata
from .qos import Qos, parse_profiles
from .topic import TopicInfo

_UNSET: Any = object()


class _TopicDecoder:
    """CDR bytes -> message object for one topic; the class is resolved (once) on first use."""

    __slots__ = ("resolver", "type_name", "serialization_format", "where")

    def __init__(self, resolver: TypeResolver, topic: TopicInfo, where: str) -> None:
        self.resolver = resolver
        self.type_name = topic.type
        self.serialization_format = topic.serialization_format
        self.where = where

    def __call__(self, data: bytes) -> Any:
        if self.serialization_format != "cdr":
            raise BagError(
                self.where,
                f"messages are serialized as {self.serialization_format!r}; only 'cdr' can be deserialized",
            )
        decode = self.resolver.decoder(self.type_name, self.where)
        try:
            return decode(data)
        except Exception as error:  # rclpy raises several kinds on malformed CDR
            raise BagError(self.where, f"cannot deserialize a {self.type_name} message: {error}") from None


class BagMessage:
    """One recorded message: topic, type, times (ns since the epoch), CDR bytes, decoded on demand."""

    __slots__ = ("topic", "type", "log_time", "publish_time", "sequence", "data", "_decode", "_message")

    def __init__(
        self,
        topic: str,
        type_name: str,
        log_time: int,
        publish_time: int,
        data: bytes,
        decode: Callable[[bytes], Any],
        sequence: int = 0,
    ) -> None:
        self.topic = topic
        self.type = type_name
        self.log_time = log_time
        """When the recorder received it (rosbag2's receive time; the replay clock)."""
        self.publish_time = publish_time
        self.sequence = sequence
        self.data = data
        self._decode = decode
        self._message = _UNSET

    @property
    def message(self) -> Any:
        """The deserialized message (rclpy's class for the type), decoded once."""
        if self._message is _UNSET:
            self._message = self._decode(self.data)
        return self._message

    def __repr__(self) -> str:
        return f"<BagMessage {self.topic} {self.type} t={self.log_time} {len(self.data)} bytes>"


STORAGE_SUFFIXES = {"mcap": ".mcap", "sqlite3": ".db3"}
"""rosbag2's storage identifiers (metadata.yaml) -> the suffix of their files."""


def _file_index(path: Path) -> tuple[int, str]:
    match = re.search(r"_(\d+)\.(mcap|db3)$", path.name)
    return (int(match.group(1)) if match else -1, path.name)


def _storage_files(folder: Path) -> list[Path]:
    return sorted((p for suffix in STORAGE_SUFFIXES.values() for p in folder.glob(f"*{suffix}")), key=_file_index)


def _open_file(path: Path) -> McapFile | Db3File:
    """A ``.db3`` file, or any SQLite database, is read as SQLite (a .db3 that is not is refused saying so)."""
    return Db3File(path) if path.suffix == ".db3" or is_sqlite(path) else McapFile(path)


class BagReader:
    """Read a rosbag2 bag (folder, ``.mcap`` or ``.db3`` file).

    ``on_error``: called with each :class:`BagError` met while reading messages (damaged data)
    instead of raising it at the end of :meth:`messages`.
    """

    def __init__(self, path: str | Path, *, on_error: Callable[[BagError], None] | None = None) -> None:
        self.path = Path(path)
        self._on_error = on_error
        self._resolver = TypeResolver()
        self.errors: list[BagError] = []
        """Every problem found so far: damage found on opening, then blocks that failed to load."""
        self.metadata: BagMetadata | None = None
        self._found: list[BagError] = []
        """Damage found on opening that no file reports itself: metadata.yaml missing or unreadable, a
        data section that ends without its DataEnd record (reported after each pass of :meth:`messages`)."""
        self._files: list[McapFile | Db3File] = []
        try:
            for file_path in self._resolve_files():
                self._files.append(_open_file(file_path))
        except BaseException:
            self.close()
            raise
        for error in [e for file in self._files for e in file.errors] + self._found:
            self._record(error)
        self.topics: dict[str, TopicInfo] = {}
        """Topic name -> :class:`TopicInfo`, in the order the bag declares them."""
        self._channels: list[dict[int, str]] = []  # per file: channel id -> topic
        self._decoders: dict[str, _TopicDecoder] = {}
        self._build_topics()
        self._lost: dict[str, tuple[int, int]] = {}
        """Topic -> (declared, readable) where metadata.yaml declares more messages than are readable."""
        self._excess: dict[str, tuple[int, int]] = {}
        """Topic -> (declared, readable) where more messages are readable than metadata.yaml declares."""
        self._check_unfinished(self._check_declared_counts())

    # -- opening ---------------------------------------------------------------------------------

    def _resolve_files(self) -> list[Path]:
        path = self.path
        if path.is_file():
            return [path]
        if not path.is_dir():
            raise BagError(
                path, "no such bag: expected a rosbag2 bag folder (with metadata.yaml), an .mcap or a .db3 file"
            )
        try:
            self.metadata = read_metadata(path)
        except BagError as error:
            # The storage files carry the messages: they are read, and the bag is damaged.
            if not _storage_files(path):
                raise
            self._found.append(BagError(error.path, f"{error.detail}: the folder's storage files are read, but "
                                                    "nothing says how many messages were recorded, so a loss would "
                                                    "not show"))
        if self.metadata is None:
            files = _storage_files(path)
            if not files:
                raise BagError(
                    path, "not a bag folder: expected metadata.yaml or at least one .mcap or .db3 file in it"
                )
            if not self._found:
                self._found.append(BagError(
                    path / "metadata.yaml", "missing: a rosbag2 bag folder has one, written by its recorder; the "
                    f"folder's {len(files)} {' and '.join(sorted({f.suffix for f in files}))} file(s) are read, but nothing says how many messages were recorded, "
                    "so a loss would not show (name an .mcap or .db3 file itself to read a file without its folder)"))
            return files
        meta = self.metadata
        if meta.storage_identifier and meta.storage_identifier not in STORAGE_SUFFIXES:
            raise BagError(
                path / "metadata.yaml",
                f"storage {meta.storage_identifier!r} is not supported: expected 'mcap' or 'sqlite3' "
                "(convert the bag with 'ros2 bag convert' to MCAP)",
            )
        if meta.compression_mode.lower() == "file":
            raise BagError(
                path / "metadata.yaml",
                f"file compression ({meta.compression_format}) is not supported: expected uncompressed "
                "storage files (MCAP chunk compression is fine)",
            )
        files = [path / Path(name).name for name in meta.relative_file_paths]
        missing = [str(f) for f in files if not f.is_file()]
        if missing:
            raise BagError(path / "metadata.yaml", f"lists files that are missing: {', '.join(missing)}")
        if not files:
            raise BagError(path / "metadata.yaml", "lists no storage file (relative_file_paths is empty)")
        return files

    def _build_topics(self) -> None:
        declared: dict[str, TopicInfo] = {}
        if self.metadata is not None:
            declared = {t.name: t for t in self.metadata.topics}
        counts: dict[str, int] = {}
        found: dict[str, TopicInfo] = {}
        for file in self._files:
            by_id: dict[int, str] = {}
            for channel_id, channel in sorted(file.channels.items()):
                by_id[channel_id] = channel.topic
                counts[channel.topic] = counts.get(channel.topic, 0) + file.counts.get(channel_id, 0)
                if channel.topic in found:
                    continue
                record = declared.get(channel.topic)
                schema = file.schemas.get(channel.schema_id)
                type_name = schema.name if schema is not None else (record.type if record else "")
                profiles: tuple[Qos, ...] = ()
                if "offered_qos_profiles" in channel.metadata:
                    try:
                        profiles = parse_profiles(channel.metadata["offered_qos_profiles"])
                    except ValueError:
                        profiles = ()
                if not profiles and record is not None:
                    profiles = record.offered_qos_profiles
                found[channel.topic] = TopicInfo(
                    name=channel.topic,
                    type=type_name,
                    serialization_format=channel.message_encoding or "cdr",
                    offered_qos_profiles=profiles,
                    message_count=0,
                    definition=schema.data.decode("utf-8", "replace") if schema is not None else "",
                    definition_encoding=schema.encoding if schema is not None else "",
                    type_description_hash=channel.metadata.get("topic_type_hash", "")
                    or (record.type_description_hash if record else ""),
                )
            self._channels.append(by_id)
        for name, record in declared.items():
            if name not in found:  # declared but without a channel in the files: no message readable
                found[name] = TopicInfo(
                    name=name,
                    type=record.type,
                    serialization_format=record.serialization_format,
                    offered_qos_profiles=record.offered_qos_profiles,
                    message_count=0,
                    type_description_hash=record.type_description_hash,
                )
        for name, info in found.items():
            self.topics[name] = replace(info, message_count=counts.get(name, 0))
            where = f"{self.path} topic {name}"
            self._decoders[name] = _TopicDecoder(self._resolver, self.topics[name], where)

    def _check_declared_counts(self) -> bool:
        """Compare what is readable with what the recorder declared in metadata.yaml; whether there
        was a declaration to compare with.

        A file cut at a record boundary, or one whose whole data section is gone, is indistinguishable
        from a recording that was stopped there: only the recorder's own count tells. A folder is
        compared topic by topic; a single ``.mcap`` file with the folder's metadata.yaml beside it,
        with that file's entry. Each shortfall (and each excess: messages stored twice) is a
        :class:`BagError` reported like any other damage.
        """
        meta, where = self.metadata, self._metadata_path
        if meta is None and self.path.is_file():
            try:
                meta = read_metadata(self.path.parent)
            except BagError:
                return False
            names = [Path(name).name for name in meta.relative_file_paths] if meta is not None else []
            if meta is None or self.path.name not in names:
                return False  # not this file's folder
            declared = {Path(f.path).name: f.message_count for f in meta.files}
            if len(names) > 1:  # one file of several: its own entry, when the metadata has one
                expected = declared.get(self.path.name)
                if expected is None:
                    return False
                if expected > self.message_count:
                    self._lost[""] = (expected, self.message_count)
                    self._record(self._shortfall(where))
                elif expected < self.message_count:
                    self._excess[""] = (expected, self.message_count)
                    self._record(self._surplus(where))
                return True
        if meta is None:
            return False
        for record in meta.topics:
            readable = self.topics[record.name].message_count if record.name in self.topics else 0
            if record.message_count > readable:
                self._lost[record.name] = (record.message_count, readable)
            elif record.message_count < readable:
                self._excess[record.name] = (record.message_count, readable)
        if self._lost:
            self._record(self._shortfall(where))
        if self._excess:
            self._record(self._surplus(where))
        return True

    def _check_unfinished(self, declared: bool) -> None:
        """A file whose data section ends without its DataEnd record was cut at a record boundary or
        not closed by its writer: damage named at the byte where the data ends, which says whether
        metadata.yaml's counts (``declared``) show that no message is missing."""
        for file in self._files:
            at = file.unfinished_at
            if at is None:
                continue
            if declared and not self._lost:
                lost = "metadata.yaml's counts show that no message is missing"
            else:
                unknown = "" if declared else " (no metadata.yaml beside it says how many were written)"
                lost = f"whatever followed is lost{unknown}"
            error = BagError(file.path, "the data section ends here without its DataEnd record and the file has no "
                                        "MCAP footer: the file is cut at a record boundary or its writer was killed; "
                                        f"the {file.message_count} messages before this point are readable, {lost}",
                             at)
            self._found.append(error)
            self._record(error)

    @property
    def _metadata_path(self) -> Path:
        return (self.path.parent if self.path.is_file() else self.path) / "metadata.yaml"

    def _shortfall(self, where: Path, topics: Iterable[str] | None = None) -> BagError:
        selected = [t for t in self._lost if topics is None or t == "" or t in topics]
        lost = sum(self._lost[t][0] - self._lost[t][1] for t in selected)
        shown = "; ".join(f"{t or 'this file'}: {self._lost[t][1]} of {self._lost[t][0]}" for t in selected)
        return BagError(where, f"the storage files hold fewer messages than it declares ({shown} readable): "
                               f"{lost} are lost (the bag is truncated or damaged)")

    def _surplus(self, where: Path, topics: Iterable[str] | None = None) -> BagError:
        selected = [t for t in self._excess if topics is None or t == "" or t in topics]
        extra = sum(self._excess[t][1] - self._excess[t][0] for t in selected)
        shown = "; ".join(f"{t or 'this file'}: {self._excess[t][1]} of {self._excess[t][0]}" for t in selected)
        return BagError(where, f"the storage files hold more messages than it declares ({shown} readable): "
                               f"{extra} are not the recording's (data stored twice, or another recording's)")

    # -- summary ---------------------------------------------------------------------------------

    @property
    def files(self) -> list[Path]:
        """The storage files read, in order."""
        return [f.path for f in self._files]

    @property
    def message_count(self) -> int:
        """Readable messages in the bag."""
        return sum(f.message_count for f in self._files)

    @property
    def start_time(self) -> int:
        """Log time (ns) of the first message; 0 for a bag without messages."""
        times = [f.start_time for f in self._files if f.start_time is not None]
        return min(times) if times else 0

    @property
    def end_time(self) -> int:
        """Log time (ns) of the last message; 0 for a bag without messages."""
        times = [f.end_time for f in self._files if f.end_time is not None]
        return max(times) if times else 0

    @property
    def duration(self) -> int:
        return self.end_time - self.start_time

    @property
    def damaged(self) -> bool:
        """Whether some data is known to be lost (see :attr:`errors`)."""
        return bool(self.errors)

    @property
    def notes(self) -> list[str]:
        """What a writer may leave that costs nothing, e.g. a file without a summary section, scanned."""
        return [f"{f.path}: {note}" for f in self._files for note in f.notes]

    def latched_topics(self) -> list[str]:
        """Topics whose messages a late subscriber would get (transient local, e.g. /tf_static)."""
        return [name for name, info in self.topics.items() if info.latched]

    def message_class(self, topic: str) -> type:
        """The Python class of a topic's messages; :class:`MessageTypeError` when not installed."""
        info = self.topics[self._select([topic])[0]]
        return self._resolver.message_class(info.type, f"{self.path} topic {topic}")

    def check_types(self, topics: Iterable[str] | None = None) -> None:
        """Raise one :class:`MessageTypeError` listing every topic whose type cannot be deserialized.

        A replay calls this before starting, so a missing package is reported up front, not at the
        first message of that topic.
        """
        problems = []
        for name in self._select(topics):
            info = self.topics[name]
            try:
                self._resolver.decoder(info.type, f"{self.path} topic {name}")
            except MessageTypeError as error:
                problems.append(f"{name} ({error.detail})")
        if problems:
            raise MessageTypeError(self.path, "cannot deserialize " + "; ".join(problems))

    # -- messages --------------------------------------------------------------------------------

    def _select(self, topics: Iterable[str] | str | None) -> list[str]:
        if topics is None:
            return list(self.topics)
        if isinstance(topics, str):
            topics = [topics]
        selected = list(dict.fromkeys(topics))
        for name in selected:
            if name not in self.topics:
                raise BagError(self.path, f"no topic {name!r} in the bag; {did_you_mean(name, self.topics)}")
        return selected

    def _record(self, error: BagError) -> None:
        key = (error.path, error.offset, error.detail)
        if all((e.path, e.offset, e.detail) != key for e in self.errors):
            self.errors.append(error)

    def _iterate(
        self, names: list[str], start: int | None, end: int | None, on_error: Callable[[BagError], None]
    ) -> Iterator[BagMessage]:
        wanted = set(names)
        streams = []
        for file, by_id in zip(self._files, self._channels):
            ids = frozenset(i for i, topic in by_id.items() if topic in wanted)
            if ids:
                streams.append(self._wrap(file.iter_messages(ids, start, end, on_error), by_id))
        if len(streams) == 1:
            yield from streams[0]
        elif streams:
            yield from heapq.merge(*streams, key=lambda m: m.log_time)

    def _wrap(self, raw: Iterator[RawMessage], by_id: dict[int, str]) -> Iterator[BagMessage]:
        topics, decoders = self.topics, self._decoders
        for message in raw:
            topic = by_id[message.channel_id]
            yield BagMessage(
                topic,
                topics[topic].type,
                message.log_time,
                message.publish_time,
                message.data,
                decoders[topic],
                message.sequence,
            )

    def messages(
        self,
        topics: Iterable[str] | str | None = None,
        start: int | None = None,
        end: int | None = None,
    ) -> Iterator[BagMessage]:
        """Messages of ``topics`` (default: all) with ``start <= log_time < end``, in log-time order.

        ``start``/``end`` are absolute log times in ns (``reader.start_time + offset``). Messages
        with equal log times keep their order in the file. When the bag is damaged, every readable
        message is yielded first, then the problems are reported (see the module docstring).
        """
        names = self._select(topics)
        problems: list[BagError] = []

        def on_error(error: BagError) -> None:
            self._record(error)
            problems.append(error)

        yield from self._iterate(names, start, end, on_error)
        for file in self._files:
            problems.extend(file.errors)
        asked = None if topics is None else names  # all: the declared topics without a channel too
        if any(topic == "" or asked is None or topic in asked for topic in self._lost):
            problems.append(self._shortfall(self._metadata_path, asked))
        if any(topic == "" or asked is None or topic in asked for topic in self._excess):
            problems.append(self._surplus(self._metadata_path, asked))
        problems.extend(self._found)
        if not problems:
            return
        if self._on_error is not None:
            for error in problems:
                self._on_error(error)
            return
        first = problems[0]
        if len(problems) == 1:
            raise first
        others = "; ".join(str(p) for p in problems[1:])
        detail = f"{first.detail} (and {len(problems) - 1} more problems: {others})"
        raise BagError(first.path, detail, first.offset)

    def latched(
        self, topics: Iterable[str] | str | None = None, *, before: int | None = None
    ) -> list[BagMessage]:
        """What a subscriber joining at log time ``before`` would get from latched topics.

        For each topic in ``topics`` (default: all) that is :attr:`TopicInfo.latched`, the messages
        logged before ``before`` (default: the whole bag): ``tf2_msgs/msg/TFMessage`` topics
        (/tf_static) keep *all* of them, since each static broadcaster publishes its own transforms;
        other topics keep their last message. The result is in log-time order, so a replay that
        starts at an offset (or loops) publishes it first and then ``messages(start=before)``.

        Damage is recorded in :attr:`errors` but not raised here: the replay's :meth:`messages`
        pass reports it.
        """
        names = [name for name in self._select(topics) if self.topics[name].latched]
        if not names:
            return []
        keep_all = {name for name in names if self.topics[name].type == TF_MESSAGE}
        every: list[BagMessage] = []
        last: dict[str, BagMessage] = {}
        for message in self._iterate(names, None, before, self._record):
            if message.topic in keep_all:
                every.append(message)
            else:
                last[message.topic] = message
        return sorted(every + list(last.values()), key=lambda m: m.log_time)

    # -- life cycle ------------------------------------------------------------------------------

    def close(self) -> None:
        """Release the files (messages already yielded stay usable)."""
        for file in self._files:
            file.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<BagReader {self.path} {len(self.topics)} topics {self.message_count} messages>"
