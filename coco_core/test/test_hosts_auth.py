"""The application's key and the seals of messages between hosts (coco_core.hosts.key, .auth): who
sent a message, that nobody changed it, that it is new; what fails is counted, never raised."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import pytest

from coco_core.errors import KeyFileError
from coco_core.hosts import auth
from coco_core.hosts.auth import WINDOW, Refusals, Seal, Sealer, Verifier
from coco_core.hosts.key import AppKey, keygen, launch_key, write_key

KEY = AppKey(bytes(range(32)), "test key")
TOPIC = "/coco/app/hosts"


def verifier(refusals: Refusals | None = None) -> Verifier:
    return Verifier(KEY, TOPIC, ["robot"], ["robot", "graphics"], refusals or Refusals())


def test_a_sealed_message_is_accepted_once_and_every_change_is_refused() -> None:
    sealer, check = Sealer(KEY, TOPIC, "robot"), verifier()
    parts = [b"body", "recipient"]
    seal = sealer.seal(parts)
    assert check.accept(seal, parts)
    assert not check.accept(seal, parts)  # the same again: a replay
    changed = sealer.seal(parts)
    assert not check.accept(changed, [b"bodY", "recipient"])
    assert not check.accept(changed, [b"body", "recipient", b""])  # one more part
    assert not check.accept(changed, [b"bodyrecipient"])  # the parts' boundaries are covered
    assert not Verifier(KEY, "/coco/app/other", ["robot"], ["robot"], Refusals()).accept(changed, parts)
    assert check.accept(changed, parts)
    rows = check.refusals.rows()
    assert [(row[1], row[2].split(" (")[0], row[3]) for row in rows] == [
        ("'robot'", "a replay", "1"), ("'robot'", "not authenticated", "3")]


def test_who_may_send_and_when() -> None:
    parts = [b"x"]
    refusals = Refusals()
    check = verifier(refusals)
    assert not check.accept(Sealer(AppKey(bytes(32), "other"), TOPIC, "robot").seal(parts), parts)
    assert not check.accept(Sealer(KEY, TOPIC, "ghost").seal(parts), parts)
    assert not check.accept(Sealer(KEY, TOPIC, "graphics").seal(parts), parts)
    old = Sealer(KEY, TOPIC, "robot")
    wall = time.time() - 2 * auth.FRESH
    stale = Seal("robot", old.session, 1, wall, auth.mac(KEY, TOPIC, "robot", old.session, 1, wall, parts))
    assert not check.accept(stale, parts)
    first, second = Sealer(KEY, TOPIC, "robot"), Sealer(KEY, TOPIC, "robot")
    assert check.accept(first.seal(parts), parts)
    assert not check.accept(second.seal(parts), parts)  # the same host name from a second launch
    assert check.accept(first.seal(parts), parts)
    whys = {(row[1], row[2].split(":")[0].split(" (")[0]) for row in refusals.rows()}
    assert whys == {("'robot'", "not authenticated"), ("'ghost'", "a host this application does not declare"),
                    ("'graphics'", "a host that does not write on this topic"), ("'robot'", "stale"),
                    ("'robot'", "a second launch claiming this host name")}


def test_a_window_of_counters_takes_reordered_messages_once() -> None:
    sealer, check = Sealer(KEY, TOPIC, "robot"), verifier()
    seals = [sealer.seal([b"m"]) for _ in range(WINDOW + 10)]
    assert check.accept(seals[5], [b"m"])
    assert check.accept(seals[3], [b"m"]) and not check.accept(seals[3], [b"m"])
    assert check.accept(seals[-1], [b"m"])
    assert not check.accept(seals[4], [b"m"])  # fell out of the window
    assert check.accept(seals[-2], [b"m"]) and not check.accept(seals[-2], [b"m"])


def test_a_flood_of_claimed_names_is_counted_with_names_cut_and_logged_once(caplog: pytest.LogCaptureFixture) -> None:
    refusals = Refusals()
    check = verifier(refusals)
    name = "ghost\n" + "x" * 5_000_000
    for counter in range(100):
        check.accept(Seal(name, 1, counter + 1, time.time(), bytes(32)), [b"x"])
    [row] = refusals.rows()
    assert row[3] == "100" and len(row[1]) < 120 and "\\n" in row[1] and "+4999942 characters" in row[1]
    assert len(caplog.records) == 1 and len(caplog.records[0].getMessage()) < 400


def test_a_key_file_is_made_for_its_owner_alone_and_read_with_checks(tmp_path: Path) -> None:
    path = tmp_path / "app.key"
    assert keygen([str(path)]) == 0
    assert path.stat().st_mode & 0o777 == 0o600
    key = AppKey.from_file(str(path))
    assert key.fingerprint == AppKey.from_text(path.read_text(), "again").fingerprint and "secret" not in repr(key)
    assert keygen([str(path)]) == 1  # kept
    assert write_key(str(path), force=True).fingerprint != key.fingerprint
    os.chmod(path, 0o644)
    with pytest.raises(KeyFileError, match=r"readable or writable by others \(mode 0644\); only its owner may: chmod 600"):
        AppKey.from_file(str(path))
    for bad, why in [(tmp_path, "not a regular file"), (tmp_path / "none", "cannot be opened"),
                     (Path("/dev/zero"), "not a regular file")]:
        with pytest.raises(KeyFileError, match=why):
            AppKey.from_file(str(bad))
    big = tmp_path / "big.key"
    big.write_bytes(b"0" * 10_000)
    big.chmod(0o600)
    with pytest.raises(KeyFileError, match="larger than 1024 bytes"):
        AppKey.from_file(str(big))
    with pytest.raises(KeyFileError, match="64 hexadecimal digits"):
        AppKey.from_text("zz" * 32, "text")


def test_the_launch_options_name_the_key_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "app.key"
    key = write_key(str(path))
    assert launch_key(argparse.Namespace(key=None, key_env=None)) is None
    assert launch_key(argparse.Namespace(key=str(path), key_env=None)) == key
    monkeypatch.setenv("APP_KEY", key.secret.hex())
    from_environment = launch_key(argparse.Namespace(key=None, key_env="APP_KEY"))
    assert from_environment is not None and from_environment.secret == key.secret
    with pytest.raises(KeyFileError, match="not both"):
        launch_key(argparse.Namespace(key=str(path), key_env="APP_KEY"))
    with pytest.raises(KeyFileError, match="environment variable NOPE .* is not set"):
        launch_key(argparse.Namespace(key=None, key_env="NOPE"))


def test_made_up_names_and_times_never_grow_the_rows_past_their_bound() -> None:
    """A flood of messages each claiming another host name, sent at another time: the rows stay
    within MAX_ROWS, the rest counted under (other senders), every message counted once."""
    refusals = Refusals()
    check = verifier(refusals)
    for number in range(1000):
        check.accept(Seal(f"host{number}", 1, 1, time.time() - number, bytes(32)), [b"x"])
    rows = refusals.rows()
    named = [row for row in rows if row[1] != auth.OTHER_SENDERS]
    assert len(named) == auth.MAX_ROWS and len(rows) == auth.MAX_ROWS + 1  # one reason: one row of the others
    assert sum(int(row[3]) for row in rows) == 1000


def test_a_second_launch_with_the_key_claiming_this_host_is_reported(caplog: pytest.LogCaptureFixture) -> None:
    check = Verifier(KEY, TOPIC, ["robot"], ["robot", "graphics"], Refusals(), own="graphics")
    impostor = Sealer(KEY, TOPIC, "graphics")
    for _ in range(3):
        parts = [b"x"]
        assert not check.accept(impostor.seal(parts), parts)
    assert [row[2] for row in check.refusals.rows()] == ["a second launch claiming this host name"]
    assert sum("claimed by two launches" in record.getMessage() for record in caplog.records) == 1
