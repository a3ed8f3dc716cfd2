"""Parse the text of attribute values: numbers, booleans, lists of cores.

Python's own ``int()`` and ``float()`` accept more than an application file should (``1_000``,
``nan``, ``inf``), and ``docs/coco.xsd`` must accept exactly what the loader accepts, so the
grammars are written out here. Each parser raises :class:`ValueError` whose text completes the
phrase "expected ...", which the reader turns into an error that points at the element.
"""

from __future__ import annotations

import re

from ..errors import AttributeValueError

TRUE_WORDS = ("true", "1", "yes", "on")
FALSE_WORDS = ("false", "0", "no", "off")
BOOLEAN_EXPECTED = "true/false, 1/0, yes/no or on/off"

_INTEGER = re.compile(r"[+-]?[0-9]+")
_NUMBER = re.compile(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?")
_CORES = re.compile(r"[0-9]+(\s*,\s*[0-9]+)*")


def parse_bool(text: str) -> bool:
    """``true``/``1``/``yes``/``on`` or ``false``/``0``/``no``/``off``, in any case."""
    word = text.strip().lower()
    if word in TRUE_WORDS:
        return True
    if word in FALSE_WORDS:
        return False
    raise AttributeValueError(BOOLEAN_EXPECTED)


def parse_condition(text: str) -> bool:
    """An ``if``/``unless`` value: a boolean, where an empty value (an unset arg) counts as false."""
    if not text.strip():
        return False
    try:
        return parse_bool(text)
    except ValueError:
        raise AttributeValueError(f"{BOOLEAN_EXPECTED} (or empty for false)") from None


def parse_int(text: str, expected: str = "an integer") -> int:
    """A decimal integer, optionally signed."""
    stripped = text.strip()
    if not _INTEGER.fullmatch(stripped):
        raise AttributeValueError(expected)
    return int(stripped)


def parse_number(text: str, expected: str = "a number") -> float:
    """A finite decimal number such as ``10``, ``2.5`` or ``1e3``."""
    stripped = text.strip()
    if not _NUMBER.fullmatch(stripped):
        raise AttributeValueError(expected)
    return float(stripped)


def parse_cores(text: str) -> list[int]:
    """CPU cores: one number or a comma-separated list; empty or ``-1`` (CoCo's default) is none."""
    stripped = text.strip()
    if stripped in ("", "-1"):
        return []
    if not _CORES.fullmatch(stripped):
        raise AttributeValueError("a core number, a comma-separated list of core numbers, or -1 for none")
    return list(dict.fromkeys(int(core) for core in stripped.split(",")))
