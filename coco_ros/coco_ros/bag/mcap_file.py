"""One MCAP file, read so that damage costs only what is damaged.

The ``mcap`` library parses the records (:mod:`mcap.records`); this module does the framing itself
(opcode, length, body) so that it knows the byte offset of every record and notices a record cut by
the end of the file, which the library's stream reader can mistake for a short one.

Opening builds a table of *blocks* (a chunk, or a run of loose messages in an unchunked file), each
with its log-time range and channels:

- from the summary section when the file is complete (footer, summary CRC and statistics intact):
  nothing else is read, so opening a large bag costs only its summary;
- otherwise by scanning the data section from the start, record by record, the way rosbag2 falls
  back when a recording was interrupted. The scan stops at the first record that is cut or whose
  framing is broken: a reserved opcode (0x00, zeros where records should be, or 0x10-0x7f), or
  :data:`SKIPPED_RUN` records in a row that carry nothing a bag holds; the rest of the file is then
  not MCAP data and is not read, so a file that is mostly not MCAP is refused in a moment however
  large it is. A chunk that is complete but does not decompress is skipped and the scan goes on
  after it, since its length still says where the next record starts.
  A chunk cut by the end of the file still gives its complete records when it is uncompressed (its
  records are plain bytes up to the cut). A chunk that repeats an earlier one byte for byte (a
  duplicated copy) is skipped and reported, so that no message is delivered twice. A data section
  that ends without its DataEnd record (cut exactly at a record boundary, or a writer killed) is
  recorded in :attr:`McapFile.unfinished_at`: only the bag's ``metadata.yaml`` can tell whether
  anything is missing, so :class:`~.reader.BagReader` reports that damage, saying which.
- A chunk whose CRC does not match its records (a damaged byte) is read record by record
  (:func:`_resynchronised`): the records are length-prefixed, so a record whose framing or message
  header is damaged costs itself only and reading resumes at the next record that checks; the chunk
  is reported as damage naming how many messages it lost.
- A file whose data section is whole but whose summary is damaged (no footer, a summary that does
  not match its CRC or does not parse) is read by scanning, and the damage is reported: nothing is
  lost, but the file is not what its writer wrote.

Messages are then merged across blocks in log-time order (blocks are loaded lazily, when the next
message could come from them), so a replay holds one or two chunks in memory, not the file.
"""

from __future__ import annotations

import heapq
import os
import re
import struct
import zlib
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, NamedTuple

from coco_core.errors import BagError, BagFormatError, CocoError
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    ChunkIndex,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
)

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")
_FOOTER_LENGTH = 9 + 20
_RUN_BYTES = 1 << 20
"""Loose messages are grouped into blocks of about this many bytes (a chunk's usual size)."""
SKIPPED_RUN = 4096
"""Records in a row that the scan skips (private opcodes, message indexes, attachments) after which the
rest of the file is taken for what is not MCAP data: a bag has a few per chunk, zeros or noise framed
as tiny records would otherwise be walked nine bytes at a time, for minutes."""
RECORD_LIMIT = 64 << 20
"""The largest Schema, Channel or Metadata record the scan reads (a message definition is kilobytes):
a larger one is damage, skipped unread rather than read into memory."""
_CHUNK_SLACK = 4096
"""Bytes a Chunk record may hold after its records (fields of a later MCAP version) before the scan
takes it for damage and skips it unread: a chunk's fields are read before its body."""
_USED = frozenset({Opcode.MESSAGE, Opcode.CHUNK, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA})
"""Data-section records the scan takes something from."""
_IN_CHUNK = frozenset({Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE})
"""The records a chunk may hold."""

_OPCODE_NAMES = {int(op): op.name.replace("_", " ").title().replace(" ", "") for op in Opcode}


def opcode_name(opcode: int) -> str:
    return _OPCODE_NAMES.get(opcode, f"unknown (opcode 0x{opcode:02x})")


def reserved(opcode: int) -> bool:
    """Whether no MCAP record has this opcode: 0x00 and 0x10-0x7f are reserved by the format (0x80 and
    up are private records, which a reader skips), so finding one means the framing is lost."""
    return opcode == 0 or 0x10 <= opcode < 0x80


class RawMessage(NamedTuple):
    """A message as stored: channel id, sequence, times (ns) and the CDR bytes. A named tuple: one is
    made per message read, and a tuple is made several times faster than a frozen dataclass."""

    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    data: bytes


@dataclass
class Block:
    """A unit of lazy loading: one chunk, or a run of loose message records."""

    offset: int
    length: int
    start: int
    end: int
    channels: frozenset[int] | None
    """Channel ids with messages in the block; None when unknown (no message index)."""
    is_chunk: bool
    order: int = 0


class _Damage(CocoError):
    """Framing or decoding failure inside a buffer: where (offset) and what."""

    def __init__(self, offset: int, detail: str) -> None:
        super().__init__(detail)
        self.offset = offset
        self.detail = detail


class _StrictStream(ReadDataStream):
    """The library's stream, but a short read is an error (not a silently short field)."""

    def read(self, length: int) -> bytes:
        data = super().read(length)
        if len(data) != length:
            raise EndOfFile()
        return data


def _parse(record_class: Any, body: bytes | memoryview) -> Any:
    """Parse a record body with the mcap library; a body that ends early raises ValueError."""
    try:
        return record_class.read(_StrictStream(BytesIO(body)))
    except (EndOfFile, struct.error, UnicodeDecodeError) as error:
        name = record_class.__name__
        raise BagFormatError(f"{name} record body is malformed ({type(error).__name__})") from None


def _message(body: bytes | memoryview) -> RawMessage:
    if len(body) < _MESSAGE_HEAD.size:
        raise BagFormatError(f"Message record of {len(body)} bytes, expected at least {_MESSAGE_HEAD.size}")
    channel_id, sequence, log_time, publish_time = _MESSAGE_HEAD.unpack_from(body)
    return RawMessage(channel_id, sequence, log_time, publish_time, bytes(body[_MESSAGE_HEAD.size :]))


def _records(buffer: memoryview, base: int) -> Iterator[tuple[int, int, memoryview]]:
    """(offset, opcode, body) of each record in a buffer whose first byte is at file offset ``base``."""
    position = 0
    size = len(buffer)
    while position < size:
        if size - position < _RECORD_HEAD.size:
            raise _Damage(base + position, f"record header cut after {size - position} of 9 bytes")
        opcode, length = _RECORD_HEAD.unpack_from(buffer, position)
        body_start = position + _RECORD_HEAD.size
        if length > size - body_start:
            raise _Damage(
                base + position,
                f"{opcode_name(opcode)} record declares {length} bytes but only {size - body_start} follow",
            )
        yield base + position, opcode, buffer[body_start : body_start + length]
        position = body_start + length


class _ChunkView(NamedTuple):
    """A Chunk record's fields, ``data`` a view into the record (no copy of the compressed bytes)."""

    message_start_time: int
    message_end_time: int
    uncompressed_size: int
    uncompressed_crc: int
    compression: str
    data: memoryview


_CHUNK_HEAD = struct.Struct("<QQQII")


def _chunk(body: bytes | memoryview) -> _ChunkView:
    """Parse a Chunk record body without copying its records (the library's parser reads them
    through a BytesIO, a copy of every chunk: a quarter of reading an uncompressed bag)."""
    view = memoryview(body)
    try:
        start, end, size, crc, name_length = _CHUNK_HEAD.unpack_from(view)
        position = _CHUNK_HEAD.size + name_length
        compression = bytes(view[_CHUNK_HEAD.size:position]).decode("utf-8")
        (length,) = struct.unpack_from("<Q", view, position)
    except (struct.error, UnicodeDecodeError) as error:
        raise BagFormatError(f"Chunk record body is malformed ({type(error).__name__})") from None
    data = view[position + 8:position + 8 + length]
    if len(data) != length:
        raise BagFormatError(f"Chunk record body is malformed (its records declare {length} bytes, {len(data)} follow)")
    return _ChunkView(start, end, size, crc, compression, data)


def _chunk_payload(chunk: _ChunkView) -> tuple[bytes | memoryview, bool]:
    """The decompressed records of a chunk, checked against its size, and whether they match its CRC:
    records that do not are still read, one by one (:func:`_resynchronised`)."""
    data: bytes | memoryview
    if chunk.compression == "":
        data = chunk.data
    elif chunk.compression == "zstd":
        import zstandard

        try:
            decompressor = zstandard.ZstdDecompressor()
            data = decompressor.decompress(chunk.data, max_output_size=chunk.uncompressed_size)
        except zstandard.ZstdError as error:
            raise BagFormatError(f"zstd data does not decompress ({error})") from None
    elif chunk.compression == "lz4":
        import lz4.frame

        try:
            data = lz4.frame.decompress(chunk.data)
        except RuntimeError as error:
            raise BagFormatError(f"lz4 data does not decompress ({error})") from None
    else:
        raise BagFormatError(
            f"chunk compression {chunk.compression!r} is not supported (expected '', zstd or lz4)"
        )
    if len(data) != chunk.uncompressed_size:
        raise BagFormatError(f"chunk holds {len(data)} bytes, its header says {chunk.uncompressed_size}")
    return data, not chunk.uncompressed_crc or zlib.crc32(data) == chunk.uncompressed_crc


_RECORD_START = re.compile(b"[\x03\x04\x05]")
"""A byte that may start a record inside a chunk (Schema, Channel, Message): where to try again."""


@dataclass
class Resynchronised:
    """The records of a chunk whose CRC does not match, read one by one (:func:`_resynchronised`)."""

    records: list[tuple[int, int, memoryview]]
    """(offset in the records, opcode, body) of each record that checks, in order."""
    skipped: list[tuple[int, int]]
    """Byte ranges (start, end) of the records skipped: framing or message header damaged."""


def _resynchronised(payload: bytes | memoryview, channels: Iterable[int], start: int, end: int) -> Resynchronised:
    """Read a chunk's records whose CRC does not match one by one, keeping those that check.

    Records are length-prefixed, so one damaged byte costs the record it is in: a record checks when
    its opcode is one a chunk holds, its length fits, the length of the record after it fits too (a
    damaged length points into data, whose bytes read as a length do not), and a message's channel is
    known (``channels``, or a Channel record before it) and its log time within the chunk's
    ``start``-``end``. Where a record does not check, reading resumes at the next byte where one does.
    A damaged value inside a message's data passes: its converter refuses it when it does not decode
    or is not finite.
    """
    buffer = memoryview(payload)
    raw = bytes(payload)
    known = set(channels)
    size = len(buffer)

    def fits(position: int) -> int | None:
        """The length of the record at ``position`` when the records hold it, or None."""
        if size - position < _RECORD_HEAD.size:
            return None
        length: int = _RECORD_HEAD.unpack_from(buffer, position)[1]
        return length if length <= size - position - _RECORD_HEAD.size else None

    def checks(position: int) -> int | None:
        length = fits(position)
        if length is None or buffer[position] not in _IN_CHUNK:
            return None
        following = position + _RECORD_HEAD.size + length
        if following != size and fits(following) is None:
            return None
        if buffer[position] == Opcode.MESSAGE:
            if length < _MESSAGE_HEAD.size:
                return None
            channel_id, _, log_time, _ = _MESSAGE_HEAD.unpack_from(buffer, position + _RECORD_HEAD.size)
            if channel_id not in known or not start <= log_time <= end:
                return None
        return length

    found = Resynchronised([], [])
    position = 0
    while position < size:
        length = checks(position)
        if length is not None:
            body = buffer[position + _RECORD_HEAD.size:position + _RECORD_HEAD.size + length]
            if buffer[position] == Opcode.CHANNEL and length >= 2:
                known.add(int.from_bytes(body[:2], "little"))
            found.records.append((position, buffer[position], body))
            position += _RECORD_HEAD.size + length
            continue
        resume = position + 1
        while resume < size and checks(resume) is None:
            match = _RECORD_START.search(raw, resume + 1)
            resume = match.start() if match else size
        found.skipped.append((position, resume))
        position = resume
    return found


def _indexed_messages(data: bytes) -> int | None:
    """Messages listed by the MessageIndex records at the start of ``data`` (those after a chunk:
    what it held), or None when there is none."""
    count, position = None, 0
    while len(data) - position >= _RECORD_HEAD.size + 6:
        opcode, length = _RECORD_HEAD.unpack_from(data, position)
        if opcode != Opcode.MESSAGE_INDEX or length > len(data) - position - _RECORD_HEAD.size:
            break
        (entries,) = struct.unpack_from("<I", data, position + _RECORD_HEAD.size + 2)
        count = (count or 0) + entries // 16
        position += _RECORD_HEAD.size + length
    return count


class _Unindexed(NamedTuple):
    """Why the summary section could not index the file: a ``reason``, and whether the summary is
    damaged (a file whose writer finished it has one that checks) or merely absent or partial, as a
    writer may leave it."""

    reason: str
    damage: bool


class McapFile:
    """Index and messages of one MCAP file; see the module docstring for the recovery rules."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.profile = ""
        self.library = ""
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.counts: dict[int, int] = {}
        self.message_count = 0
        self.start_time: int | None = None
        self.end_time: int | None = None
        self.metadata: dict[str, dict[str, str]] = {}
        self.blocks: list[Block] = []
        self.errors: list[BagError] = []
        """Damage found while opening: data that is lost, or a file that is not what its writer wrote
        (a damaged summary); reported after the readable messages."""
        self.notes: list[str] = []
        """What a writer may leave that costs nothing, e.g. a file without a summary section, scanned."""
        self.indexed_by = ""
        """'summary' or 'scan': where the block table came from."""
        self.unfinished_at: int | None = None
        """Byte where the data section ends without a DataEnd record (None: it has one, or the scan
        stopped at damage that :attr:`errors` reports)."""
        self._header_length = 0
        self._chunks_seen: dict[tuple[int, int, int, str, int], int] = {}
        """Scanned chunks by (times, size, compression, CRC of the stored bytes) -> their offset."""
        self._resynchronised: set[int] = set()
        """Chunks whose CRC does not match, by offset: reported once, when first read."""
        try:
            self._fd = os.open(self.path, os.O_RDONLY)
        except OSError as error:
            raise BagError(self.path, f"cannot open the file: {error.strerror}") from None
        try:
            self.size = os.fstat(self._fd).st_size
            self._open()
        except BaseException:
            self.close()
            raise

    # -- low level -------------------------------------------------------------------------------

    def _read(self, length: int, offset: int) -> bytes:
        if self._fd < 0:
            raise BagError(self.path, "the file was closed")
        chunks = []
        while length > 0:
            data = os.pread(self._fd, length, offset)
            if not data:
                break
            chunks.append(data)
            length -= len(data)
            offset += len(data)
        return b"".join(chunks)

    def close(self) -> None:
        if getattr(self, "_fd", -1) >= 0:
            os.close(self._fd)
            self._fd = -1

    def _damage(self, offset: int, detail: str) -> None:
        self.errors.append(BagError(self.path, detail, offset))

    # -- opening ---------------------------------------------------------------------------------

    def _open(self) -> None:
        head = self._read(len(MAGIC), 0)
        if head != MAGIC:
            if MAGIC.startswith(head):
                self._damage(
                    0,
                    f"the file ({len(head)} bytes) is truncated inside the 8-byte MCAP magic: "
                    "nothing is readable",
                )
                self.indexed_by = "scan"
                return
            raise BagError(
                self.path,
                "not an MCAP file: expected the MCAP magic bytes 89 4d 43 41 50 30 0d 0a "
                f"('\\x89MCAP0\\r\\n') at the start, found {head!r}",
                0,
            )
        header = self._header()
        if header is None:
            self.indexed_by = "scan"
            return
        self.profile, self.library = header.profile, header.library
        unindexed = self._read_summary()
        if unindexed is None:
            return
        complete = self._scan(len(MAGIC) + self._header_length)
        if not unindexed.damage:
            self.notes.append(f"{unindexed.reason}; scanned the data")
        elif complete:  # else the cut or the break the scan reported explains the end of the file
            self._damage(self.size, f"{unindexed.reason}; its data section is whole and was read by scanning: its "
                                    f"{self.message_count} messages are readable")

    def _read_summary(self) -> _Unindexed | None:
        """Index from the summary section; why not (nothing changed) when it is missing or unusable."""
        footer_offset = self.size - len(MAGIC) - _FOOTER_LENGTH
        if footer_offset < len(MAGIC) or self._read(len(MAGIC), self.size - len(MAGIC)) != MAGIC:
            return _Unindexed("the file has no MCAP footer: what follows its data section (summary and footer) is "
                              "missing, the file is cut there or its writer did not finish it", True)
        raw_footer = self._read(_FOOTER_LENGTH, footer_offset)
        opcode, length = _RECORD_HEAD.unpack_from(raw_footer)
        if opcode != Opcode.FOOTER or length != 20:
            return _Unindexed(f"the MCAP footer is malformed (a {opcode_name(opcode)} record of {length} bytes where "
                              "the 20-byte Footer should be)", True)
        footer: Footer = _parse(Footer, raw_footer[9:])
        if footer.summary_start == 0:
            return _Unindexed("the file has no summary section", False)
        if not len(MAGIC) < footer.summary_start <= footer_offset:
            return _Unindexed(f"the MCAP footer places the summary section at byte {footer.summary_start}, outside "
                              f"the file's {footer_offset} bytes before the footer", True)
        summary = self._read(footer_offset - footer.summary_start, footer.summary_start)
        if footer.summary_crc:
            crc = zlib.crc32(raw_footer[: 9 + 16], zlib.crc32(summary))
            if crc != footer.summary_crc:
                return _Unindexed(f"the summary section (from byte {footer.summary_start}) does not match its CRC",
                                  True)
        schemas, channels, chunk_indexes, metadata_indexes = {}, {}, [], []
        statistics: Statistics | None = None
        try:
            for _, op, body in _records(memoryview(summary), footer.summary_start):
                if op == Opcode.SCHEMA:
                    schema = _parse(Schema, body)
                    schemas[schema.id] = schema
                elif op == Opcode.CHANNEL:
                    channel = _parse(Channel, body)
                    channels[channel.id] = channel
                elif op == Opcode.CHUNK_INDEX:
                    chunk_indexes.append(_parse(ChunkIndex, body))
                elif op == Opcode.STATISTICS:
                    statistics = _parse(Statistics, body)
                elif op == Opcode.METADATA_INDEX:
                    metadata_indexes.append(_parse(MetadataIndex, body))
        except (_Damage, ValueError) as error:
            return _Unindexed(f"the summary section (from byte {footer.summary_start}) is malformed ({error})", True)
        if statistics is None or statistics.chunk_count != len(chunk_indexes):
            return _Unindexed("the summary has no statistics or not every chunk index", False)
        if len(channels) < statistics.channel_count or len(schemas) < statistics.schema_count:
            return _Unindexed("the summary does not repeat every channel and schema", False)
        if statistics.message_count and not chunk_indexes:
            return _Unindexed("the file is not chunked: loose messages have no index", False)
        self.schemas, self.channels = schemas, channels
        self.counts = dict(statistics.channel_message_counts)
        self.message_count = statistics.message_count
        if statistics.message_count:
            self.start_time, self.end_time = statistics.message_start_time, statistics.message_end_time
        for order, index in enumerate(sorted(chunk_indexes, key=lambda c: c.chunk_start_offset)):
            present = frozenset(index.message_index_offsets) or None
            self.blocks.append(
                Block(
                    index.chunk_start_offset,
                    index.chunk_length,
                    index.message_start_time,
                    index.message_end_time,
                    present,
                    True,
                    order,
                )
            )
        for index in metadata_indexes:
            try:
                for _, op, body in _records(memoryview(self._read(index.length, index.offset)), index.offset):
                    if op == Opcode.METADATA:
                        record = _parse(Metadata, body)
                        self.metadata[record.name] = dict(record.metadata)
            except (_Damage, ValueError):
                continue  # metadata is informative only
        self.indexed_by = "summary"
        return None

    def _header(self) -> Header | None:
        """The Header record after the magic (its size goes to ``_header_length``); None if damaged."""
        raw = self._read(_RECORD_HEAD.size, len(MAGIC))
        truncated = (
            f"the file ({self.size} bytes) is truncated inside the MCAP Header record: nothing is readable"
        )
        if len(raw) < _RECORD_HEAD.size:
            self._damage(len(MAGIC), truncated)
            return None
        opcode, length = _RECORD_HEAD.unpack(raw)
        if opcode != Opcode.HEADER:
            found = opcode_name(opcode)
            self._damage(len(MAGIC), f"expected the MCAP Header record after the magic, found {found}")
            return None
        body = self._read(length, len(MAGIC) + _RECORD_HEAD.size)
        if len(body) < length:
            self._damage(len(MAGIC), truncated)
            return None
        try:
            header = _parse(Header, body)
        except ValueError as error:
            self._damage(len(MAGIC), f"{error}: nothing is readable")
            return None
        self._header_length = _RECORD_HEAD.size + length
        return header

    def _count(self, message: RawMessage) -> None:
        self.counts[message.channel_id] = self.counts.get(message.channel_id, 0) + 1
        self.message_count += 1
        if self.start_time is None or message.log_time < self.start_time:
            self.start_time = message.log_time
        if self.end_time is None or message.log_time > self.end_time:
            self.end_time = message.log_time

    def _scan(self, position: int) -> bool:
        """Index by reading the data section record by record from ``position`` (after the Header);
        whether it ended at its DataEnd record (or a Footer) rather than at damage or the file's end."""
        self.indexed_by = "scan"
        run: Block | None = None
        skipped, skipped_from = 0, position  # records in a row that gave nothing (SKIPPED_RUN), from where

        def close_run() -> None:
            nonlocal run
            if run is not None:
                run.order = len(self.blocks)
                self.blocks.append(run)
                run = None

        while True:
            raw = self._read(_RECORD_HEAD.size, position)
            if not raw:
                self.unfinished_at = position
                break
            if len(raw) < _RECORD_HEAD.size:
                cut = f"the record header is cut after {len(raw)} of 9 bytes"
                self._damage(position, self._cut(position, cut))
                break
            opcode, length = _RECORD_HEAD.unpack(raw)
            if reserved(opcode):
                self._damage(position, self._not_mcap(position, f"opcode 0x{opcode:02x} is reserved, no MCAP record "
                                                                "starts with it"))
                break
            skipped, skipped_from = (0, position) if opcode in _USED else (skipped + 1, skipped_from)
            if skipped > SKIPPED_RUN:
                self._damage(skipped_from, self._not_mcap(skipped_from, f"{skipped} records in a row from here "
                                                                        "(private opcodes, indexes) hold no message"))
                break
            body_start = position + _RECORD_HEAD.size
            available = self.size - body_start
            if length > available:
                cut = f"a {opcode_name(opcode)} record declares {length} bytes but the file ends {available} bytes later"
                salvaged, stopped_at = self._salvage_cut_chunk(body_start, available) if opcode == Opcode.CHUNK \
                    else (0, 0)
                if salvaged:  # named where reading stopped: the first record of the chunk that is cut
                    cut = (f"the Chunk record at byte {position} declares {length} bytes but the file ends {available} "
                           f"bytes later ({salvaged} of its messages, the complete records before this byte, are read)")
                self._damage(stopped_at or position, self._cut(stopped_at or position, cut))
                break
            next_position = body_start + length
            if opcode == Opcode.MESSAGE:
                try:
                    message = _message(self._read(min(length, _MESSAGE_HEAD.size), body_start))
                except ValueError as error:
                    self._damage(position, f"{error}; skipped it")
                else:
                    self._count(message)
                    if run is None or run.length >= _RUN_BYTES:
                        close_run()
                        run = Block(position, 0, message.log_time, message.log_time, frozenset(), False)
                    run.start = min(run.start, message.log_time)
                    run.end = max(run.end, message.log_time)
                    run.channels = (run.channels or frozenset()) | {message.channel_id}
                if run is not None:
                    run.length = next_position - run.offset
            elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA) and length > RECORD_LIMIT:
                self._damage(position, f"this {opcode_name(opcode)} record declares {length} bytes, more than the "
                                       f"{RECORD_LIMIT} any bag needs; skipped it unread")
            elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                try:
                    self._register(opcode, self._read(length, body_start))
                except ValueError as error:
                    self._damage(position, f"{error}; skipped it")
                if run is not None:
                    run.length = next_position - run.offset
            elif opcode == Opcode.CHUNK:
                close_run()
                unframed = self._chunk_unframed(body_start, length)
                if unframed:
                    self._damage(position, f"{unframed}; skipped it unread, the messages it held are lost")
                else:
                    self._scan_chunk(position, length, body_start)
            elif opcode == Opcode.METADATA:
                try:
                    record = _parse(Metadata, self._read(length, body_start))
                    self.metadata[record.name] = dict(record.metadata)
                except ValueError:
                    pass  # metadata is informative only
            elif opcode in (Opcode.DATA_END, Opcode.FOOTER):
                close_run()
                return True
            position = next_position
        close_run()
        return False

    def _chunk_unframed(self, body_start: int, length: int) -> str:
        """Why the Chunk record of ``length`` bytes at ``body_start`` is not one, from its fields alone
        (read before its body, which may be gigabytes of what is not MCAP data); '' when it is."""
        if length < _CHUNK_HEAD.size:
            return f"this Chunk record of {length} bytes is too short for its fields"
        name_length = _CHUNK_HEAD.unpack(self._read(_CHUNK_HEAD.size, body_start))[4]
        records_at = _CHUNK_HEAD.size + name_length + 8
        if records_at > length:
            return f"this Chunk record of {length} bytes is too short for its fields ({records_at} bytes)"
        (records,) = struct.unpack("<Q", self._read(8, body_start + records_at - 8))
        if records_at + records > length or length - records_at - records > _CHUNK_SLACK:
            return f"the fields of this Chunk record of {length} bytes account for {records_at + records} of them"
        return ""

    def _not_mcap(self, position: int, what: str) -> str:
        return (f"{what}: the data section breaks off and the remaining {self.size - position} bytes of the file "
                f"are not MCAP data, so they are not read; the {self.message_count} messages before this point "
                "are readable")

    def _cut(self, position: int, what: str) -> str:
        return (
            f"{what}: the file ({self.size} bytes) is truncated; the {self.message_count} messages "
            "before this point are readable, whatever followed is lost"
        )

    def _register(self, opcode: int, body: bytes | memoryview) -> None:
        if opcode == Opcode.SCHEMA:
            schema = _parse(Schema, body)
            self.schemas.setdefault(schema.id, schema)
        else:
            channel = _parse(Channel, body)
            self.channels.setdefault(channel.id, channel)

    def _scan_chunk(self, position: int, length: int, body_start: int) -> None:
        try:
            chunk = _chunk(self._read(length, body_start))
            key = (chunk.message_start_time, chunk.message_end_time, chunk.uncompressed_size, chunk.compression,
                   zlib.crc32(chunk.data))
            original = self._chunks_seen.setdefault(key, position)
            if original != position:
                self._damage(
                    position,
                    f"this Chunk record ({length} bytes) repeats the one at byte {original} byte for byte "
                    "(a duplicated copy); skipped it, so that its messages are delivered once",
                )
                return
            messages = []
            for _, op, body in self._chunk_records(position, body_start + length, chunk, self._damage):
                if op in (Opcode.SCHEMA, Opcode.CHANNEL):
                    self._register(op, body)
                elif op == Opcode.MESSAGE:
                    messages.append(_message(body))
        except (ValueError, _Damage) as error:
            self._damage(
                position,
                f"the Chunk record ({length} bytes) cannot be decoded: {error}; skipped it, "
                "the messages it held are lost",
            )
            return
        if not messages:
            return
        for message in messages:
            self._count(message)
        self.blocks.append(
            Block(
                position,
                _RECORD_HEAD.size + length,
                min(m.log_time for m in messages),
                max(m.log_time for m in messages),
                frozenset(m.channel_id for m in messages),
                True,
                len(self.blocks),
            )
        )

    def _chunk_records(self, offset: int, end: int, chunk: _ChunkView,
                       report: Callable[[int, str], None]) -> Iterable[tuple[int, int, memoryview]]:
        """(offset, opcode, body) of the records of the Chunk record at bytes ``offset``-``end``: all of
        them when they match its CRC; else those that check (:func:`_resynchronised`), and the chunk
        is reported, once, through ``report(offset, detail)``."""
        payload, intact = _chunk_payload(chunk)
        if intact:
            return _records(memoryview(payload), 0)
        found = _resynchronised(payload, self.channels, chunk.message_start_time, chunk.message_end_time)
        if offset not in self._resynchronised:
            self._resynchronised.add(offset)
            report(offset, self._resynchronised_damage(end, found))
        return found.records

    def _resynchronised_damage(self, end: int, found: Resynchronised) -> str:
        """What a chunk whose CRC does not match lost: counted against the MessageIndex records after it
        (at byte ``end``), which list every message it held, when they are there."""
        delivered = sum(1 for _, opcode, _ in found.records if opcode == Opcode.MESSAGE)
        expected = _indexed_messages(self._read(min(4 * _RUN_BYTES, self.size - end), end))
        if expected is not None:
            lost = f"{max(expected - delivered, 0)} of the {expected} messages its index lists are lost"
        else:
            lost = f"{len(found.skipped)} damaged stretch(es) of records, a message or more each, are lost"
        detail = (f"the Chunk record's CRC does not match its records (damaged bytes): read them one by one, "
                  f"{delivered} messages delivered, {lost}")
        if found.skipped:
            shown = ", ".join(f"{start}-{stop}" for start, stop in found.skipped[:5])
            return f"{detail} (records skipped at bytes {shown} of its records, where framing or header is damaged)"
        return (f"{detail}; no record's framing or message header is damaged, so the damage is inside a message's "
                "data: a value that does not decode or is not finite is refused by its converter, another passes")

    def _salvage_cut_chunk(self, body_start: int, available: int) -> tuple[int, int]:
        """Index the complete records of an uncompressed chunk that the end of the file cuts, as a
        block of loose records: (messages found, byte where the first incomplete record starts).
        (0, 0) when the chunk is compressed (a compressed stream cut short does not check against its
        size and CRC) or holds no complete message."""
        raw = memoryview(self._read(available, body_start))
        try:
            name_length = _CHUNK_HEAD.unpack_from(raw)[4]
            compression = bytes(raw[_CHUNK_HEAD.size:_CHUNK_HEAD.size + name_length]).decode("utf-8")
        except (struct.error, UnicodeDecodeError):
            return 0, 0
        records_start = body_start + _CHUNK_HEAD.size + name_length + 8
        if compression != "" or records_start > body_start + available:
            return 0, 0
        messages: list[RawMessage] = []
        end = records_start
        try:
            for offset, op, body in _records(raw[records_start - body_start:], records_start):
                if op in (Opcode.SCHEMA, Opcode.CHANNEL):
                    self._register(op, body)
                elif op == Opcode.MESSAGE:
                    messages.append(_message(body))
                end = offset + _RECORD_HEAD.size + len(body)
        except (_Damage, ValueError):
            pass  # the cut (or the first broken record): what precedes it is complete
        if not messages:
            return 0, 0
        for message in messages:
            self._count(message)
        self.blocks.append(
            Block(
                records_start,
                end - records_start,
                min(m.log_time for m in messages),
                max(m.log_time for m in messages),
                frozenset(m.channel_id for m in messages),
                False,
                len(self.blocks),
            )
        )
        return len(messages), end

    # -- messages --------------------------------------------------------------------------------

    def _load(
        self, block: Block, channel_ids: frozenset[int] | None, start: int, end: int | None,
        on_error: Callable[[BagError], None] | None,
    ) -> list[RawMessage]:
        buffer = memoryview(self._read(block.length, block.offset))
        if len(buffer) < block.length:
            raise _Damage(block.offset, f"the block declares {block.length} bytes but the file ends before")
        wanted: list[RawMessage] = []

        def keep(message: RawMessage) -> None:
            if channel_ids is not None and message.channel_id not in channel_ids:
                return
            if message.log_time < start or (end is not None and message.log_time >= end):
                return
            wanted.append(message)

        def report(offset: int, detail: str) -> None:
            if on_error is not None:
                on_error(BagError(self.path, detail, offset))

        for offset, op, body in _records(buffer, block.offset):
            try:
                if op == Opcode.CHUNK:
                    chunk_end = offset + _RECORD_HEAD.size + len(body)
                    for _, inner, inner_body in self._chunk_records(offset, chunk_end, _chunk(body), report):
                        if inner == Opcode.MESSAGE:
                            keep(_message(inner_body))
                elif op == Opcode.MESSAGE:
                    keep(_message(body))
            except ValueError as error:
                raise _Damage(offset, f"the {opcode_name(op)} record cannot be decoded: {error}") from None
        return wanted  # in file order; the merge in iter_messages orders by log time

    def iter_messages(
        self,
        channel_ids: frozenset[int] | None = None,
        start: int | None = None,
        end: int | None = None,
        on_error: Callable[[BagError], None] | None = None,
    ) -> Iterator[RawMessage]:
        """Messages of these channels with ``start <= log_time < end``, in log-time order.

        A block that cannot be read is skipped and reported through ``on_error`` (its messages are
        lost, the others still come).
        """
        start = 0 if start is None else start
        blocks = [
            b
            for b in self.blocks
            if b.end >= start
            and (end is None or b.start < end)
            and (channel_ids is None or b.channels is None or b.channels & channel_ids)
        ]
        blocks.sort(key=lambda b: (b.start, b.order))
        heap: list[tuple[int, int, int, RawMessage]] = []
        next_block = 0
        while next_block < len(blocks) or heap:
            while next_block < len(blocks) and (not heap or blocks[next_block].start <= heap[0][0]):
                block = blocks[next_block]
                next_block += 1
                try:
                    loaded = self._load(block, channel_ids, start, end, on_error)
                except _Damage as damage:
                    if on_error is not None:
                        detail = f"{damage.detail}; skipped it, the messages it held are lost"
                        on_error(BagError(self.path, detail, damage.offset))
                    continue
                for index, message in enumerate(loaded):
                    heapq.heappush(heap, (message.log_time, block.order, index, message))
            if heap:
                yield heapq.heappop(heap)[3]
