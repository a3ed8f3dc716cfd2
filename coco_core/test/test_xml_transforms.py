"""``<transforms>``: the declared structure of the transformation graph, read from application files.

Every element and attribute, substitutions and conditions, the merge of sections across included
files, and every error with its file and line.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from coco_core.errors import ConfigErrors
from coco_core.transforms import se3
from coco_core.xml import load_application, parse_application_string

WORKSPACE = Path(__file__).resolve().parents[2]
SCHEMA = WORKSPACE / "docs" / "coco.xsd"

EVERY_ELEMENT = """<package>
  <arg name="height" default="1.2"/>
  <arg name="with_bowl" default="true"/>
  <transforms strict="true" history="100">
    <frame name="world"/>
    <static parent="world" child="camera" xyz="0 0 $(arg height)" rpy="0 0.3 0"/>
    <static parent="camera" child="optical" quaternion="-0.5 0.5 -0.5 0.5"/>
    <dynamic parent="world" child="bowl" history="200" if="$(arg with_bowl)"/>
    <dynamic parent="world" child="cup" unless="$(arg with_bowl)"/>
    <axis parent="base" child="arm" joint="j1" type="revolute" xyz="0 0 0.3" rpy="0 0 1.5"
          axis="0 1 0" value="0.25"/>
    <axis parent="arm" child="slider" joint="j2" type="prismatic"/>
    <axis parent="l1" child="l2" joint="j3" type="continuous" dh="0.1 0.2 0.3 0.4" value="-1e-1"/>
    <urdf file="package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"
          prefix="left/" joint_prefix="left_" name="baxter_left" attach="world" xyz="1 2 3"
          quaternion="0 0 1 1"/>
    <urdf file="file:///opt/robot.urdf"/>
  </transforms>
</package>
"""
"""Every element of ``<transforms>``, each attribute at least once, on known lines."""


def errors_of(text: str, **kwargs) -> list[tuple[int | None, str]]:
    with pytest.raises(ConfigErrors) as raised:
        parse_application_string(text, **kwargs)
    return [(e.location.line if e.location else None, e.message) for e in raised.value.errors]


def file_errors_of(path: Path, **kwargs) -> list[tuple[str, int | None, str]]:
    with pytest.raises(ConfigErrors) as raised:
        load_application(path, **kwargs)
    return [
        (Path(e.location.file).name if e.location else "", e.location.line if e.location else None, e.message)
        for e in raised.value.errors
    ]


def in_transforms(body: str, attributes: str = "") -> str:
    """A package whose ``<transforms>`` is on line 2 and whose ``body`` starts on line 3."""
    return f"<package>\n<transforms{attributes}>\n{body}\n</transforms>\n</package>"


def write(directory: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = directory / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


# ----- loading ----------------------------------------------------------------------------------


def test_every_element_is_read_with_its_values():
    spec = parse_application_string(EVERY_ELEMENT, filename="app.xml").transforms

    assert spec is not None
    assert (spec.strict, spec.history) == (True, 100)
    assert (str(spec.location)) == "app.xml:4"
    assert [(f.name, f.location.line) for f in spec.frames] == [("world", 5)]
    assert [(e.kind, e.parent, e.child, e.location.line) for e in spec.edges] == [
        ("static", "world", "camera", 6),
        ("static", "camera", "optical", 7),
        ("dynamic", "world", "bowl", 8),
        ("axis", "base", "arm", 10),
        ("axis", "arm", "slider", 12),
        ("axis", "l1", "l2", 13),
    ]
    camera, optical, bowl, j1, j2, j3 = spec.edges
    np.testing.assert_allclose(camera.origin, se3.make(se3.rpy_to_matrix(0, 0.3, 0), [0, 0, 1.2]))
    np.testing.assert_allclose(optical.origin, se3.from_pose([0, 0, 0], [-0.5, 0.5, -0.5, 0.5]))
    assert bowl.history == 200
    assert (j1.joint, j1.joint_type, j1.axis, j1.value, j1.dh) == ("j1", "revolute", (0.0, 1.0, 0.0), 0.25, None)
    np.testing.assert_allclose(j1.origin, se3.make(se3.rpy_to_matrix(0, 0, 1.5), [0, 0, 0.3]))
    assert (j2.joint, j2.joint_type, j2.axis, j2.value) == ("j2", "prismatic", (0.0, 0.0, 1.0), 0.0)
    np.testing.assert_allclose(j2.origin, np.eye(4))
    assert (j3.joint_type, j3.dh, j3.value) == ("continuous", (0.1, 0.2, 0.3, 0.4), -0.1)

    baxter, plain = spec.urdfs
    assert baxter.file == "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"
    assert (baxter.prefix, baxter.joint_prefix, baxter.name, baxter.attach) == (
        "left/", "left_", "baxter_left", "world")
    half_turn_about_z = se3.make(se3.rpy_to_matrix(0, 0, math.pi / 2), [1, 2, 3])
    np.testing.assert_allclose(baxter.origin, half_turn_about_z, atol=1e-12)
    assert baxter.location.line == 14
    assert (plain.file, plain.attach, plain.prefix) == ("file:///opt/robot.urdf", "", "")
    np.testing.assert_allclose(plain.origin, np.eye(4))


def test_substitutions_and_conditions_apply_to_every_attribute():
    text = EVERY_ELEMENT.replace('strict="true"', 'strict="$(arg strict)"').replace(
        '<arg name="height"', '<arg name="strict" default="no"/>\n  <arg name="height"')
    spec = parse_application_string(text, args={"height": "2.5", "with_bowl": "false"}).transforms
    assert spec is not None and spec.strict is False
    assert spec.edges[0].origin[2][3] == 2.5
    assert [e.child for e in spec.edges if e.kind == "dynamic"] == ["cup"]
    assert spec.edges[2].history is None  # the section's history applies to it (see the builder)


def test_the_section_is_optional_and_may_be_switched_off():
    assert parse_application_string("<package/>").transforms is None
    text = '<package><arg name="tf" default="false"/><transforms if="$(arg tf)"><frame name="w"/></transforms></package>'
    assert parse_application_string(text).transforms is None
    spec = parse_application_string(text, args={"tf": "true"}).transforms
    assert spec is not None and [f.name for f in spec.frames] == ["w"]


def test_defaults_of_an_empty_section():
    spec = parse_application_string("<package><transforms/></package>").transforms
    assert spec is not None
    assert (spec.strict, spec.history, spec.frames, spec.edges, spec.urdfs) == (True, None, [], [], [])


def test_sections_of_included_files_are_merged_in_document_order(tmp_path):
    write(tmp_path, {
        "app.xml": """<package>
  <transforms strict="false">
    <frame name="world"/>
    <static parent="world" child="table" xyz="0 0 0.7"/>
  </transforms>
  <includes><include>cell/robot.xml</include></includes>
  <transforms>
    <dynamic parent="world" child="bowl"/>
  </transforms>
</package>""",
        "cell/robot.xml": """<package>
  <transforms strict="false" history="20">
    <frame name="world"/>
    <frame name="tcp"/>
    <static parent="table" child="base"/>
    <urdf file="urdf/arm.urdf" attach="base"/>
  </transforms>
</package>""",
        "cell/urdf/arm.urdf": "<robot name='arm'/>",
    })
    spec = load_application(tmp_path / "app.xml").transforms

    assert spec is not None
    assert (spec.strict, spec.history) == (False, 20)
    assert spec.location.file == str(tmp_path / "app.xml")
    assert [f.name for f in spec.frames] == ["world", "tcp"]
    assert spec.frames[0].location.file == str(tmp_path / "app.xml")
    assert [(e.parent, e.child, Path(e.location.file).name, e.location.line) for e in spec.edges] == [
        ("world", "table", "app.xml", 4),
        ("table", "base", "robot.xml", 5),
        ("world", "bowl", "app.xml", 8),
    ]
    (urdf,) = spec.urdfs
    assert urdf.file == str(tmp_path / "cell" / "urdf" / "arm.urdf")  # next to the file that names it


def test_urdf_files_are_searched_in_the_resource_paths(tmp_path):
    write(tmp_path, {
        "app.xml": """<package>
  <transforms><urdf file="arm.urdf"/></transforms>
  <paths><path>robots</path></paths>
</package>""",
        "robots/arm.urdf": "<robot name='arm'/>",
    })
    (urdf,) = load_application(tmp_path / "app.xml").transforms.urdfs
    assert urdf.file == str(tmp_path / "robots" / "arm.urdf")


# ----- errors -----------------------------------------------------------------------------------


def test_numbers_are_checked_with_what_was_expected():
    text = in_transforms("""<static parent="a" child="b" xyz="0 0" rpy="1 2 x"/>
<static parent="a" child="c" quaternion="0 0 0 0"/>
<dynamic parent="a" child="d" history="0"/>
<axis parent="a" child="e" joint="j" type="revolute" axis="0 0 0" value="fast"/>
<axis parent="a" child="f" joint="k" type="prismatic" dh="1 2 3"/>
<urdf file="package://robots/r.urdf" attach="a" xyz="1,2,3"/>""", ' history="-5" strict="maybe"')
    assert errors_of(text) == [
        (2, '<transforms> attribute strict="maybe": expected true/false, 1/0, yes/no or on/off'),
        (2, '<transforms> attribute history="-5": expected a number of samples, at least 1'),
        (3, '<static> attribute xyz="0 0": expected 3 numbers x y z (metres)'),
        (3, '<static> attribute rpy="1 2 x": expected 3 numbers roll pitch yaw (radians)'),
        (4, '<static> attribute quaternion="0 0 0 0": expected 4 numbers x y z w, not all zero'),
        (5, '<dynamic> attribute history="0": expected a number of samples, at least 1'),
        (6, '<axis> attribute value="fast": expected a joint value (radians or metres)'),
        (6, '<axis> attribute axis="0 0 0": expected 3 numbers x y z, not all zero'),
        (7, '<axis> attribute dh="1 2 3": expected 4 numbers d theta r alpha (metres and radians)'),
        (8, '<urdf> attribute xyz="1,2,3": expected 3 numbers x y z (metres)'),
    ]


def test_rotation_is_given_one_way():
    text = in_transforms('<static parent="a" child="b" rpy="0 0 1" quaternion="0 0 0 1"/>')
    assert errors_of(text) == [
        (3, "<static> has both rpy= and quaternion=; they are two ways to give the rotation: give one"),
    ]


def test_joint_type_and_required_attributes():
    text = in_transforms("""<axis parent="a" child="b" joint="j" type="ball"/>
<axis parent="a" child="c"/>
<static child="d"/>
<dynamic parent="e" child="e"/>
<frame/>
<urdf/>""")
    assert errors_of(text) == [
        (3, '<axis> attribute type="ball" is not valid; expected one of: revolute, continuous, prismatic'),
        (4, "<axis> needs a joint= attribute"),
        (4, "<axis> needs a type= attribute"),
        (5, "<static> needs a parent= attribute"),
        (6, '<dynamic> parent= and child= are both "e"; an edge joins two different frames'),
        (7, "<frame> needs a name= attribute"),
        (8, "<urdf> needs a file= attribute"),
    ]


def test_geometry_given_twice_or_without_its_frame():
    text = in_transforms("""<axis parent="a" child="b" joint="j" type="revolute" dh="0 0 1 0" xyz="1 0 0" axis="1 0 0"/>
<urdf file="package://robots/r.urdf" rpy="0 0 1" xyz="0 0 1"/>
<urdf file="http://example.com/r.urdf"/>""")
    assert errors_of(text) == [
        (3, "<axis> has dh= and xyz=, axis=: dh= gives the whole joint geometry (d theta r alpha, moving "
            "about z); give one or the other"),
        (4, "<urdf> has xyz=, rpy= but no attach=: they place the robot's root link in the attach= frame; "
            "give attach="),
        (5, '<urdf> attribute file="http://example.com/r.urdf": expected a file name, a package:// URL or a '
            "file:// URL"),
    ]


def test_unknown_elements_and_attributes_list_the_valid_ones():
    text = in_transforms("""<joint name="j"/>
<static parent="a" child="b" origin="0 0 0"/>
oops""", ' mode="x"')
    assert errors_of(text) == [
        (2, 'unexpected attribute mode="x" in <transforms>; expected one of: history, if, strict, unless'),
        (2, "unexpected text 'oops' in <transforms>; it contains elements only"),
        (3, "unexpected element <joint> in <transforms>; expected one of: axis, dynamic, frame, static, urdf"),
        (4, 'unexpected attribute origin="0 0 0" in <static>; expected one of: child, if, parent, '
            "quaternion, rpy, unless, xyz"),
    ]


def test_an_edge_between_the_same_frames_is_declared_once():
    text = in_transforms("""<static parent="a" child="b"/>
<dynamic parent="b" child="a"/>
<axis parent="a" child="b" joint="j" type="revolute"/>""")
    assert errors_of(text, filename="app.xml") == [
        (4, "<dynamic> b->a: frames b and a are already joined by the static edge a->b declared at app.xml:3; "
            "two frames are joined by at most one edge"),
        (5, "<axis> a->b: frames a and b are already joined by the static edge a->b declared at app.xml:3; "
            "two frames are joined by at most one edge"),
    ]


def test_duplicate_edge_across_an_include_names_both_places(tmp_path):
    write(tmp_path, {
        "app.xml": """<package>
  <transforms>
    <static parent="world" child="camera" xyz="0 0 1"/>
  </transforms>
  <includes><include>camera.xml</include></includes>
</package>""",
        "camera.xml": """<package>
  <transforms>
    <frame name="world"/>
    <dynamic parent="world" child="camera"/>
  </transforms>
</package>""",
    })
    assert file_errors_of(tmp_path / "app.xml") == [
        ("camera.xml", 4,
         f"<dynamic> world->camera: frames world and camera are already joined by the static edge "
         f"world->camera declared at {tmp_path / 'app.xml'}:3; two frames are joined by at most one edge"),
    ]


def test_joint_names_are_unique():
    text = in_transforms("""<axis parent="a" child="b" joint="elbow" type="revolute"/>
<axis parent="b" child="c" joint="elbow" type="prismatic"/>""")
    assert errors_of(text, filename="app.xml") == [
        (4, "joint 'elbow' already drives edge a->b declared at app.xml:3; joint names are unique"),
    ]


def test_merged_sections_must_agree_on_their_settings(tmp_path):
    write(tmp_path, {
        "app.xml": """<package>
  <transforms strict="true" history="50"/>
  <includes><include>part.xml</include></includes>
</package>""",
        "part.xml": """<package>
  <transforms strict="yes" history="50"/>
  <transforms strict="false" history="10"/>
</package>""",
    })
    first = f"{tmp_path / 'app.xml'}:2"
    assert file_errors_of(tmp_path / "app.xml") == [
        ("part.xml", 3, f'<transforms> attribute strict="false" contradicts strict="true" at {first}; '
                        "the <transforms> sections of an application are merged: give strict= once"),
        ("part.xml", 3, f'<transforms> attribute history="10" contradicts history="50" at {first}; '
                        "the <transforms> sections of an application are merged: give history= once"),
    ]


def test_a_missing_urdf_file_lists_the_places_tried(tmp_path):
    write(tmp_path, {"app.xml": """<package>
  <paths><path>robots</path></paths>
  <transforms><urdf file="arm.urdf"/></transforms>
</package>"""})
    assert file_errors_of(tmp_path / "app.xml") == [
        ("app.xml", 3, f"<urdf> file 'arm.urdf' not found; tried: {tmp_path / 'arm.urdf'}, "
                       f"{tmp_path / 'robots' / 'arm.urdf'}"),
    ]


def test_the_same_urdf_twice_needs_another_prefix(tmp_path):
    write(tmp_path, {"app.xml": """<package>
  <transforms>
    <urdf file="arm.urdf" attach="world"/>
    <urdf file="arm.urdf" attach="table"/>
    <urdf file="arm.urdf" prefix="right/" joint_prefix="right_"/>
  </transforms>
</package>""", "arm.urdf": "<robot name='arm'/>"})
    assert file_errors_of(tmp_path / "app.xml") == [
        ("app.xml", 4, f"<urdf> {tmp_path / 'arm.urdf'} is already loaded at {tmp_path / 'app.xml'}:3 with the "
                       "same name, prefix and joint_prefix; give this copy another prefix= and joint_prefix="),
    ]


def test_transforms_errors_come_with_the_others_in_line_order():
    text = """<package>
<components><component><task>A</task><bogus/></component></components>
<transforms><static parent="a" child="b" xyz="1"/></transforms>
<connections><connection><src task="A" port="o"/><dest task="Z" port="i"/></connection></connections>
</package>"""
    assert [line for line, _ in errors_of(text)] == [2, 3, 4]


# ----- schema -----------------------------------------------------------------------------------


def schema():
    xmlschema = pytest.importorskip("xmlschema")
    return xmlschema.XMLSchema(str(SCHEMA))


def test_every_element_validates_against_the_schema():
    assert [error.reason for error in schema().iter_errors(EVERY_ELEMENT)] == []


@pytest.mark.parametrize(
    "fragment",
    [
        '<static parent="a" child="b" xyz="0 0"/>',
        '<static parent="a" child="b" quaternion="0 0 1"/>',
        '<static parent="a"/>',
        '<dynamic parent="a" child="b" history="0"/>',
        '<axis parent="a" child="b" joint="j" type="ball"/>',
        '<axis parent="a" child="b" type="revolute"/>',
        '<axis parent="a" child="b" joint="j" type="revolute" dh="1 2 3"/>',
        '<urdf prefix="x"/>',
        '<joint name="j"/>',
        '<frame name="a" kind="x"/>',
    ],
)
def test_schema_rejects_what_the_loader_rejects(fragment):
    text = f"<package><transforms>{fragment}</transforms></package>"
    assert not schema().is_valid(text)
    with pytest.raises(ConfigErrors):
        parse_application_string(text)
