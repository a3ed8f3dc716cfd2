"""One rosbag2 SQLite storage file (``.db3``): the storage of every Humble and Iron bag, and what
librealsense 2.59 writes as its recordings (a single ``.db3``, no metadata.yaml).

Read through Python's ``sqlite3``, read-only (URI ``mode=ro``): a reader never writes to, locks for
writing or repairs a recording. The tables are rosbag2's: ``topics`` (id, name, type,
serialization_format, offered_qos_profiles[, type_description_hash]), ``messages`` (id, topic_id,
timestamp, data) and, from Iron on, ``message_definitions``. It offers what :class:`~.reader.BagReader`
takes from an :class:`~.mcap_file.McapFile` (topics as channels, their types as schemas, counts,
times, messages in log-time order), so everything that reads bags reads both.

What is read is bounded by sizes before it is read: a message larger than :data:`MESSAGE_LIMIT`
(or than the file) is skipped unread and reported, so a damaged length cannot make the reader
allocate gigabytes. Damage SQLite finds (a page that is not what its b-tree says, a file cut short)
is reported like an MCAP file's: on opening it is a :class:`BagError` at once; while reading, the
messages read so far are delivered and the damage is reported after them, naming how far reading got.
"""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path
from typing import Callable, Iterator

from coco_core.errors import BagError
from mcap.records import Channel, Schema

from .mcap_file import RawMessage

SQLITE_MAGIC = b"SQLite format 3\x00"
"""The first 16 bytes of every SQLite 3 database file."""
MESSAGE_LIMIT = 1 << 30
"""The largest message read (1 GiB: a 4K depth image is 16 MB); a larger one is skipped unread, as damage."""
DEFINITION_LIMIT = 1 << 20
"""The largest message definition read from ``message_definitions``; a larger one is left out."""


def is_sqlite(path: Path) -> bool:
    """Whether ``path`` starts as an SQLite 3 database does."""
    try:
        with open(path, "rb") as file:
            return file.read(len(SQLITE_MAGIC)) == SQLITE_MAGIC
    except OSError:
        return False


class Db3File:
    """Topics, counts and messages of one ``.db3`` file; see the module docstring."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.counts: dict[int, int] = {}
        self.message_count = 0
        self.start_time: int | None = None
        self.end_time: int | None = None
        self.errors: list[BagError] = []
        """Damage found on opening (always empty: damage found on opening is raised)."""
        self.notes: list[str] = []
        self.unfinished_at: int | None = None
        """Always None: SQLite keeps no end-of-data record; metadata.yaml's counts tell what is missing."""
        try:
            self.size = os.stat(self.path).st_size
        except OSError as error:
            raise BagError(self.path, f"cannot open the file: {error.strerror}") from None
        if not is_sqlite(self.path):
            raise BagError(self.path, "not an SQLite database: expected the 16 bytes 'SQLite format 3\\0' at the "
                                      "start (a rosbag2 .db3 file)", 0)
        self._db: sqlite3.Connection | None = None
        self._limit = min(MESSAGE_LIMIT, self.size)
        try:
            self._db = sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=ro", uri=True, check_same_thread=False)
            self._open()
        except sqlite3.Error as error:
            self.close()
            raise BagError(self.path, f"the SQLite database is damaged or not a rosbag2 bag: {error}") from None
        except BaseException:
            self.close()
            raise

    def _open(self) -> None:
        db = self._connection
        tables = {row[0] for row in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if not {"topics", "messages"} <= tables:
            raise BagError(self.path, "an SQLite database without rosbag2's tables: expected 'topics' and 'messages', "
                                      f"found {', '.join(sorted(tables)) or 'none'}")
        definitions = self._definitions(db) if "message_definitions" in tables else {}
        for topic_id, name, type_name, serialization, qos in db.execute(
                "SELECT id, name, type, serialization_format, offered_qos_profiles FROM topics ORDER BY id"):
            encoding, text = definitions.get(type_name, ("", b""))
            self.schemas[topic_id] = Schema(id=topic_id, name=type_name, encoding=encoding, data=text)
            self.channels[topic_id] = Channel(id=topic_id, schema_id=topic_id, topic=name,
                                              message_encoding=serialization,
                                              metadata={"offered_qos_profiles": qos} if qos else {})
        for topic_id, count, first, last in db.execute(
                "SELECT topic_id, count(*), min(timestamp), max(timestamp) FROM messages GROUP BY topic_id"):
            if topic_id not in self.channels:
                raise BagError(self.path, f"{count} messages name topic id {topic_id}, which the topics table lacks")
            self.counts[topic_id] = count
            self.message_count += count
            self.start_time = first if self.start_time is None else min(self.start_time, first)
            self.end_time = last if self.end_time is None else max(self.end_time, last)

    @staticmethod
    def _definitions(db: sqlite3.Connection) -> dict[str, tuple[str, bytes]]:
        """Type name -> (encoding, definition) from Iron's ``message_definitions``, within the size bound."""
        found = {}
        for type_name, encoding, text in db.execute(
                "SELECT topic_type, encoding, CASE WHEN length(encoded_message_definition) <= ? "
                "THEN encoded_message_definition END FROM message_definitions", (DEFINITION_LIMIT,)):
            if text is not None:
                found[type_name] = (encoding, text.encode() if isinstance(text, str) else bytes(text))
        return found

    @property
    def _connection(self) -> sqlite3.Connection:
        if self._db is None:
            raise BagError(self.path, "the file was closed")
        return self._db

    def iter_messages(
        self,
        channel_ids: frozenset[int] | None = None,
        start: int | None = None,
        end: int | None = None,
        on_error: Callable[[BagError], None] | None = None,
    ) -> Iterator[RawMessage]:
        """Messages of these topics (by id) with ``start <= log_time < end``, in log-time order (equal
        times in the order they were written). Damage met on the way ends the pass, reported through
        ``on_error`` after the messages read before it."""
        where, values = ["timestamp >= ?"], [0 if start is None else start]
        if end is not None:
            where.append("timestamp < ?")
            values.append(end)
        if channel_ids is not None and not channel_ids >= self.channels.keys():  # all: no filter to evaluate
            where.append(f"topic_id IN ({', '.join('?' * len(channel_ids))})")
            values.extend(sorted(channel_ids))
        # The size is checked as the row is read, before its bytes are: a blob's length is in its record header.
        query = (f"SELECT topic_id, id, timestamp, timestamp, CASE WHEN length(data) <= {self._limit} THEN data END "
                 f"FROM messages WHERE {' AND '.join(where)} ORDER BY timestamp, id")
        make, rows = RawMessage._make, 0
        try:
            # Rows are selected in RawMessage's field order: a row becomes a message in one C call.
            for rows, row in enumerate(self._connection.execute(query, values), 1):
                if row[4] is None:
                    self._refuse_oversized(row[1], on_error)
                    continue
                yield make(row)
        except sqlite3.Error as error:
            if on_error is not None:
                on_error(BagError(self.path, f"the SQLite database is damaged ({error}): reading stopped at row "
                                             f"{rows + 1} of this pass, the rest of this pass is lost"))

    def _refuse_oversized(self, row_id: int, on_error: Callable[[BagError], None] | None) -> None:
        if on_error is None:
            return
        (length,) = self._connection.execute("SELECT length(data) FROM messages WHERE id = ?", (row_id,)).fetchone()
        on_error(BagError(self.path, f"message {row_id} declares {length} bytes, more than the {self._limit} a "
                                     "message may have here: skipped unread"))

    def close(self) -> None:
        if self._db is not None:
            self._db.close()
            self._db = None


__all__ = ["Db3File", "MESSAGE_LIMIT", "SQLITE_MAGIC", "is_sqlite"]
