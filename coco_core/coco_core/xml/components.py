"""``<component>`` definitions: what to instantiate, under which name, with which attributes and peers.

The same element appears in ``<package><components>`` (the later layout), inside an activity's
``<components>`` (the per-activity layout, where it is also scheduled) and nested as a peer.
Only names are read here; whether a task is registered and its attributes exist is the builder's
business, since it imports the component classes.
"""

from __future__ import annotations

from ..model import AttributeSpec, ComponentSpec
from .draft import Draft, FileAttribute
from .reader import CONDITIONS, FileReader
from .tree import Element

ON_ERROR = ("continue", "stop_component", "stop_app")
COMPONENT_ATTRIBUTES = ("on_error", *CONDITIONS)
COMPONENT_CHILDREN = ("attributes", "components", "library", "name", "task")
ATTRIBUTE_ATTRIBUTES = ("name", "type", "value", *CONDITIONS)
ATTRIBUTE_TYPES = ("file",)
MAX_PEER_DEPTH = 32
"""How deep peers may nest (a peer of a peer of ...): far beyond any real scheduling tree, and
well within what the recursive readers and builders can take."""


def read_component(
    reader: FileReader, element: Element, draft: Draft, on_error_default: str, depth: int = 0
) -> ComponentSpec | None:
    """A ``<component>`` definition whose conditions held; None when it has no usable name.

    ``on_error_default`` is the ``on_error`` of the enclosing file's ``<package>`` ("" for the
    application's policy), for components that do not set their own. ``depth`` counts the owners
    above this component (0 for a top-level component).
    """
    values = reader.attributes(element, COMPONENT_ATTRIBUTES)
    on_error = reader.choice(element, values, "on_error", ON_ERROR, on_error_default)
    children = reader.children(element, COMPONENT_CHILDREN)
    task_element = reader.once(element, children, "task")
    name_element = reader.once(element, children, "name")
    library_element = reader.once(element, children, "library")
    attributes_element = reader.once(element, children, "attributes")
    peers_element = reader.once(element, children, "components")

    task = reader.text(task_element) if task_element is not None else ""
    if task_element is None:
        reader.error(
            "<component> needs a <task>: the name the component is registered under", element
        )
    elif not task:
        reader.error("<task> is empty; it names the component to instantiate", task_element)
    name = (reader.text(name_element) if name_element is not None else "") or task
    library = reader.text(library_element) if library_element is not None else ""
    attributes = (
        _read_attributes(reader, attributes_element, draft) if attributes_element is not None else []
    )
    peers: list[ComponentSpec] = []
    if peers_element is not None and depth >= MAX_PEER_DEPTH:
        reader.error(
            f"peers nest more than {MAX_PEER_DEPTH} deep here; the peers of this component are not read",
            peers_element,
        )
    elif peers_element is not None:
        for child in reader.container(peers_element, ("component",)):
            if reader.kept(child):
                peer = read_component(reader, child, draft, on_error_default, depth + 1)
                if peer is not None:
                    peers.append(peer)
    if not name:
        return None
    return ComponentSpec(
        name=name,
        task=task,
        library=library,
        attributes=attributes,
        peers=peers,
        on_error=on_error,
        location=element.location,
    )


def _read_attributes(reader: FileReader, element: Element, draft: Draft) -> list[AttributeSpec]:
    specs: list[AttributeSpec] = []
    first_lines: dict[str, int] = {}
    for child in reader.container(element, ("attribute",)):
        if not reader.kept(child):
            continue
        values = reader.attributes(child, ATTRIBUTE_ATTRIBUTES, required=("name",))
        reader.empty(child)
        name = values.get("name", "").strip()
        kind = values.get("type", "").strip()
        if kind and kind not in ATTRIBUTE_TYPES:
            reader.error(
                f'<attribute> attribute type="{kind}" is not valid; expected "file" '
                "(a file searched in the resource paths) or nothing (plain text)",
                child,
            )
            kind = ""
        if not name:
            continue
        if name in first_lines:
            reader.error(
                f"attribute {name!r} is set twice (the first is at line {first_lines[name]})", child
            )
            continue
        first_lines[name] = child.location.line
        spec = AttributeSpec(name, values.get("value", ""), kind, child.location)
        specs.append(spec)
        if kind == "file" and spec.value:
            draft.file_attributes.append(FileAttribute(spec, reader.directory))
    return specs
