"""Player and PlaybackClock: order, offsets, latched /tf_static, loop, filter, remap, pause/step."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from tf2_msgs.msg import TFMessage

from coco_ros.bag import BagReader, BagWriter
from coco_ros.replay import PlaybackClock, Player, parse_remaps

T0 = 1_700_000_000_000_000_000
MS = 1_000_000


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    """/tf_static at t0, then 20 /chatter and 10 /other messages every 10 ms."""
    from geometry_msgs.msg import TransformStamped
    from std_msgs.msg import String

    folder = tmp_path_factory.mktemp("replay") / "bag"
    with BagWriter(folder) as writer:
        writer.write("/tf_static", TFMessage(transforms=[TransformStamped(child_frame_id="camera")]), T0)
        for i in range(20):
            writer.write("/chatter", String(data=f"c{i}"), T0 + (i + 1) * 10 * MS)
            if i % 2:
                writer.write("/other", String(data=f"o{i}"), T0 + (i + 1) * 10 * MS + 1)
    return folder


def texts(played) -> list[str]:
    return [p.message.message.data if p.topic != "/tf_static" else "tf" for p in played]


def test_fast_replay_order_and_counts(bag):
    with BagReader(bag) as reader:
        played = list(Player(reader, rate=0))
    assert len(played) == 31
    assert [p.due_time for p in played] == sorted(p.due_time for p in played)
    assert texts(played)[:3] == ["tf", "c0", "c1"]
    assert sum(1 for p in played if p.topic == "/other") == 10


def test_rate_paces_the_replay(bag):
    with BagReader(bag) as reader:
        start = time.monotonic()
        played = list(Player(reader, rate=2.0, topics=["/chatter"]))
        elapsed = time.monotonic() - start
    assert len(played) == 20
    assert 0.08 < elapsed < 2.0  # 190 ms of bag at 2x: ~95 ms


def test_start_offset_skips_messages_but_delivers_tf_static_first(bag):
    with BagReader(bag) as reader:
        played = list(Player(reader, rate=0, start_offset=0.1, duration=0.05))
    assert played[0].topic == "/tf_static" and played[0].latched
    assert played[0].due_time == T0 + 100 * MS
    assert texts(played)[1:] == ["c9", "o9", "c10", "c11", "o11", "c12", "c13", "o13"]


def test_loop_repeats_latched_each_pass(bag):
    with BagReader(bag) as reader:
        player = Player(reader, rate=0, start_offset=0.15, loop=True, topics=["/tf_static", "/chatter"])
        played = []
        for item in player:
            played.append(item)
            if len(played) == 3 * 7:
                player.stop()
    assert player.passes == 3
    names = texts(played)
    assert names[:7] == ["tf", "c14", "c15", "c16", "c17", "c18", "c19"]
    assert names == names[:7] * 3


def test_topic_filter_and_remap(bag):
    with BagReader(bag) as reader:
        played = list(Player(reader, rate=0, topics=["/other"], remap=["/other:=/robot/other"]))
        assert {p.topic for p in played} == {"/robot/other"}
        assert len(played) == 10
        with pytest.raises(Exception, match="no topic '/nope'"):
            Player(reader, topics=["/nope"])
    assert parse_remaps(["/a:=/b"]) == {"/a": "/b"}
    with pytest.raises(ValueError, match="/from:=/to"):
        parse_remaps(["/a=/b"])


def test_pause_and_step_are_deterministic(bag):
    with BagReader(bag) as reader:
        player = Player(reader, rate=1.0, topics=["/chatter"])
        player.pause()
        assert player.poll() == []
        player.step(3)
        assert texts(player.poll()) == ["c0", "c1", "c2"]
        assert player.poll() == []  # still paused
        assert player.clock.now() == T0 + 30 * MS
        player.step()
        assert texts(player.poll()) == ["c3"]
        player.clock.set_rate(0)
        player.resume()
        assert len(player.poll()) == 16 and player.finished


def test_clock_reanchors_on_resume():
    clock = PlaybackClock(1.0)
    clock.reset(T0)
    clock.pause()
    paused_at = clock.now()
    time.sleep(0.05)
    assert clock.now() == paused_at
    clock.resume()
    assert not clock.release(paused_at + 500 * MS)  # no burst after the pause
    assert clock.release(paused_at)
    with pytest.raises(ValueError):
        PlaybackClock(-1)


def test_seek_restarts_with_latched(bag):
    with BagReader(bag) as reader:
        player = Player(reader, rate=0, topics=["/tf_static", "/chatter"])
        first = player.poll(5)
        assert texts(first) == ["tf", "c0", "c1", "c2", "c3"]
        player.seek(0.19)
        assert texts(player.poll()) == ["tf", "c18", "c19"]
