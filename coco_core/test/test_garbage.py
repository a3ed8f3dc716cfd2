"""GarbageBetweenCycles: the collections a process's thresholds ask for, run between cycles when the
time to the next deadline allows, forced when garbage piled up; and the <process gc=...> attribute."""

from __future__ import annotations

import gc

import pytest

from coco_core.errors import ConfigErrors
from coco_core.garbage import FORCED, SLACK, GarbageBetweenCycles
from coco_core.xml import parse_application_string


@pytest.fixture
def collector_off():
    """Automatic collection off for the test (as in a gc="between_cycles" process), then back."""
    was = gc.isenabled()
    gc.disable()
    gc.collect()
    yield
    if was:
        gc.enable()


def make_cycles(count: int) -> None:
    for _ in range(count):
        loop: list[object] = []
        loop.append(loop)


def test_collects_with_slack_and_waits_without(collector_off) -> None:
    garbage = GarbageBetweenCycles()
    threshold = gc.get_threshold()[0]
    garbage.after_cycle(deadline=1.0, now=0.0)
    assert garbage.collections == 0, "below the threshold: nothing to do"
    make_cycles(threshold + 10)
    garbage.after_cycle(deadline=1.0, now=1.0 - SLACK / 2)
    assert garbage.collections == 0 and gc.get_count()[0] >= threshold, "no slack: waits for a better moment"
    garbage.after_cycle(deadline=1.0, now=1.0 - 2 * SLACK)
    assert garbage.collections == 1 and gc.get_count()[0] < threshold
    make_cycles(FORCED * threshold + threshold)  # (a few objects of the loop itself are freed meanwhile)
    garbage.after_cycle(deadline=1.0, now=1.0)
    assert garbage.forced == 1 and gc.get_count()[0] < threshold, "piled up: collected without the slack"
    assert garbage.describe() == "1 garbage collections between cycles, 1 forced without the slack"


def test_the_process_attribute_takes_auto_or_between_cycles() -> None:
    text = """<package name="p"><components><component><name>c</name><task>Ticker</task></component></components>
      <activities><process name="loop" gc="{gc}"><activity name="a"><schedule type="periodic" period="1"/>
      <components><component name="c"/></components></activity></process></activities></package>"""
    spec = parse_application_string(text.format(gc="between_cycles"), "app.xml")
    assert spec.processes[0].gc == "between_cycles" and not spec.processes[0].lock_memory
    with pytest.raises(ConfigErrors, match=r'gc="sometimes" is not valid; expected one of: auto, between_cycles'):
        parse_application_string(text.format(gc="sometimes"), "app.xml")
