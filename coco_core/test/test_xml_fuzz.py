"""Mutated application files (a fixed seed, so every run tries the same cases): loading each ends in
an application or in ConfigErrors that all point at a file and line, within a few seconds, never in
another exception. The mutations are those that broke the loader before: encodings, unbalanced and
deeply nested substitutions, includes of devices, entities, truncation, duplicated and swapped
pieces."""

from __future__ import annotations

import random
import shutil
from pathlib import Path

import pytest

from coco_core.errors import ConfigError, ConfigErrors
from coco_core.xml import load_application

from test_xml_limits import at_most

WORKSPACE = Path(__file__).resolve().parents[2]
SAMPLES = Path(__file__).resolve().parents[3] / "shared" / "data" / "coco_xml"
SEED = 20261123
CASES_PER_FILE = 300

TOKENS = [
    "$(", ")", "(", "$(arg x)", "$(arg ", "$(eval 1/0)", "$(eval 2**99999)", "$(eval __import__('os'))",
    "$(eval 'a'*99999999)", "$(optenv A $(optenv B $(optenv C ", "$(" * 200, "$(env HOME)", "$(dirname)",
    "$(" * 50_000, "$(optenv A " * 1000 + ")" * 1000, "/dev/zero", "/dev/urandom", "/dev/null", ".",
    "$(anon n)", "<include>/dev/zero</include>", "<includes><include>/dev/urandom</include></includes>",
    "<includes><include>.</include></includes>", '<urdf file="/dev/zero"/>', "<", ">", "</", "/>", "&amp;",
    "&#0;", "&#x1F600;", '<!DOCTYPE package [<!ENTITY e "eeeeeeeeee">]>', "&e;", "\xff\xfe", "\x00",
    '<?xml version="1.0" encoding="shift_jis"?>', '<?xml version="1.0" encoding="bogus"?>',
    '<?xml version="1.0" encoding="UTF-32"?>', "<farm>", "</farm>", "<pipeline>", "<activity>",
    '<arg name="x" value="$(arg x)$(arg x)"/>', 'if="$(arg y)"', 'unless="maybe"', 'buffersize="0"',
    'period="-1"', 'value="nan"', "<component><components>" * 50, "<component><task>T</task></component>",
    'xmlns="urn:x"', 'workers="0"', "\u00e9", "]]>", "<![CDATA[", "<!--", "-->",
]
ENCODINGS = ["utf-8", "UTF-16", "iso-8859-1", "cp1252", "bogus", "shift_jis", "utf-7", "UTF-32", "euc-jp", ""]


def application_files() -> list[Path]:
    files = sorted((WORKSPACE / "config").glob("*.xml"))
    if SAMPLES.is_dir():
        files += sorted(SAMPLES.glob("*.xml"))
    return files


def mutate(data: bytes, rng: random.Random) -> bytes:
    """One to four random edits of ``data``: bytes changed, pieces cut, repeated or swapped, a token
    inserted anywhere or where it is read (an attribute value, an element's text), an XML
    declaration put in front."""
    for _ in range(rng.randint(1, 4)):
        kind = rng.randrange(8)
        at = rng.randrange(len(data) + 1)
        if kind == 6:  # a token where a value starts: it is then expanded, included, decoded ...
            starts = [index + 2 for index in range(len(data) - 1) if data[index:index + 2] == b'="']
            starts += [index + 1 for index, byte in enumerate(data) if byte == ord(">")]
            at = rng.choice(starts) if starts else at
        if kind == 0 and data:
            index = rng.randrange(len(data))
            data = data[:index] + bytes([rng.randrange(256)]) + data[index + 1:]
        elif kind == 1:
            data = data[:at] + data[at + rng.randint(1, 200):]
        elif kind == 2:
            end = min(len(data), at + rng.randint(1, 400))
            data = data[:end] + data[at:end] * rng.randint(1, 3) + data[end:]
        elif kind == 3:
            lines = data.split(b"\n")
            i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
            lines[i], lines[j] = lines[j], lines[i]
            data = b"\n".join(lines)
        elif kind == 4:
            data = data[:at]
        elif kind in (5, 6):
            data = data[:at] + rng.choice(TOKENS).encode("utf-8", "surrogatepass") + data[at:]
        else:
            encoding = rng.choice(ENCODINGS)
            declaration = f'<?xml version="1.0" encoding="{encoding}"?>\n' if encoding else '<?xml version="1.0"?>\n'
            data = declaration.encode("ascii") + data
    return data


@pytest.mark.parametrize("original", application_files(), ids=lambda path: path.name)
def test_mutated_application_files_load_or_fail_with_file_and_line(tmp_path, original):
    # The file's neighbours come along (config/composites/ too), so that its includes and composites
    # resolve as they do for the original.
    for sibling in original.parent.rglob("*.xml"):
        (tmp_path / sibling.relative_to(original.parent)).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(sibling, tmp_path / sibling.relative_to(original.parent))
    rng = random.Random(f"{SEED}:{original.name}")
    data = original.read_bytes()
    target = tmp_path / original.name
    outcomes = {"loaded": 0, "refused": 0}
    for case in range(CASES_PER_FILE):
        mutated = mutate(data, rng)
        target.write_bytes(mutated)
        try:
            with at_most(10):
                load_application(target)
            outcomes["loaded"] += 1
        except ConfigErrors as raised:
            unplaced = [str(error) for error in raised.errors if error.location is None]
            assert not unplaced, f"case {case}: errors without file:line {unplaced} for {mutated[:300]!r}"
            outcomes["refused"] += 1
        except ConfigError as error:
            assert error.location is not None, f"case {case}: {error} has no file:line for {mutated[:300]!r}"
            outcomes["refused"] += 1
        except Exception as error:  # the point of the test: nothing else may escape
            pytest.fail(f"case {case}: {type(error).__name__}: {error} for {mutated[:300]!r}")
    assert outcomes["refused"] > 0
