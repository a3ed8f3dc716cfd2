"""Shared setup of the coco_ros tests.

``coco_ros`` builds on the workspace's other packages (``coco_core``, ``coco_mr_vision``...): under
colcon they are installed, but when pytest runs straight from the source tree
(``cd coco_ros && python -m pytest test``) each sibling package that is not importable is put on
the path here.
"""

from __future__ import annotations

import importlib.util
import sys
from typing import Any, Callable, Iterator
from pathlib import Path

_WORKSPACE = Path(__file__).resolve().parents[2]
for _package in sorted(_WORKSPACE.glob("*/package.xml")):
    _name = _package.parent.name
    if (_package.parent / _name / "__init__.py").is_file() and importlib.util.find_spec(_name) is None:
        sys.path.insert(0, str(_package.parent))
# tf2_msgs is built by colcon (vendor/tf2_msgs): only install/ has its Python module.
if importlib.util.find_spec("tf2_msgs") is None:
    for _site in sorted((_WORKSPACE / "install" / "tf2_msgs" / "lib").glob("python3*/site-packages")):
        sys.path.insert(0, str(_site))

SHARED_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
"""Real recordings from public sources (see shared/data/README.md); tests skip when it is absent."""


import pytest  # noqa: E402


@pytest.fixture
def talker_bag() -> Path:
    """The rosbag2-written talker bag folder (metadata.yaml + talker.mcap), or skip."""
    folder = SHARED_DATA / "rosbag2"
    if not (folder / "talker.mcap").is_file() or not (folder / "metadata.yaml").is_file():
        pytest.skip(f"shared test data absent: expected {folder}/talker.mcap and metadata.yaml")
    return folder


def python_lines(call: Callable[[], Any]) -> tuple[Any, int]:
    """(result, number of Python lines executed by ``call``): a per-pixel or per-point loop would run
    at least one line per element, wherever it hides (including rclpy's field checks)."""
    count = 0

    def local(frame, event, arg):
        nonlocal count
        count += event == "line"
        return local

    sys.settrace(lambda frame, event, arg: local)
    try:
        result = call()
    finally:
        sys.settrace(None)
    return result, count


def rclpy_peer(monkeypatch: pytest.MonkeyPatch, domain: str, name: str) -> Iterator[tuple[Any, Any]]:
    """For a fixture: this test's own rclpy node (and its executor) on DDS ``domain``, localhost
    only, as the other side of an application run by the ROS launcher in a subprocess."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    monkeypatch.setenv("ROS_DOMAIN_ID", domain)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = Context()
    rclpy.init(context=context)
    node = Node(name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    yield node, executor
    executor.shutdown()
    node.destroy_node()
    context.try_shutdown()
    context.destroy()  # its DDS participant ends here, not whenever the garbage collector gets to it


def spinning_peer(monkeypatch: pytest.MonkeyPatch, domain: str, name: str) -> Iterator[Any]:
    """For a fixture: an rclpy node on DDS ``domain`` (localhost only) whose executor spins in a thread
    of its own, so that a test can wait on what its callbacks collect (:func:`wait_for`)."""
    import threading

    from rclpy.executors import SingleThreadedExecutor

    peers = rclpy_peer(monkeypatch, domain, name)
    node, executor = next(peers)
    assert isinstance(executor, SingleThreadedExecutor)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    yield node
    executor.shutdown()
    spinner.join(5)
    next(peers, None)  # the peer's own clean-up


def wait_for(condition: Callable[[], Any], what: str, seconds: float = 20) -> Any:
    """What ``condition()`` gives once it is true, asked every 10 ms; fails naming ``what`` after ``seconds``."""
    import time

    deadline = time.monotonic() + seconds
    while not (result := condition()):
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)
    return result
