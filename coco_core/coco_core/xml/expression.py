"""``$(eval EXPRESSION)``: the small Python expressions of the original CoCo launcher, evaluated safely.

The original launcher (``xcoco_launcher.py``) hands the text to Python's ``eval`` with ``arg``,
``env``, ``optenv``, ``find`` and ``anon`` in scope, so its files hold expressions such as
``$(eval 2.* 3.1415 * float(arg('radius')))``. ``eval`` would also run anything else a file
contains, so the expression is parsed and interpreted here over a whitelist: literals, arithmetic,
comparisons, ``and``/``or``/``not``, ``x if c else y``, indexing and slicing, a few string methods,
``int``/``float``/``str``/``bool``/``abs``/``min``/``max``/``round``/``len``, and the argument
lookups (``arg('name')``, or the bare name of an arg, as ROS 1 roslaunch allows). Sizes and time
are bounded, so that an expression cannot build a huge number or string, nor keep the load busy: a
single operation of Python's runs to its end whatever signal comes (``round(1, -10**18)`` computes
``10**(10**18)``), so the operations whose cost grows with their operands are refused before they
run, and the whole evaluation stops after :data:`MAX_SECONDS`.
"""

from __future__ import annotations

import ast
import operator
import os
import time
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
MAX_ROUND_DIGITS = 1300
"""Most digits ``round`` may keep or drop: ``round(x, -n)`` computes ``10**n``, and 4,096 bits hold
1,233 decimal digits, so a larger ``n`` can only give 0 or a number beyond :data:`MAX_BITS`."""
MAX_SECONDS = 1.0
"""Longest time one expression may take to evaluate; real ones take microseconds."""

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
    value = _Interpreter(args, time.monotonic() + MAX_SECONDS).value(tree.body, 0)
    if isinstance(value, str) and len(value) > MAX_STRING:
        raise ExpressionError(f"the result has more than {MAX_STRING} characters")
    return str(value)


class _Interpreter:
    def __init__(self, args: Mapping[str, str], deadline: float) -> None:
        self.args = args
        self.deadline = deadline
        """``time.monotonic()`` past which the evaluation stops (checked at every node)."""
        self.functions: dict[str, Callable[..., Any]] = {
            **_BUILTINS, "arg": self._arg, "env": _env, "optenv": _optenv,
        }

    def value(self, node: ast.expr, depth: int) -> Any:
        if depth > MAX_DEPTH:
            raise ExpressionError(f"the expression nests more than {MAX_DEPTH} deep")
        if time.monotonic() > self.deadline:
            raise ExpressionError(f"the expression takes more than {MAX_SECONDS:g} s to evaluate")
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
            if node.func.id == "round":
                _check_round(arguments)
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


def _check_round(arguments: list[Any]) -> None:
    """Refuse ``round(x, n)`` with ``|n|`` beyond :data:`MAX_ROUND_DIGITS`, before it computes ``10**|n|``."""
    if len(arguments) == 2 and isinstance(arguments[1], int) and abs(arguments[1]) > MAX_ROUND_DIGITS:
        raise ExpressionError(f"round(): {arguments[1]} digits; at most {MAX_ROUND_DIGITS} either way are allowed")


def _bounded(value: Any) -> Any:
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > MAX_BITS:
        raise ExpressionError(f"a number larger than {MAX_BITS} bits")
    if isinstance(value, (str, tuple, list)) and len(value) > MAX_STRING:
        raise ExpressionError(f"a value longer than {MAX_STRING} characters")
    return value
