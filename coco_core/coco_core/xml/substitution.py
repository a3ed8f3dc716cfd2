"""``$(...)`` substitutions in attribute values and element text.

Modelled on ROS 2 launch XML so that one habit serves both: ``$(arg name)``, ``$(env NAME)``,
``$(env NAME default)``, ``$(optenv NAME default)``, ``$(anon name)``, ``$(dirname)`` and
``$(find-pkg-share package)``. Substitutions nest (``$(optenv RATE $(arg rate))``): the inner ones
are expanded first. ``ament_index_python`` is imported only when ``find-pkg-share`` is used, so
that ``coco_core`` works without ROS.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Mapping

from ..errors import did_you_mean

FUNCTIONS = ("anon", "arg", "dirname", "env", "find-pkg-share", "optenv")

_anonymous_serial = itertools.count(1)
"""Shared by every load in this process, so that two loads never produce the same anonymous name."""


class SubstitutionError(ValueError):
    """A substitution that cannot be expanded; the message says which one and why."""


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
        """``text`` with every ``$(...)`` replaced; ``directory`` is what ``$(dirname)`` gives."""
        pieces: list[str] = []
        position = 0
        while (start := text.find("$(", position)) >= 0:
            pieces.append(text[position:start])
            end = _closing_parenthesis(text, start + 1)
            inner = self.expand(text[start + 2 : end], directory)
            pieces.append(self._call(inner, directory))
            position = end + 1
        pieces.append(text[position:])
        return "".join(pieces)

    def _call(self, inner: str, directory: str) -> str:
        words = inner.split(maxsplit=2)
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


def _closing_parenthesis(text: str, opening: int) -> int:
    depth = 0
    for index in range(opening, len(text)):
        if text[index] == "(":
            depth += 1
        elif text[index] == ")":
            depth -= 1
            if depth == 0:
                return index
    raise SubstitutionError(f"unterminated $( in {text!r}: a ')' is missing")
