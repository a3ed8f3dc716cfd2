"""Wrong application files: every error points at its file and line and says what was expected."""

import pytest

from coco_core.errors import ConfigError, ConfigErrors
from coco_core.xml import load_application, parse_application_string

COMPONENTS = """
  <components>
    <component><task>A</task></component>
    <component><task>B</task></component>
  </components>"""
"""Two components, on lines 3 and 4 of a file whose first line is <package>."""


def errors_of(text: str, **kwargs) -> list[tuple[int | None, str]]:
    with pytest.raises(ConfigErrors) as raised:
        parse_application_string(text, **kwargs)
    return [(e.location.line if e.location else None, e.message) for e in raised.value.errors]


def only_error(text: str, **kwargs) -> tuple[int | None, str]:
    (error,) = errors_of(text, **kwargs)
    return error


def test_errors_carry_file_and_line_and_are_reported_together():
    with pytest.raises(ConfigErrors) as raised:
        parse_application_string(
            # on_error (an extension) puts the file in this project's dialect: unknown elements are errors
            '<package on_error="continue">\n<bogus/>\n<components>\n<component/>\n</components>\n</package>',
            filename="app.xml",
        )
    assert [(str(e.location), e.message) for e in raised.value.errors] == [
        (
            "app.xml:2",
            "unexpected element <bogus> in <package>; expected one of: activities, arg, "
            "components, connections, includes, log, logconfig, paths, ports, resourcespaths, topics, transforms",
        ),
        ("app.xml:4", "<component> needs a <task>: the name the component is registered under"),
    ]
    assert "2 errors in the application" in str(raised.value)
    assert "app.xml:4: <component> needs a <task>" in str(raised.value)


def test_syntax_error_has_the_line_of_the_fault():
    line, message = only_error("<package>\n  <components>\n  </component>\n</package>")
    assert line == 3
    assert message.startswith("XML syntax error: mismatched tag")


def test_unreadable_file_is_a_single_error(tmp_path):
    with pytest.raises(ConfigError, match="cannot read application file .*missing.xml"):
        load_application(tmp_path / "missing.xml")


def test_root_must_be_package():
    assert only_error("<application/>") == (1, "the root element is <application>; expected <package>")


def test_unknown_attribute_names_the_expected_ones():
    assert only_error('<package>\n<components>\n<component kind="x"><task>A</task></component>'
                      "\n</components>\n</package>") == (
        3,
        'unexpected attribute kind="x" in <component>; expected one of: if, on_error, unless',
    )


def test_stray_text_and_children_of_text_elements():
    text = ('<package on_error="continue">\n<components>oops\n<component><task>A<b/></task></component>\n'
            '</components>\n</package>')
    assert errors_of(text) == [
        (2, "unexpected text 'oops' in <components>; it contains elements only"),
        (3, "unexpected element <b> in <task>; it contains text only"),
    ]


def test_repeated_singletons():
    text = "<package>\n<components>\n<component><task>A</task>\n<task>B</task></component>\n</components>\n</package>"
    assert only_error(text) == (4, "<component> has more than one <task> (the first is at line 3)")


def test_connection_attribute_values():
    text = f"""<package>{COMPONENTS}
  <connections>
    <connection data="FOO" policy="LOCKD" transport="IPC" buffersize="x" event="maybe">
      <src task="A" port="out"/>
      <dest task="B" port="in"/>
    </connection>
    <connection data="BUFFER">
      <src task="A" port="out"/>
      <dest task="B" port="in"/>
    </connection>
    <connection data="CIRCULAR" buffersize="0"><src task="A" port="out"/></connection>
  </connections>
</package>"""
    assert errors_of(text) == [
        (7, '<connection> attribute data="FOO" is not valid; expected one of: DATA, BUFFER, CIRCULAR, POOL'),
        (7, '<connection> attribute policy="LOCKD" is not valid; expected one of: LOCKED, LOCK_FREE, UNSYNC'),
        (7, '<connection> attribute transport="IPC" is not available in this version; only LOCAL '
            "(components of one process) is"),
        (7, '<connection> attribute buffersize="x": expected an integer'),
        (7, '<connection> attribute event="maybe": expected true/false, 1/0, yes/no or on/off'),
        (11, "a BUFFER connection needs buffersize= (how many values it holds, at least 1)"),
        (15, '<connection> attribute buffersize="0": expected at least 1, or -1 for the default'),
        (15, '<connection> needs a <dest task="..." port="..."/>'),
    ]


def test_buffer_size_defaults_to_one_for_unsized_policies():
    text = f"""<package>{COMPONENTS}
  <connections>
    <connection data="POOL" buffersize="-1"><src task="A" port="o"/><dest task="B" port="i"/></connection>
    <connection><src task="A" port="o"/><dest task="B" port="j"/></connection>
  </connections>
</package>"""
    assert [c.buffersize for c in parse_application_string(text).connections] == [1, 1]


def test_unknown_components_in_connections_suggest_a_name():
    text = f"""<package>{COMPONENTS}
  <connections>
    <connection>
      <src task="AA" port="out"/>
      <dest task="Zed" port="in"/>
    </connection>
  </connections>
</package>"""
    assert errors_of(text) == [
        (8, "<src task=\"AA\"> is not a defined component; did you mean 'A'? valid: A, B"),
        (9, '<dest task="Zed"> is not a defined component; valid: A, B'),
    ]


def test_peers_can_be_connected_but_not_scheduled():
    text = """<package>
  <components>
    <component><task>Owner</task>
      <components><component><task>Peer</task></component></components>
    </component>
  </components>
  <connections>
    <connection><src task="Owner" port="o"/><dest task="Peer" port="i"/></connection>
  </connections>
  <activities>
    <activity>
      <schedule/>
      <components><component name="Owner"/><component name="Peer"/></components>
    </activity>
  </activities>
</package>"""
    assert only_error(text) == (
        13,
        "component 'Peer' is a peer of 'Owner': peers are run by their owner and cannot be scheduled",
    )


def test_duplicate_instance_names_across_peers_name_both_places():
    text = """<package>
  <components>
    <component><task>A</task>
      <components><component><name>B</name><task>X</task></component></components>
    </component>
    <component><task>B</task></component>
  </components>
</package>"""
    assert only_error(text, filename="dup.xml") == (
        6,
        "component name 'B' is already used at dup.xml:4; instance names must be unique "
        "(give one of them a <name>)",
    )


def test_scheduling_errors():
    text = f"""<package>{COMPONENTS}
  <activities>
    <activity>
      <schedule type="periodic" period="10"/>
      <components><component name="A"/><component name="Bb"/></components>
    </activity>
    <activity name="activity1">
      <schedule/>
      <components><component name="A"/></components>
    </activity>
  </activities>
</package>"""
    assert errors_of(text, filename="s.xml") == [
        (9, "<component name=\"Bb\"> is not a defined component; did you mean 'B'? valid: A, B"),
        (11, "activity name 'activity1' is already used at s.xml:7"),
        (13, "component 'A' is already scheduled in activity 'activity1' at s.xml:9; "
             "a component runs in one activity"),
    ]


def test_schedule_attribute_values():
    text = f"""<package>{COMPONENTS}
  <activities>
    <activity>
      <schedule period="abc" realtime="DEADLINE" nice="40" affinity="1,x" priority="high"/>
      <components/>
    </activity>
    <activity>
      <schedule type="periodic"/>
      <components/>
    </activity>
    <activity>
      <schedule type="periodic" value="-5"/>
      <components/>
    </activity>
    <activity>
      <schedule type="triggered" period="5" activity="serial"/>
      <components/>
    </activity>
    <activity>
      <schedule period="5" value="5"/>
      <components/>
    </activity>
  </activities>
</package>"""
    assert errors_of(text) == [
        (8, '<schedule> attribute period="abc": expected a number of milliseconds'),
        (8, '<schedule> attribute realtime="DEADLINE" is not available from Python (the os module '
            "has no SCHED_DEADLINE); use FIFO or RR"),
        (8, '<schedule> attribute priority="high": expected an integer'),
        (8, '<schedule> attribute nice="40": expected a nice value from -20 (most favourable) to 19'),
        (8, '<schedule> attribute affinity="1,x": expected a core number, a comma-separated list '
            "of core numbers, or -1 for none"),
        (12, '<schedule> type="periodic" needs period= (milliseconds, greater than 0)'),
        (16, '<schedule> attribute value="-5": expected a period greater than 0 milliseconds and at most 86400000 (a day)'),
        (20, '<schedule> attribute activity="serial" is not valid; expected one of: parallel, sequential'),
        (24, "<schedule> has both period= and value=; they are the same setting (milliseconds): give one"),
    ]


def test_schedule_defaults_and_legacy_values():
    text = """<package>
  <activities>
    <activity><schedulepolicy value="2.5" affinity="-1" exclusive_affinity="" priority=""/><components/></activity>
    <activity><schedule type="triggered" period="-1" affinity="3, 1,3"/><components/></activity>
  </activities>
</package>"""
    first, second = (a.schedule for a in parse_application_string(text).activities)
    assert (first.type, first.period_ms, first.affinity, first.exclusive_affinity, first.priority) == (
        "periodic", 2.5, [], [], None)
    assert (second.type, second.period_ms, second.affinity) == ("triggered", None, [3, 1])
    assert (second.activity, second.realtime, second.main, second.nice) == ("parallel", "none", False, None)


def test_spin_is_how_long_a_periodic_thread_spins_before_each_deadline():
    from coco_core.builder import build_application
    from coco_core.schedule import DEFAULT_SPIN

    text = """<package>
  <activities>
    <activity name="fast"><schedule period="1" spin="0.6"/><components/></activity>
    <activity name="plain"><schedule period="1"/><components/></activity>
  </activities>
</package>"""
    spec = parse_application_string(text)
    assert [a.schedule.spin_ms for a in spec.activities] == [0.6, None]
    app = build_application(spec)
    assert app.activity("fast").schedule.spin == pytest.approx(0.6e-3)
    assert app.activity("plain").schedule.spin == DEFAULT_SPIN


def test_a_wrong_spin_is_an_error_with_file_and_line():
    text = """<package>
  <activities>
    <activity><schedule period="1" spin="1"/><components/></activity>
    <activity><schedule period="1" spin="-0.1"/><components/></activity>
    <activity><schedule type="triggered" spin="0.2"/><components/></activity>
    <activity><schedule period="1" spin="soon"/><components/></activity>
  </activities>
</package>"""
    assert errors_of(text) == [
        (3, '<schedule> attribute spin="1": expected milliseconds from 0 to less than the period (1)'),
        (4, '<schedule> attribute spin="-0.1": expected milliseconds from 0 to less than the period (1)'),
        (5, '<schedule> attribute spin="0.2": only a periodic activity spins to its deadlines; leave it out of a '
            "triggered one"),
        (6, '<schedule> attribute spin="soon": expected a number of milliseconds'),
    ]


def test_min_period_bounds_a_triggered_activity_in_either_layout():
    from coco_core.builder import build_application

    text = """<package>
  <activities>
    <activity name="view"><schedule type="triggered" min_period="16"/><components/></activity>
    <activity name="legacy"><schedulepolicy activity="parallel" min_period="2.5"/><components/></activity>
    <activity name="plain"><schedule type="triggered"/><components/></activity>
  </activities>
</package>"""
    spec = parse_application_string(text)
    assert [a.schedule.min_period_ms for a in spec.activities] == [16.0, 2.5, 0.0]
    app = build_application(spec)
    assert [app.activity(name).schedule.min_period for name in ("view", "legacy", "plain")] == pytest.approx(
        [0.016, 0.0025, 0.0])
    assert app.activity("view").describe() == "triggered, at most every 16 ms"
    assert app.activity("plain").describe() == "triggered"


def test_a_wrong_min_period_is_an_error_with_file_and_line():
    text = """<package>
  <activities>
    <activity><schedule period="10" min_period="16"/><components/></activity>
    <activity><schedule type="triggered" min_period="-1"/><components/></activity>
    <activity><schedule type="triggered" min_period="soon"/><components/></activity>
    <activity><schedulepolicy type="periodic" value="5" min_period="1"/><components/></activity>
    <activity><schedule type="triggered" min_period="1e9"/><components/></activity>
  </activities>
</package>"""
    periodic = ("only a triggered activity has a minimum period (a periodic one cycles every period); leave it "
                'out, or make the activity type="triggered"')
    assert errors_of(text) == [
        (3, f'<schedule> attribute min_period="16": {periodic}'),
        (4, '<schedule> attribute min_period="-1": expected milliseconds from 0 (no bound) to 86400000 (a day)'),
        (5, '<schedule> attribute min_period="soon": expected a number of milliseconds'),
        (6, f'<schedulepolicy> attribute min_period="1": {periodic}'),
        (7, '<schedule> attribute min_period="1e9": expected milliseconds from 0 (no bound) to 86400000 (a day)'),
    ]


def test_activity_structure():
    text = """<package>
  <activities>
    <activity><components/></activity>
    <activity><schedule/><schedulepolicy/></activity>
    <farm/>
  </activities>
</package>"""
    assert errors_of(text) == [
        (3, "<activity> needs a <schedule> (<schedulepolicy> in the per-activity layout)"),
        (4, "<activity> has more than one schedule (the first is at line 4)"),
        (4, "<activity> needs <components>: the components it runs"),
        (5, '<farm> needs a <schedule workers="N"/>: how many copies of the pipeline run'),
        (5, "<farm> needs a <source>: the component that feeds the workers"),
        (5, "<farm> needs a <pipeline>: what each worker runs"),
        (5, "<farm> needs a <gather>: the component that collects the workers' results"),
    ]


def test_only_one_main_activity():
    text = f"""<package>{COMPONENTS}
  <activities>
    <activity name="gui"><schedule main="true"/><components><component name="A"/></components></activity>
    <activity name="other">
      <schedule main="on"/>
      <components><component name="B"/></components>
    </activity>
  </activities>
</package>"""
    assert only_error(text, filename="m.xml") == (
        9,
        "activity 'other' asks for the main thread, which activity 'gui' at m.xml:7 already has; only one can",
    )


def test_legacy_definition_and_reference_to_it_from_another_activity():
    text = """<package>
  <activities>
    <activity><schedulepolicy/><components><component><task>A</task></component></components></activity>
    <activity><schedulepolicy/><components><component name="A"/></components></activity>
  </activities>
</package>"""
    assert only_error(text, filename="l.xml") == (
        4,
        "component 'A' is already scheduled in activity 'activity1' at l.xml:3; a component runs in one activity",
    )


def test_component_and_attribute_errors():
    text = """<package>
  <components>
    <component on_error="explode">
      <task></task>
      <name>n</name>
      <attributes>
        <attribute name="a" value="1"/>
        <attribute name="a" value="2"/>
        <attribute value="3"/>
        <attribute name="b" type="dir"/>
      </attributes>
    </component>
  </components>
</package>"""
    assert errors_of(text) == [
        (3, '<component> attribute on_error="explode" is not valid; expected one of: continue, '
            "stop_component, stop_app"),
        (4, "<task> is empty; it names the component to instantiate"),
        (8, "attribute 'a' is set twice (the first is at line 7)"),
        (9, "<attribute> needs a name= attribute"),
        (10, '<attribute> attribute type="dir" is not valid; expected "file" (a file searched in the '
             "resource paths) or nothing (plain text)"),
    ]


def test_log_errors():
    text = """<package>
  <log><levels>0 x</levels><types>debug warn</types></log>
  <logconfig/>
</package>"""
    assert errors_of(text, filename="g.xml") == [
        (2, "<levels> 'x' is not valid; expected numbers separated by spaces"),
        (2, "<types> 'warn' is not valid; expected words among: debug, err, log"),
        (3, "<logconfig> is given a second time (the first is at g.xml:2); an application has one "
            "log configuration"),
    ]


def test_package_attributes():
    app = parse_application_string('<package name="demo" on_error="stop_component"/>')
    assert (app.name, app.on_error, app.file) == ("demo", "stop_component", "<string>")
    assert parse_application_string("<package/>", filename="dir/my_app.xml").name == "my_app"
    schema_hint = (
        '<package xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
        'xsi:noNamespaceSchemaLocation="coco.xsd"/>'
    )
    assert parse_application_string(schema_hint).components == []
    assert errors_of('<package xmlns:coco="urn:coco" coco:name="x"/>') == [
        (1, 'unexpected attribute coco:name="x" in <package>; expected one of: name, on_error'),
    ]
