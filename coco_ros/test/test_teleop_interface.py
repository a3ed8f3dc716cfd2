"""TransformationInterface accepts FramePose values on its ``transform`` input (target=parent, source=child)."""

from __future__ import annotations

import time

import numpy as np
from coco_core.activity import TriggeredActivity
from coco_core.application import Application
from coco_core.component import Component
from coco_core.ports import OutputPort
from coco_core.transforms.interface import TransformationInterface
from coco_core.transforms.samples import FramePose


class Source(Component):
    out = OutputPort(object)


def test_frame_pose_becomes_an_edge_and_unnamed_one_is_ignored():
    app = Application("fp")
    source = app.add(Source("source"))
    tf = app.add(TransformationInterface("tf", publish=["bowl=base:bowl"]), TriggeredActivity("tf"))
    app.connect("source.out", "tf.transform")
    T = np.eye(4)
    T[:3, 3] = (0.7, 0.2, -0.15)
    app.start()
    try:
        source.out.write(FramePose("base", "", np.eye(4), 1.0))  # no child frame: logged, ignored
        source.out.write(FramePose("base", "bowl", T, 2.0))
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and "bowl" not in app.transforms.frames:
            time.sleep(0.01)
        np.testing.assert_allclose(app.transforms.lookup("base", "bowl"), T)
        assert "" not in app.transforms.frames
    finally:
        app.stop()
