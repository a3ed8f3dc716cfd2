"""Display errors are CocoErrors (the launcher reports them as messages) that keep the built-in class
callers catch (ValueError, TypeError)."""

from __future__ import annotations

import numpy as np
import pytest
from coco_core.errors import CocoError, GeometryError, MeshLoadError, WrongTypeError
from coco_mr_display.mesh import primitive
from coco_mr_display.poses import reference_of
from coco_mr_display.projection import look_at


def test_a_degenerate_look_at_is_a_geometry_error_and_a_value_error() -> None:
    with pytest.raises(GeometryError, match="equals the target") as caught:
        look_at((1.0, 2.0, 3.0), (1.0, 2.0, 3.0), (0.0, 0.0, 1.0))
    assert isinstance(caught.value, CocoError) and isinstance(caught.value, ValueError)


def test_a_pose_input_that_is_not_a_pose_is_a_wrong_type_error_and_a_type_error() -> None:
    with pytest.raises(WrongTypeError, match="a pose input takes") as caught:
        reference_of(np.eye(3))
    assert isinstance(caught.value, CocoError) and isinstance(caught.value, TypeError)


def test_a_bad_primitive_is_a_mesh_load_error_and_a_value_error() -> None:
    with pytest.raises(MeshLoadError, match="unknown primitive") as caught:
        primitive("cone", [1.0])
    assert isinstance(caught.value, CocoError) and isinstance(caught.value, ValueError)
