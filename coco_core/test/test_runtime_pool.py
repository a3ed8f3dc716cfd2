"""Pooled channels: slot life cycle, reuse of buffers (no allocation per frame), stalls, two readers."""

from __future__ import annotations

import numpy as np
import pytest

from coco_core import (
    NEW_DATA,
    NO_DATA,
    Application,
    BufferPolicy,
    Component,
    ConnectionPolicy,
    InputPort,
    LocalFramePool,
    PooledOutputPort,
    Slot,
    SlotState,
)

FREE, WRITING, READY, READING = SlotState.FREE, SlotState.WRITING, SlotState.READY, SlotState.READING


class Camera(Component):
    image = PooledOutputPort(slots=3)


class SmallCamera(Component):
    image = PooledOutputPort(slots=2)


class Viewer(Component):
    image = InputPort(Slot)


def rig(camera_cls=Camera, readers: int = 1, policy: ConnectionPolicy | None = None):
    app = Application("pool")
    camera = app.add(camera_cls("camera"))
    viewers = [app.add(Viewer(f"viewer{i}")) for i in range(readers)]
    conns = [app.connect("camera.image", f"viewer{i}.image", policy) for i in range(readers)]
    return camera.image, [v.image for v in viewers], conns


def test_slot_lifecycle_states_at_every_step():
    out, (inp,), (conn,) = rig()
    pool = out.pool
    assert pool.states() == [FREE, FREE, FREE]
    assert inp.read() == (NO_DATA, None)

    slot = out.acquire((4, 4))
    assert slot is pool.slots[0]
    assert slot.state is WRITING
    assert pool.states() == [WRITING, FREE, FREE]
    assert inp.read() == (NO_DATA, None), "a frame being written must not be visible"

    slot.array[:] = 7
    out.write(slot)
    assert pool.states() == [READY, FREE, FREE]
    assert slot.seq == 1 and pool.published == 1
    assert conn.counters() == {"written": 1, "read": 0, "dropped": 0, "pending": 1}

    status, got = inp.read()
    assert status is NEW_DATA and got is slot
    assert got.state is READING and got.readers == 1
    assert int(got.array[0, 0]) == 7
    assert conn.counters() == {"written": 1, "read": 1, "dropped": 0, "pending": 0}
    # A pooled frame is never handed out again as OLD_DATA: it may be reused once released.
    assert inp.read() == (NO_DATA, None)

    got.release()
    assert pool.states() == [READY, FREE, FREE], "the newest frame stays READY after its reader is done"
    assert got.readers == 0

    second = out.acquire((4, 4))
    assert second is pool.slots[1] and second.state is WRITING
    out.write(second)
    assert pool.states() == [FREE, READY, FREE], "publishing frees the previous, released frame"

    status, held = inp.read()
    assert status is NEW_DATA and held is second and held.state is READING
    third = out.acquire((4, 4))
    assert third is pool.slots[0]
    out.write(third)
    assert pool.states() == [READY, READING, FREE], "a frame being read is not freed by a newer one"
    held.release()
    assert pool.states() == [READY, FREE, FREE], "an old frame goes back to FREE when its reader is done"


def test_release_via_context_manager():
    out, (inp,), _ = rig()
    slot = out.acquire((2,))
    out.write(slot)
    status, frame = inp.read()
    with frame as inside:
        assert inside is frame and frame.state is READING
    assert frame.state is READY and frame.readers == 0


def test_untaken_newest_frame_is_reused_when_no_slot_is_free():
    out, (inp,), (conn,) = rig(SmallCamera)
    pool = out.pool
    first = out.acquire((3,))
    out.write(first)
    status, held = inp.read()  # reader keeps slot 0
    assert status is NEW_DATA and held is first

    second = out.acquire((3,))
    assert second is pool.slots[1]
    out.write(second)
    assert pool.states() == [READING, READY]

    # No FREE slot: the newest frame, which nobody took, is overwritten (latest-value semantics).
    third = out.acquire((3,))
    assert third is second and third.state is WRITING
    assert pool.reused == 1 and pool.stalls == 0
    assert inp.read() == (NO_DATA, None), "a frame being rewritten must not be handed out"
    third.array[:] = 3
    out.write(third)
    assert third.seq == 3
    status, latest = inp.read()
    assert status is NEW_DATA and latest is third and int(latest.array[0]) == 3
    # Written 3 frames, read 2: the overwritten one counts as dropped.
    assert conn.counters() == {"written": 3, "read": 2, "dropped": 1, "pending": 0}
    held.release()
    latest.release()
    assert pool.states() == [FREE, READY]


def test_stall_returns_none_and_is_counted():
    out, (inp,), _ = rig(SmallCamera)
    pool = out.pool
    first = out.acquire((3,))
    out.write(first)
    _, held = inp.read()
    writing = out.acquire((3,))
    assert writing is pool.slots[1]
    assert pool.states() == [READING, WRITING]
    assert out.acquire((3,)) is None
    assert out.acquire((3,)) is None
    assert pool.stalls == 2 and pool.reused == 0
    assert pool.states() == [READING, WRITING], "a stall changes no slot"
    out.write(writing)
    held.release()
    assert out.acquire((3,)) is pool.slots[0]


def test_stall_when_every_slot_is_being_read():
    out, (a, b), _ = rig(SmallCamera, readers=2)
    pool = out.pool
    out.write(out.acquire((1,)))
    _, frame_a = a.read()
    out.write(out.acquire((1,)))
    _, frame_b = b.read()
    assert frame_a is not frame_b
    assert pool.states() == [READING, READING]
    assert out.acquire((1,)) is None
    assert pool.stalls == 1


def test_steady_stream_reuses_the_same_numpy_buffers():
    out, (inp,), _ = rig()
    pool = out.pool
    buffers: dict[int, np.ndarray] = {}
    for frame in range(30):
        slot = out.acquire((16, 16, 3))
        assert slot is not None
        if slot.index in buffers:
            assert slot.array is buffers[slot.index], f"frame {frame}: slot {slot.index} reallocated"
        buffers[slot.index] = slot.array
        slot.array.fill(frame % 256)
        out.write(slot)
        status, got = inp.read()
        assert status is NEW_DATA and got is slot
        assert int(got.array[5, 5, 1]) == frame % 256
        got.release()
    assert pool.published == 30
    assert len(buffers) <= len(pool.slots)
    distinct = {id(array) for array in buffers.values()}
    assert len(distinct) == len(buffers)
    assert all(slot.array is buffers[slot.index] for slot in pool.slots if slot.index in buffers)


def test_shape_or_dtype_change_reallocates():
    pool = LocalFramePool(2)
    slot = pool.acquire((4, 4), np.uint8)
    before = slot.array
    assert before.shape == (4, 4) and before.dtype == np.uint8
    pool.publish(slot)
    other = pool.acquire((4, 4), np.uint8)
    pool.publish(other)  # frees slot 0 (never read)
    again = pool.acquire((8, 2), np.uint8)
    assert again is slot
    assert again.array is not before and again.array.shape == (8, 2)
    pool.publish(again)
    typed = pool.acquire((4, 4), np.float32)  # slot 1 is free again
    assert typed is other and typed.array.dtype == np.float32 and typed.array.shape == (4, 4)
    pool.publish(typed)
    same = pool.acquire((8, 2), np.uint8)
    assert same is slot and same.array is again.array, "same shape and dtype: no reallocation"


def test_two_readers_share_one_slot_until_both_release():
    out, (a, b), (conn_a, conn_b) = rig(readers=2)
    slot = out.acquire((2, 2))
    slot.array[:] = 9
    out.write(slot)
    assert conn_a.pending == 1 and conn_b.pending == 1
    _, frame_a = a.read()
    _, frame_b = b.read()
    assert frame_a is frame_b is slot, "readers get the frame by reference, not a copy"
    assert slot.state is READING and slot.readers == 2
    frame_a.release()
    assert slot.state is READING and slot.readers == 1
    # The writer moves on while reader b still holds the frame.
    newer = out.acquire((2, 2))
    assert newer is not slot
    out.write(newer)
    assert slot.state is READING
    frame_b.release()
    assert slot.state is FREE and slot.readers == 0
    # Each reader sees each frame once.
    assert a.read()[1] is newer and b.read()[1] is newer
    assert a.read() == (NO_DATA, None) and b.read() == (NO_DATA, None)
    assert conn_a.read == 2 and conn_b.read == 2


def test_pool_misuse_is_refused():
    with pytest.raises(ValueError, match="at least 2"):
        LocalFramePool(1)
    pool = LocalFramePool(2)
    slot = pool.acquire((1,))
    pool.publish(slot)
    with pytest.raises(ValueError, match="publish"):
        pool.publish(slot)  # already READY
    with pytest.raises(ValueError, match="release"):
        slot.release()  # nobody is reading it
    foreign = LocalFramePool(2).acquire((1,))
    with pytest.raises(ValueError):
        pool.publish(foreign)


def test_each_component_instance_has_its_own_pool():
    a, b = Camera("a"), Camera("b")
    assert a.image.pool is not b.image.pool
    assert a.image.pool is not Camera.image.pool
    assert a.image.pool.count == 3


def test_pooled_write_without_connection_publishes_without_error():
    camera = Camera("alone")
    for _ in range(5):
        slot = camera.image.acquire((2,))
        assert slot is not None
        camera.image.write(slot)
    assert camera.image.pool.published == 5
    assert camera.image.pool.states().count(READY) == 1


def test_pool_policy_is_accepted_on_a_pooled_port():
    out, (inp,), (conn,) = rig(policy=ConnectionPolicy(BufferPolicy.POOL))
    assert conn.policy.data is BufferPolicy.POOL
    out.write(out.acquire((1,)))
    assert inp.read()[0] is NEW_DATA


def test_the_profile_shows_a_writers_stalls():
    """A frame the writer could not publish (readers held every slot) reaches no connection: the
    profile's pooled-output table is where it shows."""
    from coco_core.report import profile_report

    out, (inp,), _ = rig(SmallCamera)
    held = []
    for _ in range(2):
        slot = out.acquire((2, 2))
        out.write(slot)
        held.append(inp.read()[1])  # the viewer keeps both frames
    assert out.acquire((2, 2)) is None
    report = profile_report(out.owner.app)
    table = report.split("pooled output")[1].splitlines()
    assert table[2].split() == ["camera.image", "2", "2", "1"]  # slots, published, stalls
    for slot in held:
        slot.release()
