"""``<topics>``: output ports the ROS launcher mirrors on topics, read into ``AppSpec.topics``."""

from __future__ import annotations

import pytest
from coco_core.errors import ConfigErrors
from coco_core.model import TopicMirrorSpec
from coco_core.policy import BufferPolicy
from coco_core.xml import parse_application_string

HEAD = '<package on_error="continue">\n<arg name="ros" default="true"/>\n'


def test_topics_are_read_with_their_policy_type_and_conditions() -> None:
    spec = parse_application_string(HEAD + """<topics if="$(arg ros)">
<topic task="distance" port="distance"/>
<topic task="distance" port="color" name="/bowl_color" type="std_msgs/msg/ColorRGBA" data="BUFFER" buffersize="16"/>
<topic task="tf" port="gripper" unless="$(arg ros)"/>
<topic task="renderer" port="proxy" frame="camera" hz="30"/>
</topics>
<topics unless="$(arg ros)"><topic task="x" port="y"/></topics>
</package>""", filename="app.xml")
    assert [(t.component, t.port, t.topic, t.type, t.data, t.buffersize) for t in spec.topics] == [
        ("distance", "distance", "", "", BufferPolicy.DATA, 1),
        ("distance", "color", "/bowl_color", "std_msgs/msg/ColorRGBA", BufferPolicy.BUFFER, 16),
        ("renderer", "proxy", "", "", BufferPolicy.DATA, 1),
    ]
    assert (spec.topics[2].frame, spec.topics[2].hz) == ("camera", 30.0)
    assert isinstance(spec.topics[0], TopicMirrorSpec) and str(spec.topics[0].location) == "app.xml:4"


@pytest.mark.parametrize("topic, message", [
    ('<topic task="distance"/>', "<topic> needs a port= attribute"),
    ('<topic task="distance" port="distance" data="BUFFER"/>', "a BUFFER connection needs buffersize="),
    ('<topic task="distance" port="distance" data="POOLED"/>', 'attribute data="POOLED" is not valid'),
    ('<topic task="distance" port="distance" rate="5"/>', "rate"),
    ('<topic task="distance" port="distance" hz="-1"/>', "expected a rate >= 0"),
    ('<topic task="distance" port="distance" hz="fast"/>', 'attribute hz="fast": expected a number'),
])
def test_a_wrong_topic_is_an_error_with_its_line(topic: str, message: str) -> None:
    with pytest.raises(ConfigErrors) as raised:
        parse_application_string(HEAD + f"<topics>\n{topic}\n</topics>\n</package>", filename="app.xml")
    assert [str(e.location) for e in raised.value.errors] == ["app.xml:4"]
    assert message in raised.value.errors[0].message
