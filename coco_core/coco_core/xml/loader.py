"""Load an application file: read it and its includes in document order, then check it as a whole.

An included file is read where its ``<include>`` stands, so its components, connections,
activities, paths and args come in the result where the include is, and the args it declares are
visible after it. Errors are collected across all files and raised together; nothing is returned
for a wrong application.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from ..errors import ConfigError, ConfigErrors
from ..errors import FileWriteError
from ..files import APPLICATION_FILE_LIMIT, FileReadError, check_writable_file, read_regular_file
from ..model import AppSpec, CompositeSpec, LogSpec
from .activities import read_activity
from .arguments import Arguments
from .components import ON_ERROR, read_component
from .composite import Instance, join, read_instance, read_ports, scope, unknown_args, within
from .connections import read_connection
from .dialect import extension_of
from .draft import Draft
from .farm import expand_farms, read_farm
from .pipeline import read_pipeline
from .host import read_host
from .process import read_process
from .reader import CONDITIONS, FileReader
from .references import check_draft
from .resources import find_resource, not_found_message
from .substitution import Substitutions
from .topics import read_topics
from .transforms import read_transforms
from .tree import Element, parse_xml
from .values import parse_int

PACKAGE_ATTRIBUTES = ("name", "on_error")
PACKAGE_CHILDREN = (
    "activities",
    "arg",
    "components",
    "connections",
    "includes",
    "log",
    "logconfig",
    "paths",
    "ports",
    "resourcespaths",
    "topics",
    "transforms",
)
LOG_CHILDREN = ("file", "levels", "outfile", "types")
LOG_TYPES = ("debug", "err", "log")
MAX_INCLUDE_DEPTH = 64
"""How many files an include chain may hold (the application file included): a limit far beyond
real applications, which keeps a generated chain from exhausting the reader's recursion."""
MAX_INCLUDES = 1000
"""How many includes one load reads in all, the same file counted each time it is read: files that
each include the next one twice would otherwise be read 2^N times (30 of them, a billion)."""
MAX_INCLUDED_BYTES = 64 * 1024 * 1024
"""How many bytes of included files one load reads in all (each file has the limit of an
application file, 16 MiB): an application of many large includes stops here, not at the memory."""


def load_application(
    path: str | os.PathLike[str], args: Mapping[str, str] | None = None,
    parameters: Mapping[str, str] | None = None,
) -> AppSpec:
    """The application described by the file at ``path``.

    ``args`` gives values to the ``<arg>`` declarations (``name:=value`` on a command line);
    ``parameters`` too, ranked below ``args`` and only for declared args (the ROS launcher's node
    parameters: see :class:`.arguments.Arguments`).
    Raises :class:`ConfigError` when the file cannot be read, and :class:`ConfigErrors` with every
    error found (each pointing at a file and line) when its content is wrong.
    """
    file = os.path.abspath(os.fspath(path))
    try:
        data = read_regular_file(file, APPLICATION_FILE_LIMIT, "application file")
    except FileReadError as error:
        raise ConfigError(str(error)) from None
    return _Loader(args or {}, parameters).load(data, file, os.path.dirname(file))


def parse_application_string(
    text: str, filename: str = "<string>", args: Mapping[str, str] | None = None
) -> AppSpec:
    """The application described by ``text``; ``filename`` only names it in errors.

    Relative names in it (includes, paths, ``type="file"`` attributes, ``$(dirname)``) start from
    the current directory.
    """
    return _Loader(args or {}).load(text, filename, os.getcwd())


class _Loader:
    """The state of one load: errors so far, args, the draft and the chain of open includes."""

    def __init__(self, given_args: Mapping[str, str], parameters: Mapping[str, str] | None = None) -> None:
        self.errors: list[ConfigError] = []
        self.warnings: list[str] = []
        self.arguments = Arguments(given_args, parameters)
        self.substitutions = Substitutions(self.arguments.visible)
        self.draft = Draft()
        self.include_chain: list[tuple[str, str]] = []
        """(identity, name) of each file being read, outermost first, to detect include cycles."""
        self.files: list[str] = []
        """Every file opened, in order: errors are reported in this order, then by line."""
        self.complete = True
        """False once a file could not be read: checks across files would then only add noise."""
        self.includes_read = 0
        self.included_bytes = 0
        """The includes read so far and their bytes, against :data:`MAX_INCLUDES` and
        :data:`MAX_INCLUDED_BYTES`; past either, no include is read any more (one error says so)."""
        self.includes_refused = False

    def load(self, data: bytes | str, file: str, directory: str) -> AppSpec:
        name, on_error = Path(file).stem, ""
        root = self._parse(data, file)
        if root is not None:
            reader = FileReader(directory, self.substitutions, self.errors, self.warnings,
                                original=extension_of(root) is None)
            self.include_chain.append((_identity(file), file))
            values = self._package(reader, root, "", top=True)
            name = values.get("name", "").strip() or name
            on_error = values.get("on_error", "").strip() or on_error
        if self.complete:
            self.errors.extend(self.arguments.unknown_given())
            self.errors.extend(check_draft(self.draft))
        if self.errors:
            raise ConfigErrors(sorted(self.errors, key=self._reading_order))
        return AppSpec(
            name=name,
            file=file,
            components=self.draft.components,
            connections=self.draft.connections,
            activities=self.draft.activities,
            processes=self.draft.processes,
            hosts=self.draft.hosts,
            paths=self.draft.paths,
            args=dict(self.arguments.values),
            arg_declarations=dict(self.arguments.declarations),
            on_error=on_error,
            log=self.draft.log,
            transforms=self.draft.transforms.spec if self.draft.transforms is not None else None,
            composites=self.draft.composites,
            warnings=self.warnings,
            topics=self.draft.topics,
        )

    def _reading_order(self, error: ConfigError) -> tuple[int, int]:
        """Sort key: errors by file (in the order files were opened), then line; unplaced last."""
        if error.location is None or error.location.file not in self.files:
            return len(self.files), 0
        return self.files.index(error.location.file), error.location.line

    def _parse(self, data: bytes | str, file: str) -> Element | None:
        self.files.append(file)
        try:
            return parse_xml(data, file)
        except ConfigError as error:
            self.errors.append(error)
            self.complete = False
            return None

    def _package(
        self, reader: FileReader, root: Element, on_error_default: str, *, top: bool = False
    ) -> dict[str, str]:
        """Read a ``<package>``; its checked attributes are returned for the top file to use.

        The top file's ``on_error`` is the application's policy, which its components follow by
        keeping "". An included file's ``on_error`` is the default of the components defined in it
        (and in the files it includes), so that a sub-application can be stricter than the rest.
        """
        if root.tag != "package":
            reader.error(f"the root element is <{root.tag}>; expected <package>", root)
            return {}
        for schema_attribute in [name for name in root.attributes if _is_schema_attribute(name)]:
            del root.attributes[schema_attribute]
        values = reader.attributes(root, PACKAGE_ATTRIBUTES)
        own_on_error = reader.choice(root, values, "on_error", ON_ERROR, "")
        on_error = "" if top else own_on_error or on_error_default
        for child in reader.children(root, PACKAGE_CHILDREN):
            if child.tag in ("log", "logconfig"):
                self._log(reader, child)
            elif child.tag in ("paths", "resourcespaths"):
                self._paths(reader, child)
            elif child.tag == "includes":
                self._includes(reader, child, on_error)
            elif child.tag == "arg":
                if reader.kept(child):
                    self.arguments.declare(reader, child)
            elif child.tag == "components":
                self._components(reader, child, on_error)
            elif child.tag == "ports":
                read_ports(reader, child, self.draft)
            elif child.tag == "topics":
                if reader.kept(child):
                    read_topics(reader, child, self.draft)
            elif child.tag == "transforms":
                if reader.kept(child):
                    self.draft.transforms = read_transforms(reader, child, self.draft.transforms)
            elif child.tag == "connections":
                for connection in reader.container(child, ("connection",)):
                    if reader.kept(connection):
                        spec = read_connection(reader, connection)
                        if spec is not None:
                            self.draft.connections.append(spec)
            else:
                self._activities(reader, child, on_error)
        return values

    def _components(self, reader: FileReader, element: Element, on_error: str) -> None:
        for child in reader.container(element, ("component", "composite")):
            if not reader.kept(child):
                continue
            if child.tag == "composite":
                instance = read_instance(reader, child)
                if instance is not None:
                    self._instantiate(reader, child, instance, on_error)
            else:
                spec = read_component(reader, child, self.draft, on_error)
                if spec is not None:
                    self.draft.components.append(spec)

    def _activities(self, reader: FileReader, element: Element, on_error: str) -> None:
        def read_child(child: Element) -> None:
            if child.tag == "activity":
                read_activity(reader, child, self.draft, on_error)
            elif child.tag == "farm":
                read_farm(reader, child, self.draft)
            else:
                read_pipeline(reader, child, self.draft)

        def read_placed(child: Element) -> None:
            if child.tag == "process":
                read_process(reader, child, self.draft, read_child)
            else:
                read_child(child)

        for child in reader.container(element, ("activity", "farm", "host", "pipeline", "process")):
            if not reader.kept(child):
                continue
            if child.tag == "host":
                read_host(reader, child, self.draft, read_placed)
            else:
                read_placed(child)

    def _log(self, reader: FileReader, element: Element) -> None:
        children = reader.container(element, LOG_CHILDREN)
        if self.draft.log is not None:
            reader.error(
                f"<{element.tag}> is given a second time (the first is at {self.draft.log.location}); "
                "an application has one log configuration",
                element,
            )
            return
        log = LogSpec(location=element.location)
        # <file> named the C++ CoCo's log configuration file: it is read (so it is checked), unused.
        for tag in LOG_CHILDREN:
            child = reader.once(element, children, tag)
            if child is None:
                continue
            text = reader.text(child)
            if tag == "levels":
                log.levels = self._log_levels(reader, child, text)
            elif tag == "types":
                log.types = self._log_types(reader, child, text)
            elif tag == "outfile":
                log.outfile = text
                try:
                    if text:
                        check_writable_file(text, "<outfile>")
                except FileWriteError as error:
                    reader.error(str(error), child)
        self.draft.log = log

    @staticmethod
    def _log_levels(reader: FileReader, element: Element, text: str) -> list[int]:
        levels: list[int] = []
        for word in text.split():
            try:
                levels.append(parse_int(word))
            except ValueError:
                reader.error(
                    f"<levels> {word!r} is not valid; expected numbers separated by spaces", element
                )
        return levels

    @staticmethod
    def _log_types(reader: FileReader, element: Element, text: str) -> list[str]:
        for word in text.split():
            if word not in LOG_TYPES:
                reader.error(
                    f"<types> {word!r} is not valid; expected words among: {', '.join(LOG_TYPES)}",
                    element,
                )
        return [word for word in text.split() if word in LOG_TYPES]

    def _paths(self, reader: FileReader, element: Element) -> None:
        """``<paths>``, or the per-activity layout's ``<resourcespaths>``, whose ``<librariespath>``
        is one more resource path here (Python components are found by their package instead)."""
        allowed = ("path",) if element.tag == "paths" else ("librariespath", "path")
        for child in reader.container(element, allowed):
            text = reader.text(child)
            if text:
                self.draft.paths.append(os.path.normpath(os.path.join(reader.directory, text)))
            else:
                reader.error(f"<{child.tag}> is empty; it names a directory", child)

    def _includes(self, reader: FileReader, element: Element, on_error: str) -> None:
        for include in reader.container(element, ("include",)):
            if not reader.kept(include):
                continue
            name = reader.text(include, CONDITIONS)
            if not name:
                reader.error("<include> is empty; it names an application file", include)
                continue
            found, tried = find_resource(name, reader.directory, self.draft.paths)
            if found is None:
                reader.error(f"<include> {not_found_message(name, tried)}", include)
                self.complete = False
                continue
            self._include(reader, include, found, on_error)

    def _include(self, reader: FileReader, include: Element, file: str, on_error: str) -> None:
        root = self._open(reader, include, file, "include")
        if root is None:
            return
        included = FileReader(os.path.dirname(file), self.substitutions, self.errors, self.warnings,
                              original=extension_of(root) is None)
        self._package(included, root, on_error)
        self.include_chain.pop()

    def _instantiate(self, reader: FileReader, element: Element, instance: Instance, on_error: str) -> None:
        """Read a composite's file for one instance, with the instance's args as the only ones
        given and a draft of its own, then scope its names and join it to the application.

        Paths, the log and ``<transforms>`` stay shared with the application, as an included
        file's do; the arg scope does not: a composite sees the values its ``<composite>`` gives,
        so that two instances of one file differ only where their elements say so.
        """
        earlier = next((spec for spec in self.draft.composites if spec.name == instance.name), None)
        if earlier is not None:
            reader.error(f"composite instance name {instance.name!r} is already used at {earlier.location}; "
                         "instance names must be unique", element)
            return
        file, tried = find_resource(instance.file, reader.directory, self.draft.paths)
        if file is None:
            reader.error(f"<composite> {not_found_message(instance.file, tried)}", element)
            self.complete = False
            return
        root = self._open(reader, element, file, "composite")
        if root is None:
            return
        outer = (self.draft, self.arguments, self.substitutions)
        first_error = len(self.errors)
        self.draft = Draft(paths=outer[0].paths, log=outer[0].log, transforms=outer[0].transforms)
        self.arguments = Arguments(instance.args, giving="<arg name=\"{name}\" value=\"...\"/> in the <composite>")
        self.substitutions = Substitutions(self.arguments.visible)
        inner = FileReader(os.path.dirname(file), self.substitutions, self.errors, self.warnings,
                           original=extension_of(root) is None)
        try:
            self._package(inner, root, on_error)
            self.include_chain.pop()
            self.errors.extend(unknown_args(instance, self.arguments.declarations, self.arguments.used_undeclared))
            expand_farms(self.draft)
            spec = CompositeSpec(instance.name, file, dict(self.arguments.values), location=instance.location)
            sub = self.draft
        finally:
            self.draft, self.arguments, self.substitutions = outer
        self.errors[first_error:] = within(self.errors[first_error:], spec)
        scope(sub, instance.name + "/")
        join(self.draft, sub, spec)

    def _open(self, reader: FileReader, element: Element, file: str, kind: str) -> Element | None:
        """The root of a file an ``<include>`` or ``<composite>`` names, pushed on the chain of
        open files (the caller pops it after reading); None, the error recorded, when it would
        close a cycle, pass a limit, or cannot be read or parsed."""
        identity = _identity(file)
        identities = [open_identity for open_identity, _ in self.include_chain]
        if identity in identities:
            cycle = [name for _, name in self.include_chain[identities.index(identity) :]]
            reader.error(f"{kind} cycle: {' -> '.join([*cycle, file])}", element)
            return None
        if len(self.include_chain) >= MAX_INCLUDE_DEPTH:
            reader.error(
                f"includes nest more than {MAX_INCLUDE_DEPTH} files deep (from {self.include_chain[0][1]}); "
                f"{file} is not read",
                element,
            )
            self.complete = False
            return None
        if self.includes_read >= MAX_INCLUDES or self.included_bytes >= MAX_INCLUDED_BYTES:
            if not self.includes_refused:
                reader.error(
                    f"the application includes more than {MAX_INCLUDES} files or "
                    f"{MAX_INCLUDED_BYTES // (1024 * 1024)} MiB in all (files that include the same files "
                    f"again and again?); {file} and the includes after it are not read",
                    element,
                )
            self.includes_refused = True
            self.complete = False
            return None
        try:
            data = read_regular_file(file, APPLICATION_FILE_LIMIT, f"{'included' if kind == 'include' else kind} file")
        except FileReadError as error:
            reader.error(str(error), element)
            self.complete = False
            return None
        self.includes_read += 1
        self.included_bytes += len(data)
        root = self._parse(data, file)
        if root is None:
            return None
        self.include_chain.append((identity, file))
        return root


def _identity(file: str) -> str:
    """What makes two names the same file, for cycle detection (``<string>`` has no real path)."""
    return os.path.realpath(file) if os.path.isabs(file) else file


def _is_schema_attribute(name: str) -> bool:
    """Namespace declarations and ``xsi:`` hints (``xsi:noNamespaceSchemaLocation="coco.xsd"``) are
    for XML tools, so ``<package>`` accepts them without meaning anything by them. That includes a
    default namespace (``xmlns="http://www.example.org/coco/"``), which files of the original CoCo
    carry and its launcher ignores: elements are matched by their plain names."""
    return name == "xmlns" or name.startswith(("xmlns:", "xsi:"))
