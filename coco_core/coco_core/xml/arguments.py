"""``<arg>`` declarations and the values given for them from outside (``name:=value``).

Modelled on ROS 2 launch XML: ``value=`` fixes an arg, ``default=`` lets the command line override
it, and an arg with neither must be given. An arg is visible from its declaration on, in document
order (an included file's args are visible in it and after its ``<include>``). A repeated
declaration may only restate a ``default=``, which does not change the value already set: that lets
an included file declare the args it uses, so that it also loads on its own.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from ..errors import ConfigError, Location, did_you_mean
from .reader import CONDITIONS, FileReader
from .tree import Element

ARG_ATTRIBUTES = ("default", "doc", "name", "value", *CONDITIONS)
_NAME = re.compile(r"[A-Za-z0-9_.-]+")


class Arguments:
    """The args of one load: ``values`` is what ``$(arg ...)`` sees at any point of the reading."""

    def __init__(self, given: Mapping[str, str]) -> None:
        self.given = dict(given)
        self.values: dict[str, str] = {}
        self._declared: dict[str, Location] = {}

    def declare(self, reader: FileReader, element: Element) -> None:
        """Read one ``<arg>`` whose conditions held.

        ``default=`` is expanded only when it is used, so a default that cannot be expanded here
        (say an unset environment variable) does not matter when the value is given.
        """
        reader.check_attributes(element, ARG_ATTRIBUTES, required=("name",))
        reader.empty(element)
        name = (reader.attribute(element, "name") or "").strip()
        if not name:
            if "name" in element.attributes:
                reader.error('<arg> attribute name="" must not be empty', element)
            return
        if not _NAME.fullmatch(name):
            reader.error(
                f'<arg> attribute name="{name}": expected letters, digits, "_", "-" or "." '
                "(the name is used as $(arg NAME))",
                element,
            )
            return
        fixed = "value" in element.attributes
        if fixed and "default" in element.attributes:
            reader.error(
                f"<arg> {name!r} has both value= (fixed) and default= (may be overridden); give one",
                element,
            )
        earlier = self._declared.get(name)
        if earlier is not None:
            if fixed:
                reader.error(
                    f"arg {name!r} is already declared at {earlier}; a repeated declaration "
                    "may only give a default=",
                    element,
                )
            return
        self._declared[name] = element.location
        value: str | None
        if fixed:
            if name in self.given:
                reader.error(
                    f"arg {name!r} has a fixed value= and cannot be set from outside; "
                    "declare it with default= to allow that",
                    element,
                )
            value = reader.attribute(element, "value")
        elif name in self.given:
            value = self.given[name]
        elif "default" in element.attributes:
            value = reader.attribute(element, "default")
        else:
            reader.error(
                f"arg {name!r} has no value: give it ({name}:=VALUE) or declare a default=", element
            )
            value = ""
        self.values[name] = value or ""

    def unknown_given(self) -> list[ConfigError]:
        """An error for each given arg that no file declares (usually a typo on the command line)."""
        return [
            ConfigError(
                f"arg {name!r} was given ({name}:={value}) but no file declares it; "
                f"{did_you_mean(name, list(self._declared))}"
            )
            for name, value in self.given.items()
            if name not in self._declared
        ]
