"""Shared fixtures of the runtime tests: applications that are always stopped, and polling."""

from __future__ import annotations

import time
from typing import Callable

import pytest

from coco_core import Application


@pytest.fixture
def make_app():
    """A factory of :class:`Application` objects, every one of them stopped at teardown.

    A test that fails half-way must not leave activity threads running into the next test.
    """
    apps: list[Application] = []

    def make(name: str = "test", **options) -> Application:
        app = Application(name, **options)
        apps.append(app)
        return app

    yield make
    for app in apps:
        app.stop()


@pytest.fixture
def wait_until() -> Callable[..., bool]:
    """``wait_until(predicate, timeout=2.0)``: poll until ``predicate()`` is true; return whether it was."""

    def wait(predicate: Callable[[], object], timeout: float = 2.0, interval: float = 0.002) -> bool:
        deadline = time.monotonic() + timeout
        while True:
            if predicate():
                return True
            if time.monotonic() >= deadline:
                return bool(predicate())
            time.sleep(interval)

    return wait
