"""``$(eval EXPRESSION)``: the small Python expressions of the original CoCo launcher, evaluated safely.

The original launcher (``xcoco_launcher.py``) hands the text to Python's ``eval`` with ``arg``,
``env``, ``optenv``, ``find`` and ``anon`` in scope, so its files hold expressions such as
``$(eval 2.* 3.1415 * float(arg('radius')))``. ``eval`` would also run anything else a file
contains, so the expression is parsed and interpreted here over a whitelist: literals, arithmetic,
comparisons, ``and``/``or``/``not``, ``x if c else y``, indexing and slicing, a few string methods,
``int``/``float``/``str``/``bool``/``abs``/``min``/``max``/``round``/``len``, and the argument
lookups (``arg('name')``, or the bare name of an arg, as ROS 1 roslaunch allows). Sizes are
bounded, so that an expression cannot build a huge number or string.
"""

from __future__ import annotations

import ast
import operator
import os
from collections.abc import Callable, Mapping
from typing import Any
from ..errors import ExpressionError

MAX_LENGTH = 2000
"""Longest expression text, in characters."""
MAX_DEPTH = 50
"""Deepest nesting of the expression's syntax tree."""
MAX_BITS = 4096
"""Largest integer an expression may compute (bits)."""
MAX_STRING = 1_000_000
"""Longest string an expression may compute (characters); the same as a substitution's result."""

_BINARY: dict[type[ast.operator], Callable[[Any, Any], Any]] = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.FloorDiv: operator.floordiv,
    ast.Mod: operator.mod,
    ast.Pow: operator.pow,
}
_UNARY: dict[type[ast.unaryop], Callable[[Any], Any]] = {
    ast.UAdd: operator.pos,
    ast.USub: operator.neg,
    ast.Not: operator.not_,
}
_COMPARE: dict[type[ast.cmpop], Callable[[Any, Any], Any]] = {
    ast.Eq: operator.eq,
    ast.NotEq: operator.ne,
    ast.Lt: operator.lt,
    ast.LtE: operator.le,
    ast.Gt: operator.gt,
    ast.GtE: operator.ge,
    ast.In: lambda a, b: a in b,
    ast.NotIn: lambda a, b: a not in b,
}
_BUILTINS: dict[str, Callable[..., Any]] = {
    "abs": abs, "bool": bool, "float": float, "int": int, "len": len, "max": max, "min": min,
    "round": round, "str": str,
}
STRING_METHODS = frozenset({
    "endswith", "find", "lower", "lstrip", "replace", "rstrip", "split", "startswith", "strip", "upper",
})


def evaluate(text: str, args: Mapping[str, str]) -> str:
    """The value of the expression ``text`` as a string (Python's ``str`` of the result).

    ``args`` are the ``<arg>`` values visible at this point of the file.
    """
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"the expression has {len(text)} characters; at most {MAX_LENGTH} are allowed")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError, MemoryError, RecursionError) as error:
        reason = error.msg if isinstance(error, SyntaxError) else "too deeply nested"
        raise ExpressionError(f"{text.strip()!r} is not a valid expression: {reason}") from None
    value = _Interpreter(args).value(tree.body, 0)
    if isinstance(value, str) and len(value) > MAX_STRING:
        raise ExpressionError(f"the result has more than {MAX_STRING} characters")
    return str(value)


class _Interpreter:
    def __init__(self, args: Mapping[str, str]) -> None:
        self.args = args
        self.functions: dict[str, Callable[..., Any]] = {
            **_BUILTINS, "arg": self._arg, "env": _env, "optenv": _optenv,
        }

    def value(self, node: ast.expr, depth: int) -> Any:
        if depth > MAX_DEPTH:
            raise ExpressionError(f"the expression nests more than {MAX_DEPTH} deep")
        depth += 1
        if isinstance(node, ast.Constant) and isinstance(node.value, (str, int, float, bool, type(None))):
            return _bounded(node.value)
        if isinstance(node, ast.Name):
            return self._arg(node.id)
        if isinstance(node, (ast.Tuple, ast.List)):
            return tuple(self.value(item, depth) for item in node.elts)
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            left, right = self.value(node.left, depth), self.value(node.right, depth)
            _check_operands(node.op, left, right)
            return _bounded(_apply(_BINARY[type(node.op)], left, right))
        if isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
            return _apply(_UNARY[type(node.op)], self.value(node.operand, depth))
        if isinstance(node, ast.BoolOp):
            result = self.value(node.values[0], depth)
            for operand in node.values[1:]:
                if (not result) if isinstance(node.op, ast.And) else result:
                    break
                result = self.value(operand, depth)
            return result
        if isinstance(node, ast.Compare) and all(type(op) in _COMPARE for op in node.ops):
            left = self.value(node.left, depth)
            for op, comparator in zip(node.ops, node.comparators):
                right = self.value(comparator, depth)
                if not _apply(_COMPARE[type(op)], left, right):
                    return False
                left = right
            return True
        if isinstance(node, ast.IfExp):
            return self.value(node.body if self.value(node.test, depth) else node.orelse, depth)
        if isinstance(node, ast.Subscript):
            return _bounded(_apply(operator.getitem, self.value(node.value, depth), self._index(node.slice, depth)))
        if isinstance(node, ast.Call) and not node.keywords:
            return self._call(node, depth)
        raise ExpressionError(f"{ast.unparse(node)!r} is not allowed in $(eval); expected literals, arithmetic, "
                              "comparisons, and/or/not, x if c else y, indexing, string methods, "
                              f"{', '.join(sorted(self.functions))}")

    def _index(self, node: ast.expr, depth: int) -> Any:
        if isinstance(node, ast.Slice):
            parts = (node.lower, node.upper, node.step)
            return slice(*(None if part is None else self.value(part, depth) for part in parts))
        return self.value(node, depth)

    def _call(self, node: ast.Call, depth: int) -> Any:
        arguments = [self.value(argument, depth) for argument in node.args]
        if isinstance(node.func, ast.Name) and node.func.id in self.functions:
            return _bounded(_apply(self.functions[node.func.id], *arguments))
        if isinstance(node.func, ast.Attribute) and node.func.attr in STRING_METHODS:
            target = self.value(node.func.value, depth)
            if node.func.attr == "replace" and len(arguments) > 1:
                if len(str(target)) * max(1, len(str(arguments[1]))) > MAX_STRING:
                    raise ExpressionError(f"the replaced string could have more than {MAX_STRING} characters")
            if isinstance(target, str):
                return _bounded(_apply(getattr(target, node.func.attr), *arguments))
        raise ExpressionError(f"{ast.unparse(node.func)}() cannot be called in $(eval); the functions are "
                              f"{', '.join(sorted(self.functions))} and the string methods "
                              f"{', '.join(sorted(STRING_METHODS))}")

    def _arg(self, name: object) -> str:
        if not isinstance(name, str) or name not in self.args:
            valid = ", ".join(sorted(self.args)) or "none"
            raise ExpressionError(f"no <arg> named {name!r} is declared before this point; valid: {valid}")
        return self.args[name]


def _env(name: str) -> str:
    if name not in os.environ:
        raise ExpressionError(f"env({name!r}): environment variable {name} is not set")
    return os.environ[name]


def _optenv(name: str, default: str = "") -> str:
    """``optenv('NAME', 'default')``; the original's single-string form ``optenv('NAME default')``
    is understood too."""
    if default == "" and " " in name.strip():
        name, default = name.strip().split(" ", 1)
    return os.environ.get(name, default)


def _apply(function: Callable[..., Any], *arguments: Any) -> Any:
    """Call ``function``, turning the errors that values cause into an :class:`ExpressionError`."""
    try:
        return function(*arguments)
    except ExpressionError:
        raise
    except (ArithmeticError, TypeError, ValueError, IndexError, KeyError) as error:
        raise ExpressionError(f"{type(error).__name__}: {error}") from None


def _check_operands(op: ast.operator, left: Any, right: Any) -> None:
    """Refuse, before computing them, the operations whose result would be too large."""
    if isinstance(op, ast.Pow) and isinstance(left, int) and isinstance(right, int) and abs(left) > 1:
        if right * left.bit_length() > MAX_BITS:
            raise ExpressionError(f"{left} ** {right} is larger than {MAX_BITS} bits")
    if isinstance(op, ast.Mod) and isinstance(left, str):
        raise ExpressionError("string formatting with % is not supported in $(eval); use + and str()")
    if isinstance(op, ast.Mult):
        for text, count in ((left, right), (right, left)):
            if isinstance(text, (str, tuple)) and isinstance(count, int) and len(text) * count > MAX_STRING:
                raise ExpressionError(f"the repeated string would have more than {MAX_STRING} characters")


def _bounded(value: Any) -> Any:
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > MAX_BITS:
        raise ExpressionError(f"a number larger than {MAX_BITS} bits")
    if isinstance(value, (str, tuple, list)) and len(value) > MAX_STRING:
        raise ExpressionError(f"a value longer than {MAX_STRING} characters")
    return value
