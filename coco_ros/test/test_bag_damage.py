"""Damaged bags: every readable message comes out, then an error names the file and the byte.

Cases: files cut at many positions (a recorder killed mid-write, a copy interrupted), a chunk
corrupted in the middle of an otherwise complete file, a writer killed by SIGKILL after its last
flush, a writer stopped by Ctrl-C, and files that are not MCAP at all.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from coco_core.errors import BagError
from coco_ros.bag import BagReader, BagWriter

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
COUNT = 300


@pytest.fixture(scope="module", params=["none", "zstd"])
def intact(request, tmp_path_factory) -> tuple[Path, list[tuple[str, int, str]], list]:
    """(mcap file, its messages as (topic, log time, text), its chunk indexes), several chunks."""
    from std_msgs.msg import String

    folder = tmp_path_factory.mktemp(f"damage_{request.param}") / "bag"
    with BagWriter(folder, compression=request.param, chunk_size=2048) as writer:
        for i in range(COUNT):
            topic = "/a" if i % 3 else "/b"
            writer.write(topic, String(data=f"message {i:04d} " + "x" * (i % 50)), T0 + i * MS)
    path = folder / "bag_0.mcap"
    with BagReader(path) as reader:
        messages = [(m.topic, m.log_time, m.message.data) for m in reader.messages()]
    from mcap.reader import make_reader

    with open(path, "rb") as stream:
        chunks = sorted(make_reader(stream).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(chunks) >= 5
    return path, messages, chunks


def read_all(path: Path) -> tuple[list[tuple[str, int, str]], BagError | None, BagReader]:
    """Messages yielded before the error (if any) and the error raised after them."""
    reader = BagReader(path)
    got = []
    try:
        for message in reader.messages():
            got.append((message.topic, message.log_time, message.message.data))
    except BagError as error:
        return got, error, reader
    return got, None, reader


def readable_before(data: bytes, messages, chunks, cut: int) -> int:
    """Messages a file cut at ``cut`` still holds whole: those of the chunks before the cut and, when
    the cut goes through an uncompressed chunk, its message records that end before the cut."""
    import struct

    complete = [c for c in chunks if c.chunk_start_offset + c.chunk_length <= cut]
    count = sum(1 for _, t, _ in messages if any(c.message_start_time <= t <= c.message_end_time for c in complete))
    cut_through = [c for c in chunks if c.chunk_start_offset < cut < c.chunk_start_offset + c.chunk_length]
    if not cut_through or cut_through[0].compression != "":
        return count
    # The Chunk record: opcode and length (9), start, end, size, CRC, compression name, records length.
    position = cut_through[0].chunk_start_offset + 9 + 28
    if position + 4 > cut:
        return count
    position += 4 + struct.unpack_from("<I", data, position)[0] + 8
    while position + 9 <= cut:
        opcode, length = struct.unpack_from("<BQ", data, position)
        position += 9 + length
        if position > cut:
            break
        count += opcode == 0x05  # a Message record
    return count


def cut_positions(chunks) -> list[tuple[str, int]]:
    """Named cut points in the data section: inside the header, inside chunks, between chunks."""
    middle = chunks[len(chunks) // 2]
    last = chunks[-1]
    size = last.chunk_start_offset + last.chunk_length
    return [
        ("header", 12),
        ("first chunk", chunks[0].chunk_start_offset + 5),
        ("middle chunk start", middle.chunk_start_offset + 1),
        ("middle chunk body", middle.chunk_start_offset + middle.chunk_length // 2),
        ("middle chunk last byte", middle.chunk_start_offset + middle.chunk_length - 1),
        ("last chunk", last.chunk_start_offset + last.chunk_length // 3),
        ("40 % of the data", size * 2 // 5),
        ("70 % of the data", size * 7 // 10),
        ("message index after a chunk", middle.chunk_start_offset + middle.chunk_length + 3),
    ]


def test_truncated_files_yield_everything_before_the_cut_then_name_file_and_byte(intact, tmp_path):
    path, messages, chunks = intact
    data = path.read_bytes()
    for name, cut in cut_positions(chunks):
        damaged = tmp_path / f"cut_{cut}.mcap"
        damaged.write_bytes(data[:cut])
        readable = readable_before(data, messages, chunks, cut)
        got, error, reader = read_all(damaged)
        assert got == messages[:readable], f"cut {name} at byte {cut}: {len(got)} messages, expected {readable}"
        assert error is not None, f"cut {name} at byte {cut}: no error"
        assert error.path == str(damaged) and str(damaged) in str(error)
        assert error.offset is not None and 8 <= error.offset < cut, (name, cut, error)
        assert f"at byte {error.offset}" in str(error) and "truncated" in str(error)
        assert reader.damaged and reader.errors[0].offset == error.offset
        assert reader.message_count == readable
        reader.close()


def test_a_cut_in_the_summary_loses_no_message_and_is_damage(intact, tmp_path):
    """Every message is read by scanning, then an error names the missing footer at the file's end:
    a file whose end is gone is not what its writer wrote (``truncate -s -100`` exited 0)."""
    path, messages, chunks = intact
    data = path.read_bytes()
    last = chunks[-1]
    for cut in (last.chunk_start_offset + last.chunk_length + last.message_index_length + 20, len(data) - 10,
                len(data) - 100):
        damaged = tmp_path / f"summary_cut_{cut}.mcap"
        damaged.write_bytes(data[:cut])
        got, error, reader = read_all(damaged)
        assert got == messages and error is not None, cut
        assert error.path == str(damaged) and error.offset == cut and "no MCAP footer" in str(error), error
        assert f"its {COUNT} messages are readable" in str(error)
        reader.close()


def test_a_summary_that_does_not_match_its_crc_is_damage(intact, tmp_path):
    """One byte of the summary section flipped: every message is read by scanning, and an error names
    the summary (it was a note)."""
    import struct

    path, messages, _ = intact
    data = bytearray(path.read_bytes())
    (summary_start,) = struct.unpack_from("<Q", data, len(data) - 8 - 20)  # the Footer's first field
    data[summary_start + 12] ^= 0x01
    damaged = tmp_path / "summary_crc.mcap"
    damaged.write_bytes(bytes(data))
    got, error, reader = read_all(damaged)
    reader.close()
    assert got == messages and error is not None and error.path == str(damaged)
    assert f"the summary section (from byte {summary_start}) does not match its CRC" in str(error), error


def test_on_error_callback_reports_instead_of_raising(intact, tmp_path):
    path, messages, chunks = intact
    damaged = tmp_path / "cut.mcap"
    damaged.write_bytes(path.read_bytes()[: chunks[3].chunk_start_offset + 7])
    reported: list[BagError] = []
    with BagReader(damaged, on_error=reported.append) as reader:
        got = [m.log_time for m in reader.messages()]
    assert got == [t for _, t, _ in messages[: len(got)]] and got
    assert len(reported) == 1 and reported[0].offset == chunks[3].chunk_start_offset


def read_raw(path: Path) -> tuple[list[tuple[str, int, bytes]], list[BagError]]:
    """Every message as (topic, log time, CDR bytes), nothing decoded, and the errors reported."""
    reported: list[BagError] = []
    with BagReader(path, on_error=reported.append) as reader:
        return [(m.topic, m.log_time, m.data) for m in reader.messages()], reported


def test_a_corrupt_chunk_in_a_complete_file_costs_only_the_damaged_message(intact, tmp_path):
    """A byte flipped in a message's data: the chunk's CRC no longer matches. A compressed chunk no
    longer decompresses and its messages are lost; the records of an uncompressed one are read one by
    one and each is delivered (the damaged value is its converter's to refuse), and the chunk is
    reported (the whole chunk was dropped: 1,035 of 1,044 samples)."""
    path, messages, chunks = intact
    data = bytearray(path.read_bytes())
    bad = chunks[2]
    position = bad.chunk_start_offset + bad.chunk_length - 20  # inside the chunk's last message's data
    intact_raw, _ = read_raw(path)
    data[position] ^= 0xFF
    damaged = tmp_path / "corrupt.mcap"
    damaged.write_bytes(bytes(data))
    got, reported = read_raw(damaged)
    in_chunk = [m for m in intact_raw if bad.message_start_time <= m[1] <= bad.message_end_time]
    assert len(reported) == 1 and reported[0].offset == bad.chunk_start_offset and reported[0].path == str(damaged)
    if bad.compression:
        assert got == [m for m in intact_raw if m not in in_chunk]
        assert "Chunk" in str(reported[0]) and "lost" in str(reported[0])
        return
    assert [m[:2] for m in got] == [m[:2] for m in intact_raw]
    assert [i for i, (a, b) in enumerate(zip(got, intact_raw)) if a != b] == [intact_raw.index(in_chunk[-1])]
    assert "CRC does not match" in str(reported[0]) and f"0 of the {len(in_chunk)} messages" in str(reported[0])
    assert "the damage is inside a message's data" in str(reported[0])


def message_records(data: bytes, chunk) -> list[int]:
    """File offsets of the Message records inside an uncompressed chunk."""
    import struct

    name_length = struct.unpack_from("<I", data, chunk.chunk_start_offset + 9 + 28)[0]
    position = chunk.chunk_start_offset + 9 + 32 + name_length + 8
    end = chunk.chunk_start_offset + chunk.chunk_length
    found = []
    while position < end:
        opcode, length = struct.unpack_from("<BQ", data, position)
        if opcode == 0x05:
            found.append(position)
        position += 9 + length
    return found


@pytest.mark.parametrize("field, at", [("opcode", 0), ("length", 1), ("channel id", 9), ("log time", 9 + 2 + 4 + 7)])
def test_a_damaged_record_in_a_chunk_costs_that_message_only(intact, tmp_path, field, at):
    """A byte of one message record's framing or header damaged (the chunk's CRC then fails): the
    records are length-prefixed, so reading resumes at the next record that checks; that message is
    lost, and the error counts it against the chunk's message index."""
    path, messages, chunks = intact
    chunk = chunks[2]
    if chunk.compression:
        pytest.skip("a compressed chunk whose data changed does not decompress: its records cannot be reached")
    data = bytearray(path.read_bytes())
    victim = message_records(bytes(data), chunk)[3]
    data[victim + at] ^= 0x40
    damaged = tmp_path / "record.mcap"
    damaged.write_bytes(bytes(data))
    intact_raw, _ = read_raw(path)
    got, reported = read_raw(damaged)
    in_chunk = [m for m in intact_raw if chunk.message_start_time <= m[1] <= chunk.message_end_time]
    assert got == [m for m in intact_raw if m != in_chunk[3]], field
    assert len(reported) == 1 and reported[0].offset == chunk.chunk_start_offset, reported
    assert f"1 of the {len(in_chunk)} messages its index lists are lost" in str(reported[0]), reported[0]
    assert "records skipped at bytes" in str(reported[0])


def test_not_mcap_files_are_refused_at_once(tmp_path):
    text = tmp_path / "notes.mcap"
    text.write_text("this is not a bag\n")
    with pytest.raises(BagError, match=r"notes\.mcap at byte 0: not an MCAP file: expected the MCAP magic"):
        BagReader(text)
    sqlite = tmp_path / "old.db3"
    sqlite.write_bytes(b"SQLite format 3\x00" + bytes(100))
    with pytest.raises(BagError, match=r"old\.db3: the SQLite database is damaged or not a rosbag2 bag"):
        BagReader(sqlite)
    with pytest.raises(BagError, match="no such bag"):
        BagReader(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(BagError, match="expected metadata.yaml or at least one .mcap or .db3 file"):
        BagReader(tmp_path / "empty")


def test_metadata_yaml_problems_name_the_file(tmp_path):
    from std_msgs.msg import String

    folder = tmp_path / "bag"
    with BagWriter(folder) as writer:
        writer.write("/a", String(data="a"), T0)
    meta = (folder / "metadata.yaml").read_text()
    (folder / "bag_0.mcap").unlink()
    with pytest.raises(BagError, match=r"metadata\.yaml: lists files that are missing: .*bag_0\.mcap"):
        BagReader(folder)
    (folder / "metadata.yaml").write_text(meta.replace("storage_identifier: mcap", "storage_identifier: leveldb"))
    with pytest.raises(BagError, match="storage 'leveldb' is not supported: expected 'mcap' or 'sqlite3'"):
        BagReader(folder)
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: [not, a, mapping]\n")
    with pytest.raises(BagError, match="expected a mapping 'rosbag2_bagfile_information'"):
        BagReader(folder)


def test_a_broken_or_missing_metadata_yaml_beside_good_files_is_damage(tmp_path):
    """The .mcap files are read, then an error names metadata.yaml: without its counts a loss would not
    show (a deleted metadata.yaml exited 0)."""
    from std_msgs.msg import String

    folder = tmp_path / "bag"
    with BagWriter(folder) as writer:
        writer.write("/a", String(data="a"), T0)
    text = (folder / "metadata.yaml").read_text()
    (folder / "metadata.yaml").write_text(text[: len(text) // 2] + "\n  - [unbalanced")
    reported: list[BagError] = []
    with BagReader(folder, on_error=reported.append) as reader:
        assert [m.message.data for m in reader.messages()] == ["a"]
        assert reader.metadata is None and reader.damaged
    assert [e.path for e in reported] == [str(folder / "metadata.yaml")]
    assert "cannot read it as YAML" in str(reported[0]) and "a loss would not show" in str(reported[0])
    (folder / "metadata.yaml").unlink()
    got, error, reader = read_all(folder)
    reader.close()
    assert [m[2] for m in got] == ["a"] and error is not None and error.path == str(folder / "metadata.yaml")
    assert "missing: a rosbag2 bag folder has one" in str(error) and "1 .mcap file(s) are read" in str(error)
    with BagReader(folder / "bag_0.mcap") as reader:  # the file alone: a file, not a folder, is asked for
        assert [m.message.data for m in reader.messages()] == ["a"] and not reader.damaged


def sparse_bag(path: Path, size: int, tail: bytes = b"") -> Path:
    """An MCAP magic and Header record, ``tail`` after them, then zeros up to ``size`` bytes, stored
    sparse (``truncate``): no disk, no time."""
    import struct

    header = struct.pack("<I", 4) + b"ros2" + struct.pack("<I", 4) + b"test"
    with open(path, "wb") as stream:
        stream.write(b"\x89MCAP0\r\n" + struct.pack("<BQ", 0x01, len(header)) + header + tail)
    os.truncate(path, max(size, path.stat().st_size))
    return path


def open_within(path: Path, seconds: float) -> tuple[BagReader, float]:
    """Open ``path``; a real SIGALRM ends the opening if it takes longer than ``seconds``."""
    import time

    def expired(_signum, _frame):
        raise TimeoutError(f"opening {path} took more than {seconds} s")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    started = time.monotonic()
    try:
        return BagReader(path), time.monotonic() - started
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def test_a_large_file_that_is_mostly_not_mcap_is_refused_at_once(tmp_path):
    """A valid Header, then 2 GB of zeros: the scan walked them nine bytes at a time (over 10 minutes at
    100 % CPU). A reserved opcode ends the data section: the error names the byte and the bytes not read."""
    path = sparse_bag(tmp_path / "zeros.mcap", 2 << 30)
    reader, took = open_within(path, 5.0)
    with reader:
        assert took < 2.0 and reader.message_count == 0
        assert [e.offset for e in reader.errors] == [33]
        assert "opcode 0x00 is reserved" in str(reader.errors[0])
        assert f"the remaining {(2 << 30) - 33} bytes of the file are not MCAP data" in str(reader.errors[0])
        with pytest.raises(BagError, match="not MCAP data"):
            list(reader.messages())


@pytest.mark.parametrize("opcode", [0x06, 0x03, 0x0C])
def test_a_record_that_declares_the_whole_file_is_refused_before_it_is_read(tmp_path, opcode):
    """A Chunk, Schema or Metadata record declaring 2 GB of zeros: the Chunk's own fields account for
    none of them, and no schema or metadata is that large, so it is skipped unread, named as damage
    (15 s and 2 GB of memory for the chunk, which then passed as an empty one)."""
    import struct

    size = 2 << 30
    path = sparse_bag(tmp_path / "declared.mcap", size, struct.pack("<BQ", opcode, size - 33 - 9))
    reader, took = open_within(path, 5.0)
    with reader:
        assert took < 2.0 and [e.offset for e in reader.errors][:1] == [33], reader.errors
        assert "skipped it unread" in str(reader.errors[0]) and str(size - 33 - 9) in str(reader.errors[0])
        assert reader.damaged and reader.message_count == 0


def test_a_run_of_records_that_hold_no_message_is_refused_at_once(tmp_path):
    """Noise framed as tiny private records (opcode 0x80, 0 bytes each) for 50 MB: refused after
    SKIPPED_RUN of them, at the byte where the run began."""
    import struct

    from coco_ros.bag.mcap_file import SKIPPED_RUN

    path = sparse_bag(tmp_path / "private.mcap", 50 << 20, struct.pack("<BQ", 0x80, 0) * (SKIPPED_RUN + 10))
    reader, took = open_within(path, 5.0)
    with reader:
        assert took < 2.0 and [e.offset for e in reader.errors] == [33], reader.errors
        assert f"{SKIPPED_RUN + 1} records in a row from here" in str(reader.errors[0])


def test_an_empty_or_tiny_file_reads_as_nothing_with_an_error(tmp_path):
    for size in (0, 5, 8, 15):
        path = tmp_path / f"tiny_{size}.mcap"
        path.write_bytes(b"\x89MCAP0\r\n\x01\x00\x00\x00\x00\x00\x00\x00"[:size])
        got, error, reader = read_all(path)
        assert got == [] and error is not None and str(path) in str(error), size
        assert "nothing is readable" in str(error)
        reader.close()


WRITER_CHILD = textwrap.dedent(
    """
    import sys, time
    from coco_ros.bag import BagWriter
    from std_msgs.msg import String
    writer = BagWriter(sys.argv[1], flush_interval=None)
    count = 0
    def write(n):
        global count
        for _ in range(n):
            writer.write("/count", String(data=str(count)), {t0} + count * 1000)
            count += 1
    write(500)
    writer.flush()
    flushed = count
    write(3)  # still in the open chunk: only close() writes these
    print("ready", flushed, count, flush=True)
    time.sleep(60)  # the parent kills or interrupts us here
    """
).format(t0=T0)


def start_writer(folder: Path) -> tuple[subprocess.Popen, int, int]:
    """A child process recording a bag: (process, messages flushed, messages written)."""
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ)
    paths = [str(root / "coco_ros"), str(root / "coco_core"), env.get("PYTHONPATH", "")]
    env["PYTHONPATH"] = os.pathsep.join(paths)
    command = [sys.executable, "-c", WRITER_CHILD, str(folder)]
    child = subprocess.Popen(command, stdout=subprocess.PIPE, text=True, env=env)
    line = child.stdout.readline().split()
    if line[:1] != ["ready"]:
        child.kill()
        child.wait()
        pytest.fail(f"writer child did not start: {line}")
    return child, int(line[1]), int(line[2])


def stop(child: subprocess.Popen, signal_number: int) -> None:
    child.send_signal(signal_number)
    try:
        child.wait(timeout=10)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
        child.stdout.close()


def test_a_killed_writer_leaves_a_bag_that_reads_up_to_its_last_flush(tmp_path):
    """Everything flushed is read; that metadata.yaml is missing and that the data section ends without
    its DataEnd record is damage (the messages written after the last flush are lost)."""
    folder = tmp_path / "killed"
    child, flushed, _ = start_writer(folder)
    stop(child, signal.SIGKILL)
    assert not (folder / "metadata.yaml").exists()
    reported: list[BagError] = []
    with BagReader(folder, on_error=reported.append) as reader:  # no metadata.yaml: the folder's .mcap is found
        values = [int(m.message.data) for m in reader.messages()]
    assert values == list(range(flushed))
    size = (folder / "killed_0.mcap").stat().st_size
    assert [(e.path, e.offset) for e in reported] == [(str(folder / "metadata.yaml"), None),
                                                      (str(folder / "killed_0.mcap"), size)], reported
    assert "without its DataEnd record" in str(reported[1]) and f"the {flushed} messages before" in str(reported[1])


def test_ctrl_c_closes_the_bag_completely(tmp_path):
    """KeyboardInterrupt ends the program; the writer is closed at exit, unflushed messages included."""
    folder = tmp_path / "interrupted"
    child, _, written = start_writer(folder)
    stop(child, signal.SIGINT)
    assert (folder / "metadata.yaml").exists(), "close() did not run at exit"
    with BagReader(folder) as reader:
        values = [int(m.message.data) for m in reader.messages()]
        assert reader.errors == [] and reader.notes == []  # summary and footer are there
        assert reader.metadata.message_count == written
    assert values == list(range(written))


# --- the damaged-bag matrix: cuts compared with metadata.yaml (issue 14) -----------------------------

def top_level_records(data: bytes) -> list[tuple[int, int]]:
    """(offset, opcode) of every record after the magic, in file order."""
    import struct

    records, position = [], 8
    while position + 9 <= len(data) - 8:
        opcode, length = struct.unpack_from("<BQ", data, position)
        records.append((position, opcode))
        position += 9 + length
    return records


def test_damaged_bag_matrix_every_loss_is_an_error_naming_what_is_lost(intact, tmp_path):
    """A bag folder (metadata.yaml beside its .mcap) cut at every record boundary and after 60 bytes:
    whatever loses messages is an error after the readable ones, naming metadata.yaml's count or the
    byte where the file breaks; a cut that loses no message (inside the summary) is only a note.
    Read as a folder and as the single .mcap file (the folder's metadata.yaml is found beside it)."""
    from mcap.opcode import Opcode

    path, messages, chunks = intact
    data = path.read_bytes()
    metadata = (path.parent / "metadata.yaml").read_text()
    data_end = next(offset for offset, opcode in top_level_records(data) if opcode == Opcode.DATA_END)
    cuts = sorted({60, *(offset for offset, _ in top_level_records(data) if offset <= data_end + 20)})
    assert len(cuts) > 2 * len(chunks)
    for cut in cuts:
        folder = tmp_path / f"cut_{cut}"
        folder.mkdir()
        (folder / "metadata.yaml").write_text(metadata)
        (folder / path.name).write_bytes(data[:cut])
        complete = [c for c in chunks if c.chunk_start_offset + c.chunk_length <= cut]
        readable = [m for m in messages if any(c.message_start_time <= m[1] <= c.message_end_time for c in complete)]
        for target in (folder, folder / path.name):
            got, error, reader = read_all(target)
            reader.close()
            assert got == readable, (cut, target)
            if len(readable) == COUNT:  # the end of the file is gone all the same: damage that says so
                assert error is not None and ("no message is missing" in str(error)
                                              or f"its {COUNT} messages are readable" in str(error)), (cut, error)
                continue
            assert error is not None, f"cut at byte {cut} loses {COUNT - len(readable)} messages without an error"
            assert str(folder) in str(error)
            lost = COUNT - len(readable)
            assert f"{lost} are lost" in str(error) or "truncated" in str(error), (cut, error)
            assert "fewer messages than it declares" in str(error) or "at byte" in str(error), (cut, error)


def test_a_bag_cut_at_a_record_boundary_names_each_topic_s_shortfall(intact, tmp_path):
    path, messages, chunks = intact
    folder = tmp_path / "bag"
    folder.mkdir()
    (folder / "metadata.yaml").write_text((path.parent / "metadata.yaml").read_text())
    (folder / path.name).write_bytes(path.read_bytes()[: chunks[2].chunk_start_offset])
    got, error, reader = read_all(folder)
    reader.close()
    on_a = sum(1 for m in messages if m[0] == "/a")
    got_a = sum(1 for m in got if m[0] == "/a")
    assert error is not None and error.path == str(folder / "metadata.yaml")
    assert f"/a: {got_a} of {on_a}" in str(error) and f"{COUNT - len(got)} are lost" in str(error)
    assert reader.damaged


# --- damage that was read without a word (issue 23) ---------------------------------------------------

def bag_folder(tmp_path: Path, name: str, content: bytes, metadata: str | None) -> Path:
    """A bag folder holding ``content`` as its .mcap file, with ``metadata`` as metadata.yaml (None: none)."""
    folder = tmp_path / name
    folder.mkdir()
    (folder / "bag_0.mcap").write_bytes(content)
    if metadata is not None:
        (folder / "metadata.yaml").write_text(metadata)
    return folder


def test_a_folder_cut_at_a_chunk_boundary_without_metadata_is_damage(intact, tmp_path):
    """No byte of a record is cut and metadata.yaml is gone: the data section ends without its DataEnd
    record, which no finished recording does. The chunks before the cut are read, then an error names
    the file and the byte where the data ends (it was a note, and a replay exited 0)."""
    path, messages, chunks = intact
    data = path.read_bytes()
    cut = chunks[2].chunk_start_offset
    folder = bag_folder(tmp_path, "cut", data[:cut], None)
    reported: list[BagError] = []
    with BagReader(folder, on_error=reported.append) as reader:
        got = [(m.topic, m.log_time, m.message.data) for m in reader.messages()]
    assert got == messages[:readable_before(data, messages, chunks, cut)] and got
    assert [(e.path, e.offset) for e in reported] == [(str(folder / "metadata.yaml"), None),
                                                      (str(folder / "bag_0.mcap"), cut)], reported
    assert f"at byte {cut}" in str(reported[1]) and "without its DataEnd record" in str(reported[1])
    assert f"the {len(got)} messages before this point are readable" in str(reported[1])


def test_a_file_cut_right_after_its_last_chunk_is_damage_that_says_nothing_is_lost(intact, tmp_path):
    """The same end of the data (every chunk there, DataEnd and summary gone) with metadata.yaml's counts
    all readable: every message is read, then an error names the byte where the data ends and says that
    metadata.yaml's counts show no message missing (it was a note, and a replay exited 0)."""
    path, messages, chunks = intact
    data = path.read_bytes()
    data_end = next(offset for offset, opcode in top_level_records(data) if opcode == 0x0F)
    folder = bag_folder(tmp_path, "complete", data[:data_end], (path.parent / "metadata.yaml").read_text())
    got, error, reader = read_all(folder)
    reader.close()
    assert got == messages and error is not None and error.offset == data_end
    assert "without its DataEnd record" in str(error) and "no message is missing" in str(error), error


def test_a_duplicated_chunk_is_read_once_and_reported(intact, tmp_path):
    """A chunk stored twice (a copy tool that wrote a block again): its messages are delivered once and
    an error names the copy's byte, with or without metadata.yaml (4,649 messages of 2,417 were published)."""
    path, messages, chunks = intact
    data = path.read_bytes()
    chunk = chunks[2]
    end = chunk.chunk_start_offset + chunk.chunk_length
    doubled = data[:end] + data[chunk.chunk_start_offset:end] + data[end:]
    metadata = (path.parent / "metadata.yaml").read_text()
    for name, meta in (("with_metadata", metadata), ("without_metadata", None)):
        folder = bag_folder(tmp_path, name, doubled, meta)
        for target in (folder, folder / "bag_0.mcap"):
            got, error, reader = read_all(target)
            reader.close()
            assert got == messages, (name, target, len(got))
            assert error is not None and error.offset == end and error.path == str(folder / "bag_0.mcap"), error
            assert f"repeats the one at byte {chunk.chunk_start_offset}" in str(error)


def test_more_messages_than_metadata_declares_is_damage(intact, tmp_path):
    """Data that is not a byte-for-byte copy of a chunk, but more than the recorder wrote, shows only
    in the counts: an error naming metadata.yaml and the topic."""
    path, messages, _ = intact
    on_a = sum(1 for m in messages if m[0] == "/a")
    metadata = (path.parent / "metadata.yaml").read_text()
    assert f"message_count: {on_a}\n" in metadata
    folder = bag_folder(tmp_path, "surplus", path.read_bytes(), metadata.replace(
        f"message_count: {on_a}\n", f"message_count: {on_a - 5}\n"))
    got, error, reader = read_all(folder)
    reader.close()
    assert got == messages
    assert error is not None and error.path == str(folder / "metadata.yaml")
    assert f"more messages than it declares (/a: {on_a} of {on_a - 5} readable): 5 are not" in str(error), error


def test_a_half_cut_single_file_reads_what_it_holds_and_names_the_byte(intact, tmp_path):
    path, messages, chunks = intact
    data = path.read_bytes()
    half = tmp_path / "half.mcap"
    half.write_bytes(data[: len(data) // 2])
    got, error, reader = read_all(half)
    reader.close()
    assert got == messages[:readable_before(data, messages, chunks, len(data) // 2)] and got
    assert error is not None and error.path == str(half) and 8 <= error.offset < len(data) // 2
    assert "truncated" in str(error) and f"at byte {error.offset}" in str(error)


def test_an_uncompressed_chunk_cut_in_the_middle_gives_its_complete_records(intact, tmp_path):
    """The records of an uncompressed chunk before a cut are intact: they are read (a cut at 679 kB of
    the 1.19 MB session gave 0 readable of its big chunk), and the error names the byte of the first
    record the cut breaks. A compressed chunk cut short gives nothing (its data no longer checks)."""
    path, messages, chunks = intact
    data = path.read_bytes()
    chunk = chunks[3]
    cut = chunk.chunk_start_offset + chunk.chunk_length * 2 // 3
    damaged = tmp_path / "cut.mcap"
    damaged.write_bytes(data[:cut])
    got, error, reader = read_all(damaged)
    reader.close()
    before = sum(1 for m in messages if m[1] < chunk.message_start_time)
    in_chunk = sum(1 for m in messages if chunk.message_start_time <= m[1] <= chunk.message_end_time)
    assert error is not None and error.path == str(damaged)
    if chunk.compression == "":
        assert before < len(got) < before + in_chunk
        assert got == messages[:len(got)] == messages[:readable_before(data, messages, chunks, cut)]
        assert chunk.chunk_start_offset < error.offset < cut
        assert f"the Chunk record at byte {chunk.chunk_start_offset}" in str(error)
        assert f"{len(got) - before} of its messages, the complete records before this byte, are read" in str(error)
    else:
        assert got == messages[:before] and error.offset == chunk.chunk_start_offset
