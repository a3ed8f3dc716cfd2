"""The surface expression of application files: what it builds and how it reports mistakes."""

import pytest

from coco_core.errors import SurfaceExpressionError
from coco_mr_haptics.expression import MAX_DEPTH, PRIMITIVES, parse_surface, surface_problem
from coco_mr_haptics.implicit import Box, Difference, Placed, Plane, Sphere, Torus, Union


def test_builds_the_tree_it_describes():
    surface = parse_surface("difference(box(size=[0.2, 0.2, 0.1]), translate([0, 0, 0.05], sphere(0.04)))")
    assert isinstance(surface, Difference) and isinstance(surface.base, Box)
    (hole,) = surface.removed
    assert isinstance(hole, Placed) and isinstance(hole.child, Sphere)
    assert hole.matrix[2, 3] == 0.05 and hole.child.radius == 0.04
    assert (surface.base.hx, surface.base.hy, surface.base.hz) == (0.1, 0.1, 0.05)


def test_keywords_defaults_numbers_and_frames():
    surface = parse_surface("union(plane(), plane(normal=[1,0,0], offset=-1.5e-2), torus(minor=.01, major=0.1),"
                            " frame('cup', sphere(radius=+3E-2)))")
    assert isinstance(surface, Union)
    first, second, torus, cup = surface.parts
    assert isinstance(first, Plane) and (first.nx, first.ny, first.nz, first.offset) == (0, 0, 1, 0)
    assert (second.nx, second.offset) == (1, -0.015)
    assert isinstance(torus, Torus) and (torus.major, torus.minor) == (0.1, 0.01)
    assert isinstance(cup, Placed) and cup.frame == "cup" and cup.child.radius == 0.03


@pytest.mark.parametrize("text,column,words", [
    ("difference(box(size=[0.2,0.2,0.1]), translate([0,0,0.05], spere(0.04)))", 59,
     ["unknown surface function 'spere'", "did you mean 'sphere'", *PRIMITIVES]),
    ("box(size=[0.2,0.2])", 10, ["3 numbers"]),
    ("sphere(radius=0.1, r=2)", 20, ["no argument 'r'", "valid: radius"]),
    ("sphere()", 1, ["needs 'radius'"]),
    ("sphere(0.1", 11, ["expected ',' or ')'", "the end"]),
    ("sphere(0.1) box([1,1,1])", 13, ["one surface per attribute"]),
    ("union(sphere(0.1), 0.5)", 20, ["'surfaces' must be a surface, got a number"]),
    ("translate(sphere(0.1), [0,0,1])", 11, ["'xyz' must be a vector"]),
    ("sphere(-0.1)", 1, ["radius must be > 0"]),
    ("sphere(0.1) ; rm", 13, ["unexpected character ';'"]),
    ("0.5", 1, ["expected a surface"]),
    ("sphere(1e999)", 8, ["number 1e999 is out of range", "at most 10000"]),
    ("translate([1e999, 0, 0], sphere(0.1))", 12, ["number 1e999 is out of range"]),
    ("plane(offset=-2e300)", 14, ["number -2e300 is out of range"]),
    ("rotate([0, 0, 1e5], sphere(0.1))", 15, ["number 1e5 is out of range"]),
])
def test_errors_name_the_column_and_what_was_expected(text, column, words):
    with pytest.raises(SurfaceExpressionError) as caught:
        parse_surface(text)
    message = str(caught.value)
    assert f"column {column}:" in message
    for word in words:
        assert word in message
    caret_line = message.splitlines()[-1]
    assert caret_line.index("^") - 4 == column - 1


def test_attribute_check_text():
    assert surface_problem("sphere(0.1)") is None
    assert "unknown surface function" in surface_problem("sphre(0.1)")


def test_nesting_is_bounded_with_a_message_not_a_recursion_error():
    deep = "union(" * 495 + "sphere(0.1)" + ")" * 495
    with pytest.raises(SurfaceExpressionError) as caught:
        parse_surface(deep)
    assert f"nests deeper than {MAX_DEPTH} calls" in str(caught.value)
    assert f"column {6 * MAX_DEPTH + 1}:" in str(caught.value)  # the first call too deep
    at_limit = "union(" * (MAX_DEPTH - 1) + "sphere(0.1)" + ")" * (MAX_DEPTH - 1)
    assert isinstance(parse_surface(at_limit), Union)
