"""A component that lingers at one stage of a launch, for the signal tests (``test_signals.py``).

It says on the log when it reaches that stage (``stage NAME: building``, ``configuring``,
``running``, ``stopping``) and then takes ``seconds`` there, so that a test sends its signals at
that stage, not after a guessed delay. The launchers import it by ``signal_stages:Stage`` (this
folder is on their PYTHONPATH), in the launcher's process and in a child process alike.
"""

from __future__ import annotations

import logging
import time

from coco_core import Attribute, Component

log = logging.getLogger("coco")


class Stage(Component):
    """Lingers ``seconds`` at the stage ``linger`` names (nothing: none); says when it is there."""

    linger = Attribute(str, "", "building, configuring, running or stopping")
    seconds = Attribute(float, 0.6, "how long it stays at that stage (a hard stop waits a second at most)")

    def _at(self, stage: str) -> None:
        log.info("stage %s: %s", self.name, stage)
        if self.linger == stage:
            time.sleep(self.seconds)

    def init(self) -> None:
        self._at("building")
        self.ran = False

    def on_config(self) -> None:
        self._at("configuring")

    def on_update(self) -> None:
        if not self.ran:
            self.ran = True
            self._at("running")

    def on_stop(self) -> None:
        self._at("stopping")
