"""<arg> declarations, $(...) substitutions and if/unless conditions."""

import os
import sys
import types

import pytest

from coco_core.errors import ConfigErrors
from coco_core.xml import parse_application_string


def errors_of(text: str, **kwargs) -> list[tuple[int | None, str]]:
    with pytest.raises(ConfigErrors) as raised:
        parse_application_string(text, **kwargs)
    return [(e.location.line if e.location else None, e.message) for e in raised.value.errors]


def attribute_values(text: str, **kwargs) -> dict[str, str]:
    app = parse_application_string(text, **kwargs)
    return {a.name: a.value for a in app.components[0].attributes}


def with_attributes(attributes: str, declarations: str = "") -> str:
    return f"""<package>{declarations}
  <components>
    <component>
      <task>T</task>
      <attributes>
{attributes}
      </attributes>
    </component>
  </components>
</package>"""


# ----- args -------------------------------------------------------------------------------------


ARGS = """
  <arg name="rate" default="100"/>
  <arg name="mode" value="fast"/>
  <arg name="robot" doc="which robot; no default"/>"""


def test_arg_defaults_values_and_overrides():
    text = with_attributes(
        '<attribute name="r" value="$(arg rate)"/>\n'
        '<attribute name="m" value="$(arg mode)-$(arg robot)"/>',
        ARGS,
    )
    app = parse_application_string(text, args={"robot": "baxter"})
    assert app.args == {"rate": "100", "mode": "fast", "robot": "baxter"}
    assert attribute_values(text, args={"robot": "baxter", "rate": "250"}) == {
        "r": "250",
        "m": "fast-baxter",
    }


def test_arg_errors():
    text = with_attributes('<attribute name="r" value="$(arg rat)"/>', ARGS)
    assert errors_of(text, args={"mode": "slow", "robt": "x"}) == [
        (4, "arg 'robot' has no value: give it (robot:=VALUE) or declare a default="),
        (9, "<attribute> attribute value=\"$(arg rat)\": $(arg rat): no <arg> named 'rat' is "
             "declared before this point; did you mean 'rate'? valid: mode, rate, robot, robt"),
        (None, "arg 'robt' was given (robt:=x) but no file declares it; did you mean 'robot'? "
               "valid: mode, rate, robot"),
    ]


def test_arg_choices_as_in_ros2_launch():
    """``<choice value=.../>`` children list what an arg accepts, whoever gives the value."""
    declaration = """
  <arg name="source" default="sim">
    <choice value="sim"/>
    <choice value="bag"/>
  </arg>"""
    text = with_attributes('<attribute name="s" value="$(arg source)"/>', declaration)
    assert attribute_values(text) == {"s": "sim"}
    assert attribute_values(text, args={"source": "bag"}) == {"s": "bag"}
    assert errors_of(text, args={"source": "kinect"}) == [(2, "arg 'source' is 'kinect'; expected one of: sim, bag")]
    wrong = with_attributes("", '<arg name="a" default="x"><option value="x"/><choice/></arg>')
    assert errors_of(wrong) == [
        (1, "unexpected element <option> in <arg>; expected <choice value=.../>"),
        (1, "<choice> needs a value= attribute"),
    ]


def test_arg_bounds_hold_whoever_gives_the_value():
    """``min=`` / ``max=``: a number within them (the ROS launcher's parameter range), checked at the
    declaration for a default and for a given value alike."""
    declaration = '\n  <arg name="rate" default="1.0" min="0" max="10"/>'
    text = with_attributes('<attribute name="r" value="$(arg rate)"/>', declaration)
    app = parse_application_string(text, args={"rate": "10"})
    assert (app.arg_declarations["rate"].min, app.arg_declarations["rate"].max) == (0.0, 10.0)
    assert errors_of(text, args={"rate": "11"}) == [(2, "arg 'rate' is '11'; expected a number >= 0 and <= 10")]
    assert errors_of(text, args={"rate": "fast"}) == [(2, "arg 'rate' is 'fast'; expected a number >= 0 and <= 10")]
    assert errors_of(text, args={"rate": "nan"}) == [(2, "arg 'rate' is 'nan'; expected a number >= 0 and <= 10")]
    wrong = with_attributes("", '<arg name="a" default="1" min="low"/>')
    assert errors_of(wrong) == [(1, '<arg> attribute min="low": expected a number')]


def test_arg_must_be_declared_before_use():
    text = """<package>
  <components><component><task>$(arg t)</task></component></components>
  <arg name="t" default="T"/>
</package>"""
    assert errors_of(text) == [
        (2, "<task> text '$(arg t)': $(arg t): no <arg> named 't' is declared before this point; "
            "there are none"),
        (2, "<task> is empty; it names the component to instantiate"),
    ]


def test_arg_declaration_errors():
    text = """<package>
  <arg name="a" value="1" default="2"/>
  <arg name="bad name"/>
  <arg default="x"/>
  <arg name="a" value="3"/>
  <arg name="a" default="4"/>
</package>"""
    app_errors = errors_of(text)
    assert app_errors == [
        (2, "<arg> 'a' has both value= and default=; they are the same setting: give one"),
        (3, '<arg> attribute name="bad name": expected letters, digits, "_", "-" or "." '
            "(the name is used as $(arg NAME))"),
        (4, "<arg> needs a name= attribute"),
        (5, "arg 'a' is already declared at <string>:2; a repeated declaration may only give a default="),
    ]


def test_a_repeated_default_keeps_the_first_value():
    text = with_attributes(
        '<attribute name="v" value="$(arg a)"/>',
        '\n<arg name="a" default="first"/>\n<arg name="a" default="second"/>',
    )
    assert attribute_values(text) == {"v": "first"}


def test_a_default_is_expanded_only_when_used(monkeypatch):
    monkeypatch.delenv("COCO_TEST_UNSET", raising=False)
    text = with_attributes('<attribute name="v" value="$(arg a)"/>', '\n<arg name="a" default="$(env COCO_TEST_UNSET)"/>')
    assert attribute_values(text, args={"a": "given"}) == {"v": "given"}
    assert errors_of(text)[0][1].startswith('<arg> attribute default="$(env COCO_TEST_UNSET)": $(env COCO_TEST_UNSET)')


# ----- substitutions ----------------------------------------------------------------------------


def test_env_optenv_and_nesting(monkeypatch):
    monkeypatch.setenv("COCO_TEST_SET", "here")
    monkeypatch.delenv("COCO_TEST_UNSET", raising=False)
    text = with_attributes(
        """<attribute name="a" value="$(env COCO_TEST_SET)"/>
<attribute name="b" value="$(env COCO_TEST_UNSET two words)"/>
<attribute name="c" value="[$(optenv COCO_TEST_UNSET)]"/>
<attribute name="d" value="$(optenv COCO_TEST_UNSET $(arg x))"/>
<attribute name="e" value="$(optenv COCO_TEST_SET other)/x"/>""",
        '\n<arg name="x" default="fallback"/>',
    )
    assert attribute_values(text) == {
        "a": "here",
        "b": "two words",
        "c": "[]",
        "d": "fallback",
        "e": "here/x",
    }


def test_unset_env_and_unknown_substitutions_are_errors(monkeypatch):
    monkeypatch.delenv("COCO_TEST_UNSET", raising=False)
    text = with_attributes(
        """<attribute name="a" value="$(env COCO_TEST_UNSET)"/>
<attribute name="b" value="$(find pkg)"/>
<attribute name="c" value="$(arg x"/>
<attribute name="d" value="$(dirname extra)"/>"""
    )
    assert errors_of(text) == [
        (6, '<attribute> attribute value="$(env COCO_TEST_UNSET)": $(env COCO_TEST_UNSET): environment '
            "variable COCO_TEST_UNSET is not set (give a default: $(env COCO_TEST_UNSET default), or "
            "use $(optenv COCO_TEST_UNSET))"),
        (7, '<attribute> attribute value="$(find pkg)": unknown substitution $(find pkg); expected one '
            "of: anon, arg, dirname, env, eval, find-pkg-share, optenv"),
        (8, "<attribute> attribute value=\"$(arg x\": unterminated $( in '$(arg x': a ')' is missing"),
        (9, "<attribute> attribute value=\"$(dirname extra)\": $(dirname) takes no argument, got 'extra'"),
    ]


def test_anon_is_stable_within_a_load_and_unique_across_loads():
    text = with_attributes(
        """<attribute name="a" value="$(anon node)"/>
<attribute name="b" value="$(anon node)"/>
<attribute name="c" value="$(anon other)"/>"""
    )
    first, second = attribute_values(text), attribute_values(text)
    assert first["a"] == first["b"]
    assert first["a"].startswith(f"node_{os.getpid()}_")
    assert first["c"].startswith("other_") and first["c"] != first["a"]
    assert second["a"] != first["a"]


def test_dirname_is_the_directory_of_the_current_file(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "inner.xml").write_text(
        '<package><components><component><task>T</task><attributes>'
        '<attribute name="d" value="$(dirname)"/></attributes></component></components></package>'
    )
    (tmp_path / "app.xml").write_text(
        '<package name="$(dirname)"><includes><include>sub/inner.xml</include></includes></package>'
    )
    from coco_core.xml import load_application

    app = load_application(tmp_path / "app.xml")
    assert app.name == str(tmp_path)
    assert app.components[0].attributes[0].value == str(tmp_path / "sub")


def test_find_pkg_share(monkeypatch):
    fake = types.ModuleType("ament_index_python.packages")

    class PackageNotFoundError(KeyError):
        pass

    def get_package_share_directory(name):
        if name == "known_pkg":
            return "/opt/share/known_pkg"
        raise PackageNotFoundError(f"package '{name}' not found")

    fake.get_package_share_directory = get_package_share_directory
    monkeypatch.setitem(sys.modules, "ament_index_python", types.ModuleType("ament_index_python"))
    monkeypatch.setitem(sys.modules, "ament_index_python.packages", fake)
    text = with_attributes('<attribute name="p" value="$(find-pkg-share known_pkg)/urdf"/>')
    assert attribute_values(text) == {"p": "/opt/share/known_pkg/urdf"}
    (error,) = errors_of(with_attributes('<attribute name="p" value="$(find-pkg-share nope)"/>'))
    assert error[0] == 6
    assert "$(find-pkg-share nope): package 'nope' is not installed in the ament index" in error[1]


def test_find_pkg_share_without_ros(monkeypatch):
    monkeypatch.setitem(sys.modules, "ament_index_python", None)
    monkeypatch.setitem(sys.modules, "ament_index_python.packages", None)
    (error,) = errors_of(with_attributes('<attribute name="p" value="$(find-pkg-share any)"/>'))
    assert error == (
        6,
        '<attribute> attribute value="$(find-pkg-share any)": $(find-pkg-share any) needs '
        "ament_index_python: source a ROS 2 setup first",
    )


def test_substitutions_apply_to_text_and_typed_attributes():
    text = """<package>
  <arg name="task" default="Gen"/>
  <arg name="period" default="20"/>
  <arg name="policy" default="CIRCULAR"/>
  <components>
    <component><name>$(arg task)_1</name><task>$(arg task)</task></component>
    <component><task>B</task></component>
  </components>
  <connections>
    <connection data="$(arg policy)" buffersize="$(arg period)">
      <src task="$(arg task)_1" port="o"/><dest task="B" port="i"/>
    </connection>
  </connections>
  <activities>
    <activity><schedule period="$(arg period)"/><components><component name="Gen_1"/></components></activity>
  </activities>
</package>"""
    app = parse_application_string(text, args={"period": "5"})
    assert (app.components[0].name, app.components[0].task) == ("Gen_1", "Gen")
    assert app.connections[0].data.value == "CIRCULAR" and app.connections[0].buffersize == 5
    assert app.activities[0].schedule.period_ms == 5.0
    assert errors_of(text, args={"period": "fast"})[0] == (
        10,
        '<connection> attribute buffersize="fast": expected an integer',
    )


# ----- conditions -------------------------------------------------------------------------------


CONDITIONAL = """<package>
  <arg name="sim" default="false"/>
  <arg name="extra" default="" if="$(arg sim)"/>
  <components>
    <component><task>Real</task></component>
    <component if="$(arg sim)"><task>Sim</task></component>
    <component unless="$(arg sim)"><task>Hw</task>
      <attributes>
        <attribute name="a" value="1" if="TRUE"/>
        <attribute name="b" value="2" if="off"/>
        <attribute name="c" value="3" unless=""/>
      </attributes>
    </component>
  </components>
  <connections>
    <connection if="$(arg sim)"><src task="Sim" port="o"/><dest task="Real" port="i"/></connection>
    <connection unless="$(arg sim)"><src task="Hw" port="o"/><dest task="Real" port="i"/></connection>
  </connections>
  <activities>
    <activity if="$(arg sim)"><schedule/><components><component name="Sim"/></components></activity>
    <activity unless="$(arg sim)">
      <schedule/><components><component name="Hw"/><component name="Real" if="0"/></components>
    </activity>
    <pipeline if="yes"><components><component name="Real"/></components></pipeline>
  </activities>
</package>"""


def test_false_conditions_drop_elements_and_their_references():
    app = parse_application_string(CONDITIONAL)
    assert [c.name for c in app.components] == ["Real", "Hw"]
    assert [(a.name, a.value) for a in app.components[1].attributes] == [("a", "1"), ("c", "3")]
    assert [str(c.src) for c in app.connections] == ["Hw.o"]
    assert [(a.name, a.components) for a in app.activities] == [
        ("activity1", ["Hw"]),
        ("pipeline1.Real", ["Real"]),
    ]
    assert app.args == {"sim": "false"}

    simulated = parse_application_string(CONDITIONAL, args={"sim": "On"})
    assert [c.name for c in simulated.components] == ["Real", "Sim"]
    assert [str(c.src) for c in simulated.connections] == ["Sim.o"]
    assert simulated.args == {"sim": "On", "extra": ""}


def test_invalid_condition_is_an_error():
    text = with_attributes('<attribute name="a" value="1" if="maybe"/>\n<attribute name="b" unless="$(arg x)"/>')
    assert errors_of(text) == [
        (6, '<attribute> attribute if="maybe": expected true/false, 1/0, yes/no or on/off (or empty for false)'),
        (7, "<attribute> attribute unless=\"$(arg x)\": $(arg x): no <arg> named 'x' is declared "
            "before this point; there are none"),
    ]


def test_dropped_element_is_not_checked():
    text = """<package>
  <components>
    <component if="false" bogus="1"><nonsense/></component>
  </components>
</package>"""
    assert parse_application_string(text).components == []
