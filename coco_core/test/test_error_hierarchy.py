"""Every deliberate error is a CocoError and keeps the built-in class users catch as its second parent;
all exception classes live in coco_core.errors. The source scan keeps the rule true for new code."""

from __future__ import annotations

import ast
import builtins
from pathlib import Path

import numpy as np
import pytest

from coco_core import errors
from coco_core.errors import (
    ActivityError,
    AttributeValueError,
    CocoError,
    ConnectionClosedError,
    DeclarationError,
    EdgeError,
    GeometryError,
    PolicyError,
    PoolError,
    UsageError,
)
from coco_core.component import Component
from coco_core.period import PeriodGrid
from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_core.pool import LocalFramePool
from coco_core.profiling import ActivityStats
from coco_core.transforms import se3
from coco_core.transforms.edges import StaticEdge
from coco_core.transforms.graph import TransformGraph
from coco_core.transforms.rwlock import ReadWriteLock
from coco_core.transforms.server import TransformServer
from coco_core.transforms.websocket import read_frame
from coco_core.xml.values import parse_bool

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("coco_core", "coco_ros", "coco_mr_display", "coco_mr_haptics", "coco_mr_vision")
ERRORS_MODULE = REPO / "coco_core" / "coco_core" / "errors.py"
BUILTIN_EXCEPTIONS = {name for name, value in vars(builtins).items()
                      if isinstance(value, type) and issubclass(value, BaseException)}
COCO_EXCEPTIONS = {name for name, value in vars(errors).items()
                   if isinstance(value, type) and issubclass(value, BaseException)}
# Private control-flow exceptions, caught in their own module: they need no public home.
PRIVATE_EXCEPTIONS = {("coco_core/coco_core/transforms/server.py", "_RequestError"),
                      ("coco_ros/coco_ros/bag/mcap_file.py", "_Damage"),
                      ("coco_ros/coco_ros/bag/cdr_decoder.py", "_Unsupported")}


def sources() -> list[Path]:
    """The Python files of the five packages present in this checkout."""
    files = [path for package in PACKAGES for path in sorted((REPO / package / package).rglob("*.py"))]
    if not files:
        pytest.skip("the package sources are not next to this test (an installed copy is being tested)")
    return files


def _name(node: ast.expr) -> str | None:
    """``ValueError`` for ``ValueError``, ``ValueError(...)`` and ``module.ValueError``."""
    if isinstance(node, ast.Call):
        node = node.func
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return None


def _getattr_bodies(tree: ast.Module) -> set[ast.AST]:
    """Nodes inside a module's ``__getattr__``: Python's import protocol requires AttributeError there."""
    return {inner for node in tree.body if isinstance(node, ast.FunctionDef) and node.name == "__getattr__"
            for inner in ast.walk(node)}


def test_no_builtin_exception_is_raised_directly() -> None:
    found = []
    for path in sources():
        tree = ast.parse(path.read_text(), str(path))
        protocol = _getattr_bodies(tree)
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Raise) and node.exc is not None):
                continue
            name = _name(node.exc)
            if name not in BUILTIN_EXCEPTIONS or name == "NotImplementedError":
                continue
            if name == "AttributeError" and node in protocol:
                continue
            found.append(f"{path.relative_to(REPO)}:{node.lineno}: raise {name}")
    assert not found, "raise a CocoError subclass (with the built-in as second parent):\n" + "\n".join(found)


def test_exception_classes_are_defined_only_in_coco_core_errors() -> None:
    found = []
    for path in sources():
        if path == ERRORS_MODULE:
            continue
        relative = path.relative_to(REPO).as_posix()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.ClassDef) or (relative, node.name) in PRIVATE_EXCEPTIONS:
                continue
            if any(_name(base) in BUILTIN_EXCEPTIONS | COCO_EXCEPTIONS for base in node.bases):
                found.append(f"{relative}:{node.lineno}: class {node.name}")
    assert not found, "define exception classes in coco_core/coco_core/errors.py:\n" + "\n".join(found)


def test_every_error_class_is_a_coco_error() -> None:
    for name in COCO_EXCEPTIONS - {"CocoError"}:
        assert issubclass(getattr(errors, name), CocoError), name


def test_a_bad_quaternion_is_a_geometry_error_and_a_value_error() -> None:
    with pytest.raises(GeometryError, match="not a rotation") as caught:
        se3.quaternion_to_matrix((0.0, 0.0, 0.0, 0.0))
    assert isinstance(caught.value, ValueError)
    with pytest.raises(GeometryError, match="orthonormal"):
        se3.as_transform(np.diag([2.0, 1.0, 1.0, 1.0]))


def test_frame_pool_misuse_is_a_pool_error_and_a_value_error() -> None:
    with pytest.raises(PoolError) as caught:
        LocalFramePool(1)
    assert isinstance(caught.value, ValueError)


def test_a_bad_period_is_an_activity_error() -> None:
    with pytest.raises(ActivityError) as caught:
        PeriodGrid(0.0, ActivityStats())
    assert isinstance(caught.value, ValueError)


def test_a_buffer_without_room_is_a_policy_error_and_a_value_error() -> None:
    with pytest.raises(PolicyError) as caught:
        ConnectionPolicy(data=BufferPolicy.BUFFER, size=0)
    assert isinstance(caught.value, ValueError)


def test_graph_values_it_refuses_are_edge_errors_and_value_errors() -> None:
    with pytest.raises(EdgeError, match="two different frames") as caught:
        StaticEdge("base", "base", np.eye(4))
    assert isinstance(caught.value, ValueError)
    with pytest.raises(EdgeError, match="finite number of seconds"):
        TransformGraph().set_transform("world", "tool", np.eye(4), float("nan"))


def test_writing_the_graph_inside_a_read_is_a_usage_error_and_a_runtime_error() -> None:
    lock = ReadWriteLock()
    with lock.read(), pytest.raises(UsageError) as caught, lock.write():
        pass
    assert isinstance(caught.value, RuntimeError)


def test_a_transform_server_asked_its_url_before_start_is_a_usage_error() -> None:
    server = TransformServer(TransformGraph())
    with pytest.raises(UsageError) as caught:
        server.url
    assert isinstance(caught.value, RuntimeError)
    with pytest.raises(AttributeValueError):
        TransformServer(TransformGraph(), rate=0.0)


def test_a_closed_websocket_is_a_connection_closed_error_and_an_eof_error() -> None:
    with pytest.raises(ConnectionClosedError) as caught:
        read_frame(lambda count: b"")
    assert isinstance(caught.value, EOFError)


def test_an_attribute_text_that_does_not_parse_is_an_attribute_value_error() -> None:
    with pytest.raises(AttributeValueError) as caught:
        parse_bool("maybe")
    assert isinstance(caught.value, ValueError)


def test_a_component_shadowing_its_own_members_is_a_declaration_error_and_a_type_error() -> None:
    from coco_core.attributes import Attribute

    with pytest.raises(DeclarationError) as caught:
        type("Shadowing", (Component,), {"name": Attribute(str, "", "shadows Component.name")})
    assert isinstance(caught.value, TypeError)
