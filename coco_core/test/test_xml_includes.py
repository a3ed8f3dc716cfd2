"""<include>, resource paths and type="file" attributes: finding files and merging them."""

from pathlib import Path

import pytest

from coco_core.errors import ConfigErrors
from coco_core.xml import load_application, parse_application_string


def write(directory: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = directory / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def errors_of(path: Path, **kwargs) -> list[tuple[str, int | None, str]]:
    with pytest.raises(ConfigErrors) as raised:
        load_application(path, **kwargs)
    return [
        (Path(e.location.file).name if e.location else "", e.location.line if e.location else None, e.message)
        for e in raised.value.errors
    ]


def component(task: str, *, name: str = "", extra: str = "") -> str:
    named = f"<name>{name}</name>" if name else ""
    return f"<component{extra}>{named}<task>{task}</task></component>"


def test_included_items_come_where_the_include_stands(tmp_path):
    write(tmp_path, {
        "app.xml": f"""<package>
  <components>{component("First")}</components>
  <includes><include>parts/part.xml</include></includes>
  <components>{component("Last")}</components>
  <connections>
    <connection><src task="First" port="o"/><dest task="Middle" port="i"/></connection>
  </connections>
  <activities>
    <activity><schedule/><components><component name="Last"/></components></activity>
  </activities>
</package>""",
        "parts/part.xml": f"""<package>
  <paths><path>res</path></paths>
  <arg name="who" default="Middle"/>
  <components>{component("$(arg who)")}</components>
  <activities>
    <activity><schedule/><components><component name="Middle"/></components></activity>
  </activities>
</package>""",
    })
    app = load_application(tmp_path / "app.xml")
    assert [c.name for c in app.components] == ["First", "Middle", "Last"]
    assert app.components[1].location.file == str(tmp_path / "parts" / "part.xml")
    assert [a.components for a in app.activities] == [["Middle"], ["Last"]]
    assert [a.name for a in app.activities] == ["activity1", "activity2"]
    assert app.paths == [str(tmp_path / "parts" / "res")]
    assert app.args == {"who": "Middle"}


def test_args_of_the_includer_are_visible_in_the_included_file_and_back(tmp_path):
    write(tmp_path, {
        "app.xml": """<package>
  <arg name="outer" default="Outer"/>
  <includes><include>inner.xml</include></includes>
  <components><component><task>$(arg inner)</task></component></components>
</package>""",
        "inner.xml": """<package>
  <arg name="inner" default="Inner"/>
  <components><component><task>$(arg outer)</task></component></components>
</package>""",
    })
    app = load_application(tmp_path / "app.xml", args={"inner": "Given"})
    assert [c.task for c in app.components] == ["Outer", "Given"]


def test_include_is_searched_in_the_resource_paths_and_may_be_conditional(tmp_path):
    write(tmp_path, {
        "app.xml": """<package>
  <arg name="with_extra" default="false"/>
  <paths><path>lib</path></paths>
  <includes>
    <include>shared.xml</include>
    <include if="$(arg with_extra)">extra.xml</include>
  </includes>
</package>""",
        "lib/shared.xml": f"<package><components>{component('Shared')}</components></package>",
    })
    assert [c.name for c in load_application(tmp_path / "app.xml").components] == ["Shared"]
    assert errors_of(tmp_path / "app.xml", args={"with_extra": "true"}) == [
        ("app.xml", 6, f"<include> 'extra.xml' not found; tried: {tmp_path / 'extra.xml'}, "
                       f"{tmp_path / 'lib' / 'extra.xml'}"),
    ]


def test_errors_in_an_included_file_carry_its_name_and_line(tmp_path):
    write(tmp_path, {
        "app.xml": f"""<package>
  <components>{component("A")}</components>
  <includes><include>bad.xml</include><include>broken.xml</include></includes>
  <components>{component("A")}</components>
</package>""",
        "bad.xml": """<package on_error="continue">
  <components>
    <component><task>B</task><colour/></component>
  </components>
</package>""",
        "broken.xml": "<package>\n<components>\n</package>",
    })
    assert errors_of(tmp_path / "app.xml") == [
        ("bad.xml", 3, "unexpected element <colour> in <component>; expected one of: attributes, "
                       "components, library, name, task"),
        ("broken.xml", 3, "XML syntax error: mismatched tag (column 3)"),
        # Checks across files are skipped when a file could not be read, so the duplicate "A" on
        # line 4 is not reported until broken.xml is fixed.
    ]


def test_duplicate_names_across_files_name_both_places(tmp_path):
    write(tmp_path, {
        "app.xml": f"""<package>
  <includes><include>other.xml</include></includes>
  <components>{component("A")}</components>
</package>""",
        "other.xml": f"<package>\n<components>\n{component('A')}\n</components>\n</package>",
    })
    assert errors_of(tmp_path / "app.xml") == [
        ("app.xml", 3, f"component name 'A' is already used at {tmp_path / 'other.xml'}:3; instance "
                       "names must be unique (give one of them a <name>)"),
    ]


def test_include_cycle_names_the_chain(tmp_path):
    write(tmp_path, {
        "a.xml": "<package>\n<includes><include>b.xml</include></includes>\n</package>",
        "b.xml": "<package>\n\n<includes><include>sub/../a.xml</include></includes>\n</package>",
    })
    assert errors_of(tmp_path / "a.xml") == [
        ("b.xml", 3, f"include cycle: {tmp_path / 'a.xml'} -> {tmp_path / 'b.xml'} -> {tmp_path / 'a.xml'}"),
    ]


def test_including_itself_is_a_cycle(tmp_path):
    write(tmp_path, {"self.xml": "<package><includes><include>self.xml</include></includes></package>"})
    ((_, line, message),) = errors_of(tmp_path / "self.xml")
    assert (line, message) == (1, f"include cycle: {tmp_path / 'self.xml'} -> {tmp_path / 'self.xml'}")


def test_package_on_error_is_the_default_of_its_own_components(tmp_path):
    write(tmp_path, {
        "app.xml": f"""<package on_error="stop_app">
  <components>{component("Top")}</components>
  <includes><include>part.xml</include></includes>
</package>""",
        "part.xml": f"""<package on_error="stop_component">
  <components>{component("Part")}{component("Own", extra=' on_error="continue"')}</components>
</package>""",
    })
    app = load_application(tmp_path / "app.xml")
    assert app.on_error == "stop_app"
    assert [(c.name, c.on_error) for c in app.components] == [
        ("Top", ""),
        ("Part", "stop_component"),
        ("Own", "continue"),
    ]


def test_string_applications_resolve_relative_to_the_working_directory(tmp_path, monkeypatch):
    write(tmp_path, {"part.xml": f"<package><components>{component('P')}</components></package>"})
    monkeypatch.chdir(tmp_path)
    app = parse_application_string("<package><includes><include>part.xml</include></includes></package>")
    assert [c.name for c in app.components] == ["P"]


# ----- type="file" attributes -------------------------------------------------------------------


def file_attributes(value: str, paths: str = "") -> str:
    return f"""<package>
  <paths>{paths}</paths>
  <components>
    <component>
      <task>T</task>
      <attributes>
        <attribute name="f" value="{value}" type="file"/>
        <attribute name="plain" value="{value}"/>
      </attributes>
    </component>
  </components>
</package>"""


def test_file_attribute_next_to_the_file(tmp_path):
    write(tmp_path, {"app.xml": file_attributes("data/model.urdf"), "data/model.urdf": ""})
    attributes = load_application(tmp_path / "app.xml").components[0].attributes
    assert [(a.name, a.value, a.type) for a in attributes] == [
        ("f", str(tmp_path / "data" / "model.urdf"), "file"),
        ("plain", "data/model.urdf", ""),
    ]


def test_file_attribute_in_resource_paths_in_order(tmp_path):
    write(tmp_path, {
        "app/app.xml": file_attributes("mesh.obj", "<path>../first</path><path>../second</path>"),
        "first/other.obj": "",
        "second/mesh.obj": "",
    })
    attribute = load_application(tmp_path / "app" / "app.xml").components[0].attributes[0]
    assert attribute.value == str(tmp_path / "second" / "mesh.obj")


def test_file_attribute_in_an_included_file_starts_from_that_file(tmp_path):
    write(tmp_path, {
        "app.xml": "<package><includes><include>sub/part.xml</include></includes></package>",
        "sub/part.xml": file_attributes("here.txt"),
        "sub/here.txt": "",
    })
    attribute = load_application(tmp_path / "app.xml").components[0].attributes[0]
    assert attribute.value == str(tmp_path / "sub" / "here.txt")


def test_absolute_file_attribute_stays(tmp_path):
    target = tmp_path / "abs.txt"
    target.write_text("")
    write(tmp_path, {"app.xml": file_attributes(str(target))})
    assert load_application(tmp_path / "app.xml").components[0].attributes[0].value == str(target)


def test_missing_file_attribute_lists_the_places_tried(tmp_path):
    write(tmp_path, {"app.xml": file_attributes("nowhere.txt", "<path>res</path>")})
    assert errors_of(tmp_path / "app.xml") == [
        ("app.xml", 7, f'<attribute name="f" type="file"> \'nowhere.txt\' not found; tried: '
                       f"{tmp_path / 'nowhere.txt'}, {tmp_path / 'res' / 'nowhere.txt'}"),
    ]


def test_resourcespaths_of_the_legacy_layout(tmp_path):
    write(tmp_path, {
        "app.xml": """<package>
  <resourcespaths><librariespath>lib</librariespath><path>/abs/res</path></resourcespaths>
</package>""",
    })
    assert load_application(tmp_path / "app.xml").paths == [str(tmp_path / "lib"), "/abs/res"]
