"""Strict, error-collecting access to the elements of one application file.

Every value the loader takes from the tree goes through a :class:`FileReader`, which is where the
dialect's general rules live: unknown elements and attributes are errors that name what was
expected (in a file of the original CoCo's dialect, warnings: see :mod:`.dialect`), ``$(...)`` is
expanded in every attribute value and element text, ``if``/``unless`` drop an element, and an empty
attribute value means the attribute's default. Errors are recorded, not
raised, so that one run of the loader reports everything that is wrong with a file.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeVar

from ..errors import ConfigError
from .substitution import SubstitutionError, Substitutions
from .tree import Element
from .values import parse_condition

CONDITIONS = ("if", "unless")
"""Attributes accepted by every element that can be switched off."""

T = TypeVar("T")


class FileReader:
    """Reads the elements of one file; ``directory`` is where relative names in it start from.

    Elements carry their own file and line, so the reader only needs to know the directory (for
    ``$(dirname)`` and relative names), how to substitute, and where errors go.
    """

    def __init__(
        self,
        directory: str,
        substitutions: Substitutions,
        errors: list[ConfigError],
        warnings: list[str],
        original: bool = False,
    ) -> None:
        self.directory = directory
        self.substitutions = substitutions
        self.errors = errors
        self.warnings = warnings
        self.original = original
        """Whether the file is in the original CoCo's dialect (:mod:`.dialect`): unknown elements
        are then ignored with a warning instead of being errors."""

    def error(self, message: str, element: Element) -> None:
        """Record an error at ``element``'s line."""
        self.errors.append(ConfigError(message, element.location))

    def warn(self, message: str, element: Element) -> None:
        """Record a warning at ``element``'s line: something the original CoCo launcher accepts
        and ignores, which this loader ignores too, but says so."""
        self.warnings.append(f"{element.location}: {message}")

    def kept(self, element: Element) -> bool:
        """Whether ``element`` survives its ``if``/``unless`` conditions.

        Conditions are evaluated before anything else of the element is read, so a dropped element
        is ignored entirely (its other values are neither expanded nor checked). A value that is not
        a boolean word is evaluated as an expression, as the original CoCo launcher does
        (``if="arg('camera') == 'kinect'"``, see :mod:`.expression`).
        """
        for name, keep_when in (("if", True), ("unless", False)):
            if name not in element.attributes:
                continue
            value = self.attribute(element, name)
            if value is None:
                return False
            try:
                holds = parse_condition(value)
            except ValueError as expected:
                try:
                    holds = parse_condition(self.substitutions.evaluate(value))
                except ValueError:
                    self._invalid(element, name, element.attributes[name], str(expected))
                    return False
            if holds != keep_when:
                return False
        return True

    def check_attributes(
        self, element: Element, allowed: Sequence[str], required: Sequence[str] = ()
    ) -> None:
        """Report attributes outside ``allowed`` and missing ones of ``required``."""
        for name, raw in element.attributes.items():
            if name not in allowed:
                expected = (
                    f"expected one of: {', '.join(sorted(allowed))}"
                    if allowed
                    else "it takes no attributes"
                )
                self.error(
                    f'unexpected attribute {name}="{raw}" in <{element.tag}>; {expected}', element
                )
        for name in required:
            if name not in element.attributes:
                self.error(f"<{element.tag}> needs a {name}= attribute", element)

    def attribute(self, element: Element, name: str) -> str | None:
        """One attribute with substitutions expanded; None when missing or when expansion failed."""
        if name not in element.attributes:
            return None
        raw = element.attributes[name]
        return self._expand(element, f'attribute {name}="{raw}"', raw)

    def attributes(
        self, element: Element, allowed: Sequence[str], required: Sequence[str] = ()
    ) -> dict[str, str]:
        """The element's attributes, checked and expanded (conditions excluded: see :meth:`kept`).

        A ``required`` attribute must also be non-empty; an attribute whose substitution failed is
        left out of the result, after its error was recorded.
        """
        self.check_attributes(element, allowed, required)
        values: dict[str, str] = {}
        for name in element.attributes:
            if name in allowed and name not in CONDITIONS:
                value = self.attribute(element, name)
                if value is not None:
                    values[name] = value
        for name in required:
            if name in values and not values[name].strip():
                self.error(f'<{element.tag}> attribute {name}="" must not be empty', element)
        return values

    def children(self, element: Element, allowed: Sequence[str]) -> list[Element]:
        """The child elements whose tag is in ``allowed``; any other child or stray text is an error."""
        stray = element.text.strip()
        if stray:
            self.error(
                f"unexpected text {_shorten(stray)!r} in <{element.tag}>; it contains elements only",
                element,
            )
        found: list[Element] = []
        for child in element.children:
            if child.tag in allowed:
                found.append(child)
            else:
                self.unexpected(child, f"unexpected element <{child.tag}> in <{element.tag}>; "
                                       f"expected one of: {', '.join(sorted(allowed))}")
        return found

    def unexpected(self, element: Element, message: str) -> None:
        """An element the dialect does not know at this place: an error, or in the original CoCo's
        dialect a warning, after the substitutions in it were expanded as the original launcher
        does (so a wrong one is still an error)."""
        if not self.original:
            self.error(message, element)
            return
        self.warn(f"{message}; ignored, as the original CoCo ignores it (this file uses none of this "
                  "project's extensions, so it is read in the original dialect)", element)
        pending = [element]
        while pending:
            current = pending.pop()
            for name in current.attributes:
                self.attribute(current, name)
            self._expand(current, f"text {current.text.strip()!r}", current.text)
            pending.extend(current.children)

    def container(self, element: Element, allowed: Sequence[str]) -> list[Element]:
        """:meth:`children` of an element that has no attributes of its own."""
        self.check_attributes(element, ())
        return self.children(element, allowed)

    def empty(self, element: Element) -> None:
        """Report any content of an element that carries attributes only."""
        if element.text.strip():
            self.error(f"unexpected text {_shorten(element.text.strip())!r} in <{element.tag}>; "
                       "it has attributes only", element)
        for child in element.children:
            self.unexpected(child, f"unexpected element <{child.tag}> in <{element.tag}>; it has attributes only")

    def text(self, element: Element, allowed_attributes: Sequence[str] = ()) -> str:
        """The stripped, expanded text of an element that holds text only."""
        self.check_attributes(element, allowed_attributes)
        for child in element.children:
            self.unexpected(child, f"unexpected element <{child.tag}> in <{element.tag}>; it contains text only")
        value = self._expand(element, f"text {element.text.strip()!r}", element.text)
        return "" if value is None else value.strip()

    def once(self, parent: Element, children: list[Element], tag: str) -> Element | None:
        """The child ``<tag>`` of ``parent``, which may appear at most once."""
        found = [child for child in children if child.tag == tag]
        for extra in found[1:]:
            self.error(
                f"<{parent.tag}> has more than one <{tag}> (the first is at line "
                f"{found[0].location.line})",
                extra,
            )
        return found[0] if found else None

    def choice(
        self, element: Element, values: dict[str, str], name: str, choices: Sequence[str], default: str
    ) -> str:
        """An attribute restricted to ``choices``; missing or empty gives ``default``."""
        value = values.get(name, "").strip()
        if not value:
            return default
        if value in choices:
            return value
        self.error(
            f'<{element.tag}> attribute {name}="{value}" is not valid; '
            f"expected one of: {', '.join(choices)}",
            element,
        )
        return default

    def parsed(
        self, element: Element, values: dict[str, str], name: str, parse: Callable[[str], T]
    ) -> T | None:
        """An attribute read by ``parse`` (see :mod:`.values`); None when missing, empty or wrong."""
        value = values.get(name, "")
        if not value.strip():
            return None
        try:
            return parse(value)
        except ValueError as expected:
            self._invalid(element, name, value, str(expected))
            return None

    def _invalid(self, element: Element, name: str, value: str, expected: str) -> None:
        self.error(f'<{element.tag}> attribute {name}="{value}": expected {expected}', element)

    def _expand(self, element: Element, what: str, raw: str) -> str | None:
        try:
            return self.substitutions.expand(raw, self.directory)
        except SubstitutionError as error:
            self.error(f"<{element.tag}> {what}: {error}", element)
            return None


def _shorten(text: str, limit: int = 40) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."
