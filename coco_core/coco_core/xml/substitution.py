"""``$(...)`` substitutions in attribute values and element text.

Modelled on ROS 2 launch XML so that one habit serves both: ``$(arg name)``, ``$(env NAME)``,
``$(env NAME default)``, ``$(optenv NAME default)``, ``$(anon name)``, ``$(dirname)`` and
``$(find-pkg-share package)``, and the original CoCo launcher's ``$(eval EXPRESSION)`` (see
:mod:`.expression`). Substitutions nest (``$(optenv RATE $(arg rate))``): the inner ones
are expanded first. ``ament_index_python`` is imported only when ``find-pkg-share`` is used, so
that ``coco_core`` works without ROS.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Mapping

from ..errors import SubstitutionError, did_you_mean
from .expression import ExpressionError, evaluate

FUNCTIONS = ("anon", "arg", "dirname", "env", "eval", "find-pkg-share", "optenv")
MAX_NESTING = 20
"""How deep ``$(...)`` may nest inside one another; real files nest two or three deep."""
MAX_EXPANSION = 1_000_000
"""The longest value a substitution may produce, in characters: args that repeat each other
(``a`` = ``$(arg b)$(arg b)`` ...) would otherwise double with each declaration."""

_anonymous_serial = itertools.count(1)
"""Shared by every load in this process, so that two loads never produce the same anonymous name."""


class Substitutions:
    """Expands the substitutions of one application load.

    ``args`` is a live view of the ``<arg>`` values declared so far: a file sees the args declared
    before the point where a value is read, which is what document order means.
    """

    def __init__(self, args: Mapping[str, str]) -> None:
        self._args = args
        self._anonymous: dict[str, str] = {}
        self._functions: dict[str, Callable[[list[str], str], str]] = {
            "anon": self._anon,
            "arg": self._arg,
            "dirname": self._dirname,
            "env": self._env,
            "find-pkg-share": self._find_pkg_share,
            "optenv": self._optenv,
        }

    def expand(self, text: str, directory: str) -> str:
        """``text`` with every ``$(...)`` replaced; ``directory`` is what ``$(dirname)`` gives.

        The parentheses are matched once, in one pass, so that the cost grows with the length of
        ``text`` however the substitutions nest; nesting beyond :data:`MAX_NESTING` and results
        longer than :data:`MAX_EXPANSION` are errors.
        """
        if "$(" not in text:
            return text
        return self._expand(text, 0, len(text), _matching_parentheses(text), directory, 0)

    def _expand(
        self, text: str, begin: int, end: int, closing: dict[int, int], directory: str, depth: int
    ) -> str:
        """The expansion of ``text[begin:end]``, whose parentheses ``closing`` matches."""
        if depth >= MAX_NESTING:
            raise SubstitutionError(f"substitutions nest more than {MAX_NESTING} deep")
        pieces: list[str] = []
        size = 0
        position = begin
        while (start := text.find("$(", position, end)) >= 0:
            close = closing[start + 1]
            inner = self._expand(text, start + 2, close, closing, directory, depth + 1)
            for piece in (text[position:start], self._call(inner, directory)):
                size += len(piece)
                if size > MAX_EXPANSION:
                    raise SubstitutionError(
                        f"the expanded value would have more than {MAX_EXPANSION} characters"
                    )
                pieces.append(piece)
            position = close + 1
        pieces.append(text[position:end])
        if size + end - position > MAX_EXPANSION:
            raise SubstitutionError(f"the expanded value would have more than {MAX_EXPANSION} characters")
        return "".join(pieces)

    def evaluate(self, expression: str) -> str:
        """The value of an expression over the args (see :mod:`.expression`); raises
        :class:`~.expression.ExpressionError` (a ``ValueError``) when it cannot be evaluated."""
        return evaluate(expression, self._args)

    def _call(self, inner: str, directory: str) -> str:
        words = inner.split(maxsplit=2)
        if words and words[0] == "eval":
            try:
                return evaluate(inner.strip()[len("eval"):], self._args)
            except ExpressionError as error:
                raise SubstitutionError(f"$({_shorten(inner)}): {error}") from None
        if not words:
            raise SubstitutionError(f"empty $(); expected one of: {', '.join(FUNCTIONS)}")
        function = self._functions.get(words[0])
        if function is None:
            raise SubstitutionError(
                f"unknown substitution $({inner}); expected one of: {', '.join(FUNCTIONS)}"
            )
        return function(words[1:], directory)

    def _arg(self, words: list[str], _directory: str) -> str:
        name = _one_word("arg", words)
        if name not in self._args:
            raise SubstitutionError(
                f"$(arg {name}): no <arg> named {name!r} is declared before this point; "
                f"{did_you_mean(name, list(self._args))}"
            )
        return self._args[name]

    def _env(self, words: list[str], _directory: str) -> str:
        if not words:
            raise SubstitutionError("$(env) needs the name of an environment variable")
        if words[0] in os.environ:
            return os.environ[words[0]]
        if len(words) > 1:
            return words[1]
        raise SubstitutionError(
            f"$(env {words[0]}): environment variable {words[0]} is not set "
            f"(give a default: $(env {words[0]} default), or use $(optenv {words[0]}))"
        )

    def _optenv(self, words: list[str], _directory: str) -> str:
        if not words:
            raise SubstitutionError("$(optenv) needs the name of an environment variable")
        return os.environ.get(words[0], words[1] if len(words) > 1 else "")

    def _anon(self, words: list[str], _directory: str) -> str:
        name = _one_word("anon", words)
        if name not in self._anonymous:
            self._anonymous[name] = f"{name}_{os.getpid()}_{next(_anonymous_serial)}"
        return self._anonymous[name]

    def _dirname(self, words: list[str], directory: str) -> str:
        if words:
            raise SubstitutionError(f"$(dirname) takes no argument, got {' '.join(words)!r}")
        return directory

    def _find_pkg_share(self, words: list[str], _directory: str) -> str:
        package = _one_word("find-pkg-share", words)
        try:
            from ament_index_python.packages import get_package_share_directory
        except ImportError:
            raise SubstitutionError(
                f"$(find-pkg-share {package}) needs ament_index_python: source a ROS 2 setup first"
            ) from None
        try:
            return get_package_share_directory(package)
        except (LookupError, OSError) as error:
            raise SubstitutionError(
                f"$(find-pkg-share {package}): package {package!r} is not installed "
                f"in the ament index ({error})"
            ) from None


def _one_word(function: str, words: list[str]) -> str:
    if len(words) != 1:
        raise SubstitutionError(
            f"$({function} ...) takes exactly one name, got {' '.join(words)!r}"
        )
    return words[0]


def _matching_parentheses(text: str) -> dict[int, int]:
    """The index of the ``)`` that closes each ``(`` of ``text`` (one pass, with a stack).

    A ``)`` with nothing open is plain text; a ``(`` left open is an error only when it is the
    ``(`` of a ``$(``.
    """
    closing: dict[int, int] = {}
    open_at: list[int] = []
    for index, character in enumerate(text):
        if character == "(":
            open_at.append(index)
        elif character == ")" and open_at:
            closing[open_at.pop()] = index
    for index in open_at:
        if text.startswith("$(", index - 1):
            raise SubstitutionError(f"unterminated $( in {_shorten(text)!r}: a ')' is missing")
    return closing


def _shorten(text: str, limit: int = 80) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."
