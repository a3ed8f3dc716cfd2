"""``<arg>`` declarations and the values given for them from outside (``name:=value``).

Modelled on ROS 2 launch XML and the original CoCo launcher: ``value=`` or ``default=`` give an
arg its value (ROS 2's ``<choice value="..."/>`` children list the values it accepts), a value given from outside (the command line's ``name:=value``) wins over both, as
in the original launcher, and an arg with neither must be given. An arg is visible from its declaration on, in document
order (an included file's args are visible in it and after its ``<include>``). A value given from
outside is also visible where no declaration precedes it, as in the original launcher, whose
files use ``$(arg port)`` without declaring ``port``; only a given value that nothing declares
or uses is an error (usually a typo on the command line). Values set from a lower layer (the ROS
launcher's node parameters, ``-p`` and ``--params-file``) rank between the command line's and the
file's, and only for declared args: a ROS node has parameters of its own (``use_sim_time``) that no
file declares. A repeated
declaration may only restate a ``default=``, which does not change the value already set: that lets
an included file declare the args it uses, so that it also loads on its own.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping

from ..errors import CommandLineError, ConfigError, Location, did_you_mean
from ..model import ArgDeclaration
from .reader import CONDITIONS, FileReader
from .tree import Element
from .values import parse_number

ARG_ATTRIBUTES = ("default", "doc", "max", "min", "name", "value", *CONDITIONS)
_NAME = re.compile(r"[A-Za-z0-9_.-]+")


class Arguments:
    """The args of one load: ``values`` is what ``$(arg ...)`` sees at any point of the reading."""

    def __init__(self, given: Mapping[str, str], parameters: Mapping[str, str] | None = None,
                 giving: str = "{name}:=VALUE") -> None:
        self.given = dict(given)
        self.giving = giving
        """How a value is given, for the error about an arg that has none: on the command line, or
        by a composite's instance (:mod:`.composite`)."""
        self.parameters = dict(parameters or {})
        """Values for declared args that rank below ``given`` (ROS parameters); never an error."""
        self.declarations: dict[str, ArgDeclaration] = {}
        self.values: dict[str, str] = {}
        self._declared: dict[str, Location] = {}
        self.used_undeclared: set[str] = set()
        """Given args read by a substitution where no declaration preceded it."""
        self.visible: Mapping[str, str] = _Visible(self)
        """What ``$(arg ...)`` sees: the declared values, and the given ones not declared (yet)."""

    def declare(self, reader: FileReader, element: Element) -> None:
        """Read one ``<arg>`` whose conditions held.

        ``default=`` is expanded only when it is used, so a default that cannot be expanded here
        (say an unset environment variable) does not matter when the value is given.
        """
        reader.check_attributes(element, ARG_ATTRIBUTES, required=("name",))
        choices = self._choices(reader, element)
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
                f"<arg> {name!r} has both value= and default=; they are the same setting: give one",
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
        if name in self.given:
            value = self.given[name]
        elif name in self.parameters and not fixed:
            value = self.parameters[name]
        elif fixed:
            value = reader.attribute(element, "value")
        elif "default" in element.attributes:
            value = reader.attribute(element, "default")
        else:
            reader.error(
                f"arg {name!r} has no value: give it ({self.giving.format(name=name)}) or declare a default=",
                element,
            )
            value = ""
        if choices and value is not None and value not in choices:
            reader.error(f"arg {name!r} is {value!r}; expected one of: {', '.join(choices)}", element)
        low, high = self._bound(reader, element, "min"), self._bound(reader, element, "max")
        if value is not None and (low is not None or high is not None):
            self._check_bounds(reader, element, name, value, low, high)
        self.values[name] = value or ""
        self.declarations[name] = ArgDeclaration(name, self.values[name], tuple(choices),
                                                 reader.attribute(element, "doc") or "", fixed, element.location,
                                                 low, high)

    @staticmethod
    def _bound(reader: FileReader, element: Element, which: str) -> float | None:
        """``min=`` / ``max=``: the numbers an arg's value must lie within (a ROS parameter's range)."""
        values = {which: reader.attribute(element, which) or ""}
        return reader.parsed(element, values, which, parse_number)

    @staticmethod
    def _check_bounds(reader: FileReader, element: Element, name: str, value: str, low: float | None,
                      high: float | None) -> None:
        """An arg with bounds is a number within them, whoever gave it."""
        expected = " and ".join(text for text in (f">= {low:g}" if low is not None else "",
                                                  f"<= {high:g}" if high is not None else "") if text)
        try:
            number = parse_number(value)
        except ValueError:
            reader.error(f"arg {name!r} is {value!r}; expected a number {expected}", element)
            return
        if (low is not None and number < low) or (high is not None and number > high):
            reader.error(f"arg {name!r} is {value!r}; expected a number {expected}", element)

    @staticmethod
    def _choices(reader: FileReader, element: Element) -> list[str]:
        """The values of the ``<choice value=.../>`` children (none: any value); other content is an error."""
        if element.text.strip():
            reader.error("unexpected text in <arg>; it has attributes and <choice value=.../> children only",
                         element)
        choices = []
        for child in element.children:
            if child.tag != "choice":
                reader.unexpected(child, f"unexpected element <{child.tag}> in <arg>; expected <choice value=.../>")
                continue
            reader.check_attributes(child, ("value",), required=("value",))
            reader.empty(child)
            value = reader.attribute(child, "value")
            if value is not None:
                choices.append(value)
        return choices

    def unknown_given(self) -> list[ConfigError]:
        """An error for each given arg that no file declares (usually a typo on the command line)."""
        return [
            CommandLineError(
                f"arg {name!r} was given ({name}:={value}) but no file declares it; "
                f"{did_you_mean(name, list(self._declared))}"
            )
            for name, value in self.given.items()
            if name not in self._declared and name not in self.used_undeclared
        ]


class _Visible(Mapping[str, str]):
    """The args a substitution may read; reading a given but undeclared one is noted, so that it
    does not count as a typo."""

    def __init__(self, arguments: Arguments) -> None:
        self._arguments = arguments

    def __getitem__(self, name: str) -> str:
        arguments = self._arguments
        if name in arguments.values:
            return arguments.values[name]
        value = arguments.given[name]  # KeyError when neither declared nor given
        arguments.used_undeclared.add(name)
        return value

    def __iter__(self) -> Iterator[str]:
        return iter({**self._arguments.given, **self._arguments.values})

    def __len__(self) -> int:
        return len({**self._arguments.given, **self._arguments.values})
