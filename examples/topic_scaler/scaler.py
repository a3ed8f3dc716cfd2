"""A component of your own between two ROS topics: it scales every number it receives.

The component knows nothing of ROS: it reads floats from an input port and writes floats to an
output port. The application file (scaler.xml) connects those ports to topics through a
ROSInterface, and says which activity runs it. See docs/ros.md, "Your own component between two
topics".
"""

from __future__ import annotations

from coco_core import Attribute, Component, InputPort, OutputPort, operation


class Scaler(Component):
    gain = Attribute(float, 2.0, "factor applied to every value")
    value = InputPort(float, event=True, doc="numbers to scale; each arrival wakes a triggered activity")
    scaled = OutputPort(float, "gain * value, one per value received")

    def on_update(self) -> None:
        for value in self.value.read_all():
            self.scaled.write(self.gain * value)

    @operation
    def set_gain(self, gain: float) -> float:
        """Change the gain while the application runs; returns the previous one."""
        previous, self.gain = self.gain, gain
        return previous
