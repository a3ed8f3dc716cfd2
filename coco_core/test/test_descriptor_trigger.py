"""DescriptorTrigger: a readable descriptor wakes the activity once per rearm, never in a loop."""

from __future__ import annotations

import os
import threading
import time

from coco_core.descriptor_trigger import DescriptorTrigger


class Wakes:
    """A stand-in for ``Activity.wake`` that counts, and lets the test wait for a count."""

    def __init__(self) -> None:
        self.count = 0
        self._changed = threading.Condition()

    def __call__(self) -> None:
        with self._changed:
            self.count += 1
            self._changed.notify_all()

    def reach(self, count: int, timeout: float = 10.0) -> bool:
        with self._changed:
            return self._changed.wait_for(lambda: self.count >= count, timeout)


def test_a_readable_descriptor_wakes_once_per_rearm_and_close_ends_the_thread():
    read, write = os.pipe()
    wakes = Wakes()
    trigger = DescriptorTrigger("test:trigger", [read], wakes)
    trigger.start()
    try:
        os.write(write, b"x")
        assert wakes.reach(1)
        start = time.process_time()
        # Still readable (nothing read it): the next wake-up comes with the rearm, not before.
        trigger.rearm()
        assert wakes.reach(2)
        os.read(read, 1)
        trigger.rearm()  # nothing readable now: the thread waits in poll(2)
        os.write(write, b"y")
        assert wakes.reach(3)
        os.read(read, 1)
        trigger.rearm(more=True)  # the component left data for another cycle: woken without a poll
        assert wakes.reach(4)
    finally:
        trigger.close()
    assert wakes.count == trigger.wakes == 4, "a wake-up came without a rearm"
    assert time.process_time() - start < 1.0, "the thread spun"
    assert not any(thread.name == "test:trigger" for thread in threading.enumerate())
    os.close(read)
    os.close(write)


def test_close_ends_a_thread_that_waits_for_data_or_for_a_rearm():
    read, write = os.pipe()
    idle = DescriptorTrigger("test:idle", [read], Wakes())
    idle.start()
    idle.close()  # in poll(2), nothing readable
    idle.close()  # once only: its eventfd is not closed twice
    wakes = Wakes()
    waiting = DescriptorTrigger("test:waiting", [read], wakes)
    waiting.start()
    os.write(write, b"x")
    assert wakes.reach(1)
    waiting.close()  # woken, waiting for a rearm that will not come
    assert not any(thread.name.startswith("test:") for thread in threading.enumerate())
    os.close(read)
    os.close(write)
