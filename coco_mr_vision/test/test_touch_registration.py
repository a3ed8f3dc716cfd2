"""TouchRegistration on hand poses it cannot use (its calibration on a real session is tested with
the palpation session, coco_ros/test/test_palpation_session.py)."""

from __future__ import annotations

import numpy as np

from coco_core.application import Application
from coco_core.component import Component
from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_core.ports import OutputPort
from coco_core.transforms import se3
from coco_core.transforms.samples import FramePose
from coco_mr_vision.touch_registration import TouchRegistration


class Hand(Component):
    hand = OutputPort(object)


def test_a_hand_pose_with_nan_is_refused_and_counted_not_kept():
    """A tracker that lost the hand (NaN) gives no rest to match a detection with: the pose is left
    out and counted in the profile's refused column, not dropped silently."""
    app = Application("touch")
    source = app.add(Hand("source"))
    registration = app.add(TouchRegistration("registration", marker_id=7))
    app.connect("source.hand", "registration.hand", ConnectionPolicy(BufferPolicy.BUFFER, size=10))
    registration.configure()
    for i, x in enumerate((0.1, np.nan, 0.1)):
        source.hand.write(FramePose("hand_tracker", "hand", se3.make(np.eye(3), (x, 0.0, 0.5)), 10.0 + 0.01 * i))
    registration.step()
    assert registration.stats.refused == 1
