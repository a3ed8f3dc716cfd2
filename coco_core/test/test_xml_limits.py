"""Hostile and clumsy application files end in a file:line ConfigError, never in another exception,
a hang or an exhausted memory: encodings, nesting, file types and sizes, runaway expansion."""

import contextlib
import os
import signal

import pytest

from coco_core import registry
from coco_core.builder import build_application
from coco_core.errors import ConfigError, ConfigErrors
from coco_core.files import APPLICATION_FILE_LIMIT, FileReadError, read_regular_file
from coco_core.transforms import TransformGraph
from coco_core.transforms.urdf import UrdfError, load_urdf
from coco_core.xml import load_application, parse_application_string
from coco_core.xml.components import MAX_PEER_DEPTH
from coco_core.xml import expression
from coco_core.xml.expression import MAX_ROUND_DIGITS
from coco_core.xml.loader import MAX_INCLUDE_DEPTH, MAX_INCLUDES
from coco_core.xml.substitution import MAX_EXPANSION, MAX_NESTING


@contextlib.contextmanager
def at_most(seconds: float):
    """Fail instead of hanging: the cases below used to run for minutes or block for ever."""

    def expire(_signum, _frame):
        raise TimeoutError(f"took more than {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def errors_of(load) -> list[tuple[str, str]]:
    with pytest.raises(ConfigErrors) as raised:
        load()
    return [(str(error.location), error.message) for error in raised.value.errors]


def with_attribute(value: str, declarations: str = "") -> str:
    return (f"<package>{declarations}\n<components><component><task>T</task><attributes>\n"
            f'<attribute name="a" value="{value}"/>\n</attributes></component></components></package>')


# ----- encodings --------------------------------------------------------------------------------


@pytest.mark.parametrize("encoding", ["bogus", "shift_jis", "utf-7", "UTF-32"])
def test_an_encoding_that_cannot_be_read_is_an_error_at_the_declaration(tmp_path, encoding):
    path = tmp_path / "app.xml"
    path.write_bytes(f'<?xml version="1.0" encoding="{encoding}"?>\n<package/>\n'.encode("ascii"))
    ((where, message),) = errors_of(lambda: load_application(path))
    assert where == f"{path}:1"
    assert message.startswith("the encoding of the XML declaration cannot be read")
    assert "UTF-8" in message


def test_a_single_byte_encoding_is_read(tmp_path):
    path = tmp_path / "app.xml"
    path.write_bytes('<?xml version="1.0" encoding="cp1252"?>\n<package name="caf\xe9"/>\n'.encode("cp1252"))
    assert load_application(path).name == "café"


# ----- nesting ----------------------------------------------------------------------------------


def test_substitutions_nest_up_to_the_documented_limit():
    inner = "$(optenv COCO_TEST_UNSET " * (MAX_NESTING - 1) + "deep" + ")" * (MAX_NESTING - 1)
    app = parse_application_string(with_attribute(inner))
    assert app.components[0].attributes[0].value == "deep"


def test_a_thousand_nested_substitutions_are_an_error_not_a_recursion_error():
    deep = "$(optenv COCO_TEST_UNSET " * 1000 + "x" + ")" * 1000
    ((where, message),) = errors_of(lambda: parse_application_string(with_attribute(deep), "app.xml"))
    assert where == "app.xml:3"
    assert message.endswith(f"substitutions nest more than {MAX_NESTING} deep")


def test_fifty_thousand_unclosed_substitutions_fail_fast():
    # Matching each "$(" by scanning the rest of the text took minutes; it is one pass now.
    with at_most(5):
        ((where, message),) = errors_of(lambda: parse_application_string(with_attribute("$(" * 50_000), "app.xml"))
    assert where == "app.xml:3"
    assert "unterminated $(" in message


def test_fifty_thousand_nested_substitutions_fail_fast():
    with at_most(5):
        ((_, message),) = errors_of(lambda: parse_application_string(with_attribute("$(" * 50_000 + ")" * 50_000)))
    assert message.endswith(f"substitutions nest more than {MAX_NESTING} deep")


def test_an_include_chain_deeper_than_the_limit_is_an_error(tmp_path):
    depth = 350
    for index in range(depth):
        include = f"<includes><include>f{index + 1}.xml</include></includes>" if index + 1 < depth else ""
        (tmp_path / f"f{index}.xml").write_text(f"<package>\n{include}\n</package>\n")
    ((where, message),) = errors_of(lambda: load_application(tmp_path / "f0.xml"))
    assert where == f"{tmp_path / f'f{MAX_INCLUDE_DEPTH - 1}.xml'}:2"
    assert message.startswith(f"includes nest more than {MAX_INCLUDE_DEPTH} files deep (from {tmp_path / 'f0.xml'})")


def test_an_include_chain_within_the_limit_loads(tmp_path):
    for index in range(MAX_INCLUDE_DEPTH):
        include = f"<includes><include>f{index + 1}.xml</include></includes>" if index + 1 < MAX_INCLUDE_DEPTH else ""
        (tmp_path / f"f{index}.xml").write_text(f'<package>{include}<arg name="a{index}" value="1"/></package>')
    assert len(load_application(tmp_path / "f0.xml").args) == MAX_INCLUDE_DEPTH


def nested_peers(depth: int) -> str:
    opening = "".join(f"<component><task>T</task><name>p{level}</name><components>" for level in range(depth))
    closing = "</components></component>" * depth
    return f"<package>\n<components>{opening}<component><task>T</task><name>leaf</name></component>{closing}</components></package>"


def test_peers_nested_a_thousand_deep_are_an_error():
    ((where, message),) = errors_of(lambda: parse_application_string(nested_peers(1000), "app.xml"))
    assert where == "app.xml:2"
    assert message == f"peers nest more than {MAX_PEER_DEPTH} deep here; the peers of this component are not read"


def test_peers_nest_up_to_the_limit():
    app = parse_application_string(nested_peers(MAX_PEER_DEPTH))
    assert len(app.all_components()) == MAX_PEER_DEPTH + 1


# ----- what a file name may point at ------------------------------------------------------------


def include_of(tmp_path, target: str):
    path = tmp_path / "app.xml"
    path.write_text(f"<package>\n<includes>\n<include>{target}</include>\n</includes>\n</package>\n")
    return lambda: load_application(path)


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
def test_an_include_of_a_device_is_refused(tmp_path, device):
    with at_most(5):
        ((where, message),) = errors_of(include_of(tmp_path, device))
    assert where == f"{tmp_path / 'app.xml'}:3"
    assert message == f"included file {device} is a character device, not a regular file"


def test_an_include_of_a_fifo_does_not_block(tmp_path):
    os.mkfifo(tmp_path / "pipe.xml")
    with at_most(5):
        ((_, message),) = errors_of(include_of(tmp_path, "pipe.xml"))
    assert message == f"included file {tmp_path / 'pipe.xml'} is a FIFO, not a regular file"


def test_an_include_larger_than_the_limit_is_refused(tmp_path):
    with open(tmp_path / "huge.xml", "wb") as huge:
        huge.truncate(APPLICATION_FILE_LIMIT + 1)  # sparse: no disk used
    ((_, message),) = errors_of(include_of(tmp_path, "huge.xml"))
    assert message == (f"included file {tmp_path / 'huge.xml'} has {APPLICATION_FILE_LIMIT + 1} bytes, "
                       f"more than the limit of {APPLICATION_FILE_LIMIT}")


def test_the_application_file_itself_must_be_a_regular_file(tmp_path):
    os.mkfifo(tmp_path / "app.xml")
    with at_most(5), pytest.raises(ConfigError, match="is a FIFO, not a regular file"):
        load_application(tmp_path / "app.xml")


def test_read_regular_file_stops_at_the_limit(tmp_path):
    (tmp_path / "f").write_bytes(b"x" * 100)
    assert read_regular_file(tmp_path / "f", 100) == b"x" * 100
    with pytest.raises(FileReadError, match="has 100 bytes, more than the limit of 99"):
        read_regular_file(tmp_path / "f", 99)
    with pytest.raises(FileReadError, match="is a directory, not a regular file"):
        read_regular_file(tmp_path, 99, "URDF")
    with pytest.raises(FileReadError, match="cannot read mesh .*missing: No such file or directory"):
        read_regular_file(tmp_path / "missing", 99, "mesh")


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
def test_a_urdf_of_a_device_is_refused_by_the_loader_and_by_load_urdf(tmp_path, device):
    text = f'<package>\n<transforms>\n<urdf file="{device}"/>\n</transforms>\n</package>'
    ((where, message),) = errors_of(lambda: parse_application_string(text, "app.xml"))
    assert where == "app.xml:3"
    assert message == f"<urdf> file {device} is a character device, not a regular file"
    with at_most(5), pytest.raises(UrdfError, match="is a character device, not a regular file"):
        load_urdf(TransformGraph(), device)


def test_load_urdf_of_a_fifo_does_not_block(tmp_path):
    os.mkfifo(tmp_path / "robot.urdf")
    with at_most(5), pytest.raises(UrdfError, match="is a FIFO, not a regular file"):
        load_urdf(TransformGraph(), tmp_path / "robot.urdf")


# ----- expansion --------------------------------------------------------------------------------


def test_args_that_double_each_other_stop_at_the_expansion_limit():
    declarations = '\n<arg name="a0" value="xxxxxxxxxxxxxxxx"/>' + "".join(
        f'\n<arg name="a{index}" value="$(arg a{index - 1})$(arg a{index - 1})"/>' for index in range(1, 31)
    )
    with at_most(5):
        errors = errors_of(lambda: parse_application_string(f"<package>{declarations}\n</package>", "app.xml"))
    # 16 * 2**16 characters exceed the limit: a16 is refused (and the args after it, built on its
    # empty value, stay small).
    assert errors[0] == (
        "app.xml:18",
        f'<arg> attribute value="$(arg a15)$(arg a15)": the expanded value would have more than '
        f"{MAX_EXPANSION} characters",
    )
    assert len(errors) == 1


def test_round_with_a_huge_number_of_digits_is_refused_before_it_computes():
    # round(1, -10**18) computes 10**(10**18): one operation of Python's that never ends and no
    # signal interrupts; 10**6 digits already cost a noticeable fraction of a second.
    with at_most(5):
        ((where, message),) = errors_of(lambda: parse_application_string(
            '<package>\n<arg name="y" default="$(eval round(1, -10**6))"/>\n</package>', "app.xml"))
    assert where == "app.xml:2"
    assert message.endswith(f"round(): -1000000 digits; at most {MAX_ROUND_DIGITS} either way are allowed")
    app = parse_application_string(f'<package><arg name="y" default="$(eval round(123456, -{MAX_ROUND_DIGITS}))"/></package>')
    assert app.args["y"] == "0"


def test_an_expression_stops_at_its_time_limit(monkeypatch):
    monkeypatch.setattr(expression, "MAX_SECONDS", -1.0)  # any expression is past it at its first node
    ((_, message),) = errors_of(lambda: parse_application_string(
        '<package><arg name="y" default="$(eval 1 + 1)"/></package>', "app.xml"))
    assert message.endswith("the expression takes more than -1 s to evaluate")


def test_files_that_include_the_next_one_twice_stop_at_the_include_limit(tmp_path):
    # Each file includes the next one twice: 30 files would be read 2**30 times.
    for index in range(30):
        includes = f"<include>f{index + 1}.xml</include>" * 2 if index + 1 < 30 else ""
        (tmp_path / f"f{index}.xml").write_text(
            f'<package>\n<includes>{includes}</includes>\n<arg name="a{index}" default="1"/>\n</package>\n')
    with at_most(20):
        ((where, message),) = errors_of(lambda: load_application(tmp_path / "f0.xml"))
    assert where.endswith(":2")
    assert message.startswith(f"the application includes more than {MAX_INCLUDES} files or 64 MiB in all")


def test_an_application_of_many_includes_within_the_limit_loads(tmp_path):
    (tmp_path / "leaf.xml").write_text('<package><arg name="leaf" default="1"/></package>')
    includes = "<include>leaf.xml</include>" * MAX_INCLUDES
    (tmp_path / "app.xml").write_text(f"<package><includes>{includes}</includes></package>")
    assert load_application(tmp_path / "app.xml").args == {"leaf": "1"}


# ----- many components --------------------------------------------------------------------------


def test_the_entry_points_are_scanned_once_for_all_components(monkeypatch):
    scans = []
    original = registry.entry_points

    def counting(**selection):
        scans.append(selection)
        return original(**selection)

    monkeypatch.setattr(registry, "entry_points", counting)
    registry._installed.cache_clear()
    components = "".join(f"<component><task>MovingAverage</task><name>m{index}</name></component>"
                         for index in range(200))
    app = build_application(parse_application_string(f"<package><components>{components}</components></package>"))
    assert len(app.components) == 200
    assert scans == [{"group": registry.GROUP}]


# ----- values out of range ----------------------------------------------------------------------


@pytest.mark.parametrize("period", ["1e300", "86400001"])
def test_a_period_beyond_a_day_is_an_error_at_the_schedule(period):
    # 1e300 ms passed --check, then ended the activity's thread at its first sleep (exit status 0).
    text = (f'<package>\n<activities><activity><schedule period="{period}"/>\n'
            "<components><component>c</component></components></activity></activities></package>")
    errors = errors_of(lambda: parse_application_string(text, "app.xml"))
    assert ("app.xml:2", f'<schedule> attribute period="{period}": expected a period greater than 0 '
                         "milliseconds and at most 86400000 (a day)") in errors


@pytest.mark.parametrize("task", [".".join(["a"] * 5000) + ":Thing", "coco_core.demo:Not-a-name"])
def test_a_task_path_that_cannot_name_a_class_is_an_error_not_a_traceback(task):
    # 5,000 dotted parts exhausted the import system's recursion: a RecursionError traceback.
    text = f"<package>\n<components><component><name>c</name><task>{task}</task></component></components></package>"
    with pytest.raises(ConfigErrors) as raised:
        build_application(parse_application_string(text, "app.xml"))
    ((error),) = raised.value.errors
    assert str(error.location) == "app.xml:2"
    assert error.message.startswith("cannot import component ")
    assert error.message.endswith("expected package.module:Class, Python names separated by dots (at most 32 of them)")
    assert len(error.message) < 300
