"""``<schedule>`` (``<schedulepolicy>`` in the per-activity layout): when and where an activity runs.

Both spellings of the period (``period=`` and CoCo's older ``value=``) are accepted, in
milliseconds. ``spin`` (milliseconds, periodic only) is how long before each deadline the thread
stops sleeping and spins: a real-time loop on a loaded machine whose timer wake-ups come late gives
it more. ``min_period`` (milliseconds, triggered only) is the least time from the start of one
cycle to the start of the next: a display woken by every input draws at most at its rate. ``type``
may be left out: a period makes the activity periodic. ``runtime`` (a SCHED_DEADLINE budget in the
C++ CoCo) is accepted and ignored, since DEADLINE is not available from Python.
"""

from __future__ import annotations

from ..errors import AttributeValueError
from ..model import ScheduleSpec
from ..period import MAX_PERIOD
from .reader import FileReader
from .tree import Element
from .values import parse_bool, parse_cores, parse_int, parse_number

COMMON_ATTRIBUTES = (
    "activity",
    "affinity",
    "exclusive_affinity",
    "nice",
    "priority",
    "realtime",
    "runtime",
)
ACTIVITY_SCHEDULE_ATTRIBUTES = (*COMMON_ATTRIBUTES, "main", "min_period", "period", "spin", "type", "value")
PIPELINE_SCHEDULE_ATTRIBUTES = (*COMMON_ATTRIBUTES, "buffersize")
"""A pipeline's stages are triggered by their input, so there is no type or period to give."""

REALTIME = ("none", "FIFO", "RR")


def read_schedule(reader: FileReader, element: Element, values: dict[str, str]) -> ScheduleSpec:
    """The schedule described by ``values``, the already checked attributes of ``element``."""
    kind, period = _activation(reader, element, values)
    return ScheduleSpec(
        type=kind,
        period_ms=period,
        activity=reader.choice(element, values, "activity", ("parallel", "sequential"), "parallel"),
        main=bool(reader.parsed(element, values, "main", parse_bool)),
        realtime=_realtime(reader, element, values),
        spin_ms=_spin(reader, element, values, kind, period),
        min_period_ms=_min_period(reader, element, values, kind),
        priority=reader.parsed(element, values, "priority", parse_int),
        nice=reader.parsed(element, values, "nice", parse_nice),
        affinity=reader.parsed(element, values, "affinity", parse_cores) or [],
        exclusive_affinity=reader.parsed(element, values, "exclusive_affinity", parse_cores) or [],
        location=element.location,
    )


def _activation(
    reader: FileReader, element: Element, values: dict[str, str]
) -> tuple[str, float | None]:
    """``type`` and the period in milliseconds, checked against each other."""
    given = [name for name in ("period", "value") if values.get(name, "").strip()]
    if len(given) > 1:
        reader.error(
            f"<{element.tag}> has both period= and value=; they are the same setting "
            "(milliseconds): give one",
            element,
        )
    attribute = given[0] if given else None
    period = reader.parsed(element, values, attribute, _milliseconds) if attribute else None
    if period == -1:  # the C++ CoCo's "no period"
        attribute = period = None
    kind = reader.choice(
        element, values, "type", ("periodic", "triggered"), "periodic" if attribute else "triggered"
    )
    if kind == "periodic":
        if attribute is None:
            reader.error(
                f'<{element.tag}> type="periodic" needs period= (milliseconds, greater than 0)',
                element,
            )
        elif period is not None and not 0 < period <= MAX_PERIOD * 1e3:
            reader.error(
                f'<{element.tag}> attribute {attribute}="{values[attribute]}": '
                f"expected a period greater than 0 milliseconds and at most {MAX_PERIOD * 1e3:.0f} (a day)",
                element,
            )
    elif attribute is not None:
        reader.warn(
            f'<{element.tag}> attribute {attribute}="{values[attribute]}" is ignored: a triggered '
            'activity has no period (the original CoCo ignores it too; remove it, or make the '
            'activity type="periodic")',
            element,
        )
        period = None
    return kind, period


def _spin(reader: FileReader, element: Element, values: dict[str, str], kind: str,
          period: float | None) -> float | None:
    """``spin`` (milliseconds before each deadline at which a periodic thread stops sleeping and
    spins): from 0 to less than the period, on a periodic schedule only."""
    if not values.get("spin", "").strip():
        return None
    spin = reader.parsed(element, values, "spin", _milliseconds)
    if spin is None:
        return None
    if kind != "periodic":
        reader.error(f'<{element.tag}> attribute spin="{values["spin"]}": only a periodic activity spins to its '
                     "deadlines; leave it out of a triggered one", element)
        return None
    if not 0 <= spin < (period if period is not None else float("inf")):
        reader.error(f'<{element.tag}> attribute spin="{values["spin"]}": expected milliseconds from 0 to less '
                     f"than the period ({period:g})", element)
        return None
    return spin


def _min_period(reader: FileReader, element: Element, values: dict[str, str], kind: str) -> float:
    """``min_period`` (milliseconds from the start of one cycle to the start of the next, at least):
    from 0 (no bound) to a day, on a triggered schedule only; 0 when not given."""
    bound = reader.parsed(element, values, "min_period", _milliseconds)
    if bound is None:
        return 0.0
    if kind != "triggered":
        reader.error(f'<{element.tag}> attribute min_period="{values["min_period"]}": only a triggered activity '
                     "has a minimum period (a periodic one cycles every period); leave it out, or make the "
                     'activity type="triggered"', element)
        return 0.0
    if not 0 <= bound <= MAX_PERIOD * 1e3:
        reader.error(f'<{element.tag}> attribute min_period="{values["min_period"]}": expected milliseconds '
                     f"from 0 (no bound) to {MAX_PERIOD * 1e3:.0f} (a day)", element)
        return 0.0
    return bound


def _realtime(reader: FileReader, element: Element, values: dict[str, str]) -> str:
    if values.get("realtime", "").strip() == "DEADLINE":
        reader.error(
            f'<{element.tag}> attribute realtime="DEADLINE" is not available from Python '
            "(the os module has no SCHED_DEADLINE); use FIFO or RR",
            element,
        )
        return "none"
    return reader.choice(element, values, "realtime", REALTIME, "none")


def _milliseconds(text: str) -> float:
    return parse_number(text, "a number of milliseconds")


def parse_nice(text: str) -> int:
    """A nice value, checked against the range the OS accepts."""
    expected = "a nice value from -20 (most favourable) to 19"
    value = parse_int(text, expected)
    if not -20 <= value <= 19:
        raise AttributeValueError(expected)
    return value
