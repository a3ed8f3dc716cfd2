"""Exception isolation: a component that raises is reported, counted, and handled by the error policy."""

from __future__ import annotations

import logging
import threading
import time

import pytest

from coco_core import Component, ErrorPolicy, PeriodicActivity, TriggeredActivity
from coco_core.launcher import stopped_by_a_failure


class Faulty(Component):
    """Raises in every ``on_update``."""

    def init(self):
        self.calls = 0
        self.stopped = threading.Event()

    def on_update(self):
        self.calls += 1
        raise RuntimeError(f"sensor unplugged #{self.calls}")

    def on_stop(self):
        self.stopped.set()


class Healthy(Component):
    def init(self):
        self.calls = 0
        self.stopped = threading.Event()
        self.configured_event = threading.Event()

    def on_config(self):
        self.configured_event.set()

    def on_update(self):
        self.calls += 1

    def on_stop(self):
        self.stopped.set()


def coco_errors(caplog):
    return [record for record in caplog.records if record.name == "coco" and record.levelno >= logging.ERROR]


def rig(make_app, app_policy=ErrorPolicy.CONTINUE, component_policy=None):
    app = make_app("errors", on_error=app_policy)
    activity = PeriodicActivity("periodic", 0.005)
    faulty = app.add(Faulty("faulty"), activity)
    healthy = app.add(Healthy("healthy"), activity)
    faulty.on_error = component_policy
    return app, faulty, healthy


def test_continue_reports_counts_and_keeps_calling(make_app, wait_until, caplog):
    caplog.set_level(logging.ERROR, logger="coco")
    app, faulty, healthy = rig(make_app)
    app.start()
    assert wait_until(lambda: faulty.calls >= 6 and healthy.calls >= 6)
    assert app.stop()
    assert faulty.stats.errors == faulty.calls, "every raise is counted"
    assert healthy.stats.errors == 0
    assert faulty.enabled
    assert healthy.calls >= faulty.calls - 1, "the activity goes on with the others"
    assert app.activity("periodic").finished
    records = coco_errors(caplog)
    first = records[0].getMessage()
    assert "faulty" in first and "on_update" in first
    assert "Traceback" in first and "RuntimeError: sensor unplugged #1" in first
    assert "test_runtime_errors.py" in first, "the traceback points at the component's code"
    # Flooding is avoided: full tracebacks for the first few errors only.
    assert sum("Traceback" in r.getMessage() for r in records) <= 3
    assert all("healthy" not in r.getMessage() for r in records)


def test_stop_component_disables_only_the_faulty_one(make_app, wait_until, caplog):
    caplog.set_level(logging.ERROR, logger="coco")
    app, faulty, healthy = rig(make_app, component_policy=ErrorPolicy.STOP_COMPONENT)
    app.start()
    assert wait_until(lambda: healthy.calls >= 10)
    assert app.stop()
    assert faulty.calls == 1 and faulty.stats.errors == 1
    assert not faulty.enabled and healthy.enabled
    assert faulty.stopped.is_set() and healthy.stopped.is_set(), "a stopped component still gets on_stop"
    messages = [r.getMessage() for r in coco_errors(caplog)]
    assert any("faulty" in m and "Traceback" in m for m in messages)
    assert any("faulty" in m and "stopped" in m for m in messages)


def test_application_policy_applies_when_the_component_has_none(make_app, wait_until):
    app, faulty, healthy = rig(make_app, app_policy=ErrorPolicy.STOP_COMPONENT)
    app.start()
    assert wait_until(lambda: healthy.calls >= 5)
    assert faulty.calls == 1 and not faulty.enabled


def test_component_policy_overrides_the_applications(make_app, wait_until):
    app, faulty, healthy = rig(make_app, app_policy=ErrorPolicy.STOP_APP,
                               component_policy=ErrorPolicy.CONTINUE)
    app.start()
    assert wait_until(lambda: faulty.calls >= 5)
    assert not app.stop_requested and faulty.enabled


def test_stop_app_stops_everything_cleanly(make_app, caplog):
    caplog.set_level(logging.INFO, logger="coco")
    app = make_app("stop-app")
    other = app.add(Healthy("other"), TriggeredActivity("triggered"))

    class FaultyOnceAllRun(Faulty):
        """Raises only once the other activity configured its component: a stop requested before
        that would rightly skip the other's on_config and so its on_stop too."""

        def on_update(self):
            other.configured_event.wait(5.0)
            super().on_update()

    faulty = app.add(FaultyOnceAllRun("faulty"), PeriodicActivity("periodic", 0.01))
    faulty.on_error = ErrorPolicy.STOP_APP
    t0 = time.monotonic()
    app.run(duration=10.0)
    assert time.monotonic() - t0 < 2.0, "the error stopped the application long before its duration"
    assert faulty.calls == 1
    assert "faulty" in app.stop_reason
    assert faulty.stopped.is_set() and other.stopped.is_set()
    assert all(activity.finished for activity in app.activities.values())
    assert any("Traceback" in r.getMessage() for r in coco_errors(caplog))


def test_errors_in_on_config_and_on_stop_are_reported_not_raised(make_app, wait_until, caplog):
    class BadConfig(Healthy):
        def on_config(self):
            raise OSError("no device")

    class BadStop(Healthy):
        def on_stop(self):
            super().on_stop()
            raise OSError("flush failed")

    caplog.set_level(logging.ERROR, logger="coco")
    app = make_app("phases", on_error=ErrorPolicy.CONTINUE)  # given: the application goes on without it
    activity = PeriodicActivity("periodic", 0.005)
    bad_config = app.add(BadConfig("bad_config"), activity)
    bad_stop = app.add(BadStop("bad_stop"), activity)
    app.start()
    assert wait_until(lambda: bad_stop.calls >= 3)
    assert app.stop()
    assert bad_config.calls == 0, "a component that failed to configure is not updated"
    assert bad_config.stats.errors == 1 and bad_stop.stats.errors == 1
    messages = [r.getMessage() for r in coco_errors(caplog)]
    assert any("bad_config" in m and "on_config" in m and "no device" in m for m in messages)
    assert any("bad_stop" in m and "on_stop" in m and "flush failed" in m for m in messages)


class RefusesItsConfiguration(Healthy):
    def on_config(self):
        raise OSError("no trajectory")


def test_a_refused_configuration_stops_an_application_given_no_policy(make_app):
    """A component that cannot configure never runs: the application must not run on as if it were
    sound (a haptic device without its trajectory ran until killed), so it stops, as a failure (the
    launchers then exit 1)."""
    app = make_app("refused")
    refused = app.add(RefusesItsConfiguration("device"), PeriodicActivity("periodic", 0.005))
    other = app.add(Healthy("other"), TriggeredActivity("triggered"))
    t0 = time.monotonic()
    app.run(duration=10.0)
    assert time.monotonic() - t0 < 5.0, "the refused configuration stopped the application"
    assert app.stop_reason == "component device raised in on_config"
    assert refused.calls == 0 and other.calls == 0
    assert stopped_by_a_failure(app)


@pytest.mark.parametrize("policy", [ErrorPolicy.CONTINUE, ErrorPolicy.STOP_COMPONENT])
@pytest.mark.parametrize("given_to", ["application", "component"])
def test_a_policy_given_lets_the_application_run_on_without_the_refused_component(make_app, wait_until, policy,
                                                                                  given_to):
    app = make_app("refused", on_error=policy if given_to == "application" else None)
    activity = PeriodicActivity("periodic", 0.005)
    refused = app.add(RefusesItsConfiguration("device"), activity)
    healthy = app.add(Healthy("healthy"), activity)
    if given_to == "component":
        refused.on_error = policy
    app.start()
    assert wait_until(lambda: healthy.calls >= 5)
    assert not app.stop_requested and not refused.enabled and refused.calls == 0


def test_error_in_a_peer_is_isolated_from_its_owner(make_app, wait_until, caplog):
    caplog.set_level(logging.ERROR, logger="coco")
    app = make_app("peer-error")
    owner = Healthy("owner")
    faulty = owner.add_peer(Faulty("faulty_peer"))
    sibling = owner.add_peer(Healthy("sibling"))
    app.add(owner, PeriodicActivity("periodic", 0.005))
    app.start()
    assert wait_until(lambda: sibling.calls >= 5)
    assert app.stop()
    assert faulty.stats.errors == faulty.calls >= 5
    assert owner.stats.errors == 0 and sibling.stats.errors == 0
    assert any("faulty_peer" in r.getMessage() for r in coco_errors(caplog))


def test_many_errors_keep_being_counted_with_a_standalone_component():
    faulty = Faulty("standalone")
    faulty.init()
    for _ in range(50):
        faulty.step()  # no application, no activity: the default policy is continue
    assert faulty.calls == 50 and faulty.stats.errors == 50
    assert faulty.stats.executions == 50
    assert faulty.enabled


@pytest.mark.parametrize("policy", list(ErrorPolicy))
def test_every_policy_reports_with_name_and_traceback(make_app, wait_until, caplog, policy):
    caplog.set_level(logging.ERROR, logger="coco")
    app, faulty, healthy = rig(make_app, component_policy=policy)
    app.start()
    assert wait_until(lambda: faulty.stats.errors >= 1)
    assert wait_until(lambda: any("Traceback" in r.getMessage() for r in coco_errors(caplog)))
    message = next(r.getMessage() for r in coco_errors(caplog) if "Traceback" in r.getMessage())
    assert "component faulty raised in on_update" in message
    assert "RuntimeError: sensor unplugged #1" in message
    assert app.stop() is True
