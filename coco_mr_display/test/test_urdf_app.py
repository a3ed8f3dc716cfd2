"""The mesh peers in an application file, run by their activities: Baxter from the file's ``<urdf>``
(loaded in the background while the display already runs), a bowl attached to a graph frame and
coloured by an UpdateColor peer from a distance written by another activity, rendered by a GLManager
whose frames a triggered sink receives."""

from __future__ import annotations

import time

import numpy as np
import pytest

from coco_core.builder import build_application
from coco_core.component import Component
from coco_core.ports import InputPort, OutputPort
from coco_core.registry import register
from coco_core.stamps import Stamped
from coco_core.transforms.resources import ResourceNotFoundError, resolve
from coco_core.xml import parse_application_string

BAXTER = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"

APP = f"""<package>
  <transforms>
    <urdf file="{BAXTER}"/>
    <static parent="base" child="bowl" xyz="0.9 0.0 0.05"/>
  </transforms>
  <components>
    <component>
      <name>display</name><task>GLManager</task><library>coco_mr_display</library>
      <attributes>
        <attribute name="width" value="200"/><attribute name="height" value="150"/>
        <attribute name="world" value="base"/>
      </attributes>
      <components>
        <component>
          <name>camera</name><task>GLCameraManager</task><library>coco_mr_display</library>
          <attributes>
            <attribute name="position" value="2.5 0.0 0.6"/><attribute name="look_at" value="0 0 0.2"/>
          </attributes>
        </component>
        <component>
          <name>baxter</name><task>GLUrdf</task><library>coco_mr_display</library>
          <attributes>
            <attribute name="colors" value="left_upper_shoulder=0 1 0, right_upper_shoulder=0 1 0"/>
            <attribute name="simplify" value="0.25"/>
          </attributes>
        </component>
        <component>
          <name>bowl</name><task>GLEntity</task><library>coco_mr_display</library>
          <attributes>
            <attribute name="mesh" value="sphere"/><attribute name="size" value="0.12"/>
            <attribute name="frame" value="bowl"/>
            <attribute name="ambient" value="1"/><attribute name="diffuse" value="0"/>
            <attribute name="specular" value="0"/>
          </attributes>
          <components>
            <component>
              <name>bowl_color</name><task>UpdateColor</task><library>coco_mr_display</library>
              <attributes><attribute name="min" value="0.02"/><attribute name="max" value="0.5"/></attributes>
            </component>
          </components>
        </component>
      </components>
    </component>
    <component><name>distance</name><task>MeshTestDistance</task></component>
    <component><name>frames</name><task>MeshTestFrames</task></component>
  </components>
  <connections>
    <connection><src task="distance" port="distance"/><dest task="bowl_color" port="value"/></connection>
    <connection data="BUFFER" buffersize="200">
      <src task="display" port="color"/><dest task="frames" port="image"/>
    </connection>
  </connections>
  <activities>
    <activity name="render"><schedule type="periodic" period="50"/>
      <components><component name="display"/></components></activity>
    <activity name="teleop"><schedule type="periodic" period="50"/>
      <components><component name="distance"/></components></activity>
    <activity name="sink"><schedule type="triggered"/>
      <components><component name="frames"/></components></activity>
  </activities>
</package>"""


@register("MeshTestDistance")
class MeshTestDistance(Component):
    """Writes a bowl distance of 0.5 m (red) every activation, stamped like EndEffectorDistance's."""

    distance = OutputPort(Stamped[float])

    def on_update(self) -> None:
        self.distance.write(Stamped(0.5))


@register("MeshTestFrames")
class MeshTestFrames(Component):
    """Keeps the last rendered frame that shows the robot (its green shoulders)."""

    image = InputPort(object, event=True)

    def init(self) -> None:
        self.received = 0
        self.robot_frame: np.ndarray | None = None
        self.before_robot = 0
        """Frames rendered while Baxter's meshes were still being read."""

    def on_update(self) -> None:
        for image in self.image.read_all():
            self.received += 1
            r, g, b = (image.data[..., channel].astype(int) for channel in range(3))
            if self.robot_frame is None and ((g > 100) & (r < 30) & (b < 30)).sum() > 20:
                self.robot_frame = image.data
                self.before_robot = self.received - 1


def test_display_application_from_a_file(monkeypatch):
    pytest.importorskip("collada", reason="Baxter's meshes are DAE files, read through pycollada")
    pytest.importorskip("pinocchio", reason="the graph computes Baxter's kinematics with Pinocchio")
    try:
        resolve(BAXTER)
    except ResourceNotFoundError as error:
        pytest.skip(f"example-robot-data is not installed: {error}")
    # The display must render while the loader thread reads the meshes: the files themselves, not parts
    # kept by an earlier peer of this process or by another process (COCO_MESH_CACHE, which the test
    # command sets), which are there at once.
    from coco_mr_display import mesh_cache, urdf

    monkeypatch.delenv(mesh_cache.ENVIRONMENT, raising=False)
    monkeypatch.setattr(urdf, "_LOADED", urdf.LoadedParts())
    app = build_application(parse_application_string(APP, "display_meshes.xml"))
    frames = app.component("frames")
    app.start()
    try:
        deadline = time.monotonic() + 60.0
        while frames.robot_frame is None and time.monotonic() < deadline and not app.stop_requested:
            time.sleep(0.1)
    finally:
        app.stop()
    assert frames.robot_frame is not None, f"no frame showed the robot ({frames.received} frames received)"
    assert frames.before_robot >= 1, "the display kept rendering while the meshes were read"
    for name in ("display", "baxter", "bowl", "bowl_color"):
        assert app.component(name).stats.errors == 0, f"{name} reported errors (see the log)"
    red = np.all(frames.robot_frame == (255, 0, 0), axis=2)
    assert red.sum() > 20, "the bowl is drawn red: 0.5 m through green_yellow_red from 0.02 to 0.5"
