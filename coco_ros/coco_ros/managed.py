"""The launcher as a managed (lifecycle) node: ``launcher app.xml --managed``.

ROS 2's managed nodes let a system (a launch file's lifecycle events, ``ros2 lifecycle set``, nav2's
lifecycle manager) bring many nodes up in step: configure all, then activate all. CoCo already has
that rule inside an application (:mod:`coco_core.lifecycle`: configure every activity of every
process, then start them all); with ``--managed`` the lifecycle transitions drive it:

=============  ==================================================================================
transition     what the application does
=============  ==================================================================================
configure      every activity of every process starts and configures its components (``on_config``,
               in its own thread); the transition ends once all have, and nothing cycles yet
activate       the start gate opens: every activity runs (``--duration`` counts from the first);
               after a deactivate, the activities run again where they were held
deactivate     every activity of every process holds its cycles (``Application.pause``): threads,
               timers and configuration stay, what is written meanwhile waits in the connections
               (a buffer keeps its ``buffersize`` newest), operations are still served
cleanup,       a natural stop: every activity finishes its work and flushes, then the launcher ends
shutdown       (an application runs once: a stopped one cannot be configured again; start the
               launcher again for that)
=============  ==================================================================================

Without ``--managed`` the launcher configures and activates at once, as before. The built
application, its child processes and the node exist from the start (state *unconfigured*), so the
node's parameters and services answer before ``configure``. A configure that fails (a component's
``on_config`` raising under ``on_error="stop_app"``, a signal) answers FAILURE and the launcher
stops. Managed hosting needs the default wait sets: with ``--executor-threads`` the activities
would configure in the executor that serves the very transition waiting for them.

A transition that is not valid from the current state (configure twice, activate before
configure, configure while active) is refused: the service answers ``success=False``, the log says
which transitions are valid, and the application goes on as it was. rclpy 7.1.6 (the version on
the package index) raises from its service callback instead, which ended the executor's spin and
stopped the application; :class:`ManagedLauncherNode` checks the transition before handing it over.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from coco_core import Application
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

log = logging.getLogger("coco")


class ManagedApplication:
    """What the lifecycle transitions do to ``app`` (hosted by ``host``): see the module docstring."""

    def __init__(self, app: Application, host: Any) -> None:
        self.app = app
        self.host = host
        self.started = threading.Event()
        """Set by configure once the activities started: the main thread may run the main activity."""
        self._configured = threading.Event()

    def configure(self) -> bool:
        """Start every activity with the gate held; True once all configured, False on a stop."""
        if self.started.is_set() or self.app.stop_requested:
            log.error("configure: application %s %s", self.app.name,
                      "was configured already (it runs once)" if self.started.is_set() else "is stopping")
            return False
        self.app.gate.hold(self._configured.set)  # all configured: tell this object, do not open
        self.app.start()
        self.host.start()
        self.started.set()
        if not self._until(self._configured):
            return False
        log.info("application %s configured (every activity of every process): waiting for activate", self.app.name)
        return True

    def wait_started(self) -> bool:
        """Wait (the launcher's main thread, the main activity's) until configure started the
        application; False when a stop came first."""
        return self._until(self.started)

    def _until(self, event: threading.Event) -> bool:
        """Wait for ``event``, or a stop of the application (then False)."""
        while not event.wait(0.1):
            if self.app.stop_requested:
                return False
        return True

    def activate(self) -> bool:
        """Run every activity: the first time, open the start gate; after a deactivate, resume."""
        if not self._configured.is_set() or self.app.stop_requested:
            log.error("activate: application %s %s", self.app.name,
                      "is stopping or stopped (it runs once: start the launcher again)" if self.app.stop_requested
                      else "is not configured")
            return False
        if self.app.gate.is_open:
            self.app.pause(False)
            log.info("application %s active again", self.app.name)
        else:
            self.app.gate.open()
        return True

    def deactivate(self) -> bool:
        """Hold every activity's cycles until the next activate (see the module)."""
        self.app.pause(True)
        log.info("application %s inactive: every activity holds its cycles until activate", self.app.name)
        return True

    def end(self, transition: str) -> bool:
        """cleanup, shutdown: a natural stop (every activity flushes), then the launcher ends."""
        self.app.request_stop(f"lifecycle transition {transition}")
        return True


class ManagedLauncherNode(LifecycleNode):
    """The launcher's node with the lifecycle services; :attr:`managed` (set once the application is
    built) does what each transition asks."""

    def __init__(self, name: str, **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.managed: ManagedApplication | None = None

    def valid_transitions(self) -> dict[int, str]:
        """The transitions valid from the current state: label by id (what ``ros2 lifecycle list`` shows)."""
        return {transition[0]: transition[1] for transition in self._state_machine.available_transitions}

    def _LifecycleNodeMixin__on_change_state(self, request: ChangeState.Request,
                                             response: ChangeState.Response) -> ChangeState.Response:
        """The change_state service (rclpy's callback, by its mangled name): a transition that is
        not valid from the current state is refused with the valid ones named; a valid one goes to
        rclpy's state machine (its ``trigger_*``: the three shutdown transitions are the only others). rclpy 7.1.6's own callback raised for an invalid one (rcl's
        "Transition is not registered"), out of the executor's spin, which stopped the application."""
        wanted = request.transition
        valid = self.valid_transitions()
        by_label = {label: id for id, label in valid.items()}
        transition = by_label.get(wanted.label) if wanted.label else (wanted.id if wanted.id in valid else None)
        if transition is None:
            state = self._state_machine.current_state[1]
            log.error("lifecycle transition %s refused: not valid from state %s; valid: %s",
                      wanted.label or wanted.id, state, ", ".join(f"{label} ({id})" for id, label in valid.items()))
            response.success = False
            return response
        trigger = {Transition.TRANSITION_CONFIGURE: self.trigger_configure,
                   Transition.TRANSITION_CLEANUP: self.trigger_cleanup,
                   Transition.TRANSITION_ACTIVATE: self.trigger_activate,
                   Transition.TRANSITION_DEACTIVATE: self.trigger_deactivate}.get(transition, self.trigger_shutdown)
        response.success = trigger() == TransitionCallbackReturn.SUCCESS
        return response

    def _answer(self, done: bool) -> TransitionCallbackReturn:
        return TransitionCallbackReturn.SUCCESS if done else TransitionCallbackReturn.FAILURE

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._answer(self.managed is not None and self.managed.configure())

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._answer(self.managed is not None and self.managed.activate())

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._answer(self.managed is not None and self.managed.deactivate())

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._answer(self.managed is not None and self.managed.end("cleanup"))

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._answer(self.managed is not None and self.managed.end("shutdown"))

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self.managed is not None:
            self.managed.app.request_stop("lifecycle error", hard=True)
        return TransitionCallbackReturn.SUCCESS
