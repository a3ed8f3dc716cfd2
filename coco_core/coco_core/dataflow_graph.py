"""The application's data-flow graph, as Graphviz DOT (and SVG, PNG or PDF through Graphviz's ``dot``).

FlowVR's tools draw a network as the graph of its modules, connections and filters, which is how
one reads a large application at a glance. ``--check --graph FILE`` draws this project's
equivalent from the loaded application (:class:`~coco_core.model.AppSpec`, so that nothing is
instantiated): a cluster per host (when the file has ``<host>``s) holding a cluster per process
(when it has ``<process>``es) holding a cluster per activity, whose components are nodes (a component with peers is a cluster of its own holding them,
since they run inside it), each connection an edge labelled with its ports and policy, a filter a
node of its own on its connection's path, an activity's ``beginit``/``endit`` ports small nodes in
the activity's cluster. Components no activity runs stand in their process outside any activity (on
the first host). A connection between processes is bold, one between hosts too and says so.

DOT is written by this module (plain text: no Python dependency); other formats are rendered by
the ``dot`` program of Graphviz, which is then needed on PATH (``apt install graphviz``).
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import CocoError, GraphError
from .files import check_writable_file
from .iteration import BEGIN, END
from .model import ActivitySpec, AppSpec, ComponentSpec, ConnectionSpec, FilterSpec, PortRef
from .policy import ConnectionPolicy
from .processes.placement import LAUNCHER

if TYPE_CHECKING:
    from .deployment import Deployment

DOT_SUFFIXES = (".dot", ".gv")
RENDERED_SUFFIXES = (".svg", ".png", ".pdf")
"""What ``dot`` renders here: ``-T`` takes the suffix without its dot."""
RENDER_TIMEOUT = 60.0
"""Seconds ``dot`` may take: far beyond any application's graph (the Baxter app's takes 0.1 s)."""


def check_graph_file(path: str) -> None:
    """Raise :class:`GraphError` unless ``path`` names a format this module writes, in a place it
    can write, and ``dot`` is there when the format needs it: checked before the application is
    loaded, so that a typo fails at once."""
    suffix = Path(path).suffix.lower()
    if suffix not in (*DOT_SUFFIXES, *RENDERED_SUFFIXES):
        raise GraphError(f"--graph {path}: expected a file name ending in one of "
                         f"{', '.join((*DOT_SUFFIXES, *RENDERED_SUFFIXES))} (DOT, or rendered by Graphviz's dot)")
    try:
        check_writable_file(path, "--graph")
        if suffix in RENDERED_SUFFIXES:
            check_writable_file(dot_companion(path), "--graph")
    except CocoError as error:
        raise GraphError(str(error)) from None
    if suffix in RENDERED_SUFFIXES and shutil.which("dot") is None:
        raise GraphError(f"--graph {path}: rendering {suffix[1:].upper()} needs Graphviz's dot program, which is not "
                         f"on PATH; install Graphviz (apt install graphviz) or write DOT (--graph "
                         f"{dot_companion(path)})")


def dot_companion(path: str) -> str:
    """The DOT file written beside a rendered one (``out.svg`` -> ``out.dot``): the graph's source."""
    return str(Path(path).with_suffix(".dot"))


def write_graph(deployment: Deployment, path: str) -> list[str]:
    """Write the data-flow graph of ``deployment``'s file to ``path`` (DOT; SVG, PNG or PDF rendered by ``dot``, with
    the DOT beside it); returns the files written."""
    check_graph_file(path)
    text = dataflow_dot(deployment)
    suffix = Path(path).suffix.lower()
    if suffix in DOT_SUFFIXES:
        _write(path, text)
        return [path]
    source = dot_companion(path)
    _write(source, text)
    try:
        done = subprocess.run(["dot", f"-T{suffix[1:]}", "-o", path, source], capture_output=True, text=True,
                              timeout=RENDER_TIMEOUT)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise GraphError(f"--graph {path}: Graphviz's dot could not render {source}: {error}") from None
    if done.returncode != 0:
        raise GraphError(f"--graph {path}: Graphviz's dot failed on {source} (exit status {done.returncode}): "
                         f"{done.stderr.strip()}")
    return [source, path]


def _write(path: str, text: str) -> None:
    try:
        Path(path).write_text(text, encoding="utf-8")
    except OSError as error:
        raise GraphError(f"--graph {path} cannot be written: {error.strerror or error}") from None


def quote(text: str) -> str:
    """A DOT identifier or label: a double-quoted string (backslashes and quotes escaped, new lines
    as DOT's centred ``\\n``)."""
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def component_node(name: str) -> str:
    return quote(f"component:{name}")


def activity_port_node(activity: str, port: str) -> str:
    return quote(f"activity:{activity}.{port}")


def dataflow_dot(deployment: Deployment) -> str:
    """The DOT text of the data-flow graph of ``deployment``'s file (see the module), drawn where
    the plan places each part (:attr:`~coco_core.deployment.Deployment.placement` and ``where``)."""
    return "\n".join(_Drawing(deployment).lines()) + "\n"


class _Drawing:
    """One graph being drawn: which process and activity each part is in, and the filters' ids."""

    def __init__(self, deployment: Deployment) -> None:
        self.spec = spec = deployment.spec
        self.placement = deployment.placement
        self.where = deployment.where
        """The host of every activity and component, when the application has several."""
        self.scheduled = {name: activity for activity in spec.activities for name in activity.components}
        self.definitions = {component.name: component for component in spec.components}
        self.activity_ports = {(ref.component, ref.port) for connection in spec.connections
                               for ref in (connection.src, connection.dest) if ref.activity}

    def lines(self) -> Iterator[str]:
        yield f"digraph {quote(self.spec.name or 'application')} {{"
        yield "  rankdir=LR;"
        yield "  compound=true;"
        yield '  node [shape=box, style="rounded,filled", fillcolor=white, fontname="Helvetica", fontsize=11];'
        yield '  edge [fontname="Helvetica", fontsize=9];'
        yield '  graph [fontname="Helvetica", fontsize=12, style=rounded];'
        yield f"  label={quote(f'application {self.spec.name}')}; labelloc=t;"
        hosts: list[str | None] = [host.name for host in self.spec.hosts] or [None]
        for host_index, host in enumerate(hosts):
            body = list(self._host_body(host_index, host))
            if host is None:
                yield from body
                continue
            yield f"  subgraph {quote(f'cluster_host_{host_index}')} {{"
            yield f"    label={quote(f'host {host}')}; style=bold;"
            yield from ("  " + line for line in body)
            yield "  }"
        for index, connection in enumerate(self.spec.connections):
            yield from ("  " + line for line in self._connection(index, connection))
        yield "}"

    def _host_body(self, host_index: int, host: str | None) -> Iterator[str]:
        """The processes of ``host`` (None: the application has one host), each a cluster when there
        are several."""
        children = [name for name, process in self.placement.processes.items() if host is None or process.host == host]
        several = bool(children)
        for index, process in enumerate([LAUNCHER, *children]):
            inner = self._process_body(process, host)
            if not several:
                yield from ("  " + line for line in inner)
                continue
            title = f"process {process or 'launcher'}"
            yield f"  subgraph {quote(f'cluster_process_{host_index}_{index}')} {{"
            yield f"    label={quote(title)}; style=dashed;"
            yield from ("    " + line for line in inner)
            yield "  }"

    def _process_body(self, process: str, host: str | None) -> Iterator[str]:
        for index, activity in enumerate(self.spec.activities):
            if activity.process == process and (host is None or activity.host == host):
                yield from self._activity(index, activity)
        first = host is None or host == self.spec.hosts[0].name  # what no activity runs is the first host's
        for component in self.spec.components:
            if (first and component.name not in self.scheduled
                    and self.placement.process_of(component.name) == process):
                yield from self._component(component)

    def _activity(self, index: int, activity: ActivitySpec) -> Iterator[str]:
        schedule = activity.schedule
        timing = f"periodic {schedule.period_ms:g} ms" if schedule.type == "periodic" and schedule.period_ms else schedule.type
        title = f"activity {activity.name}\n{timing}"
        yield f"subgraph {quote(f'cluster_activity_{index}')} {{"
        yield f"  label={quote(title)}; style=\"rounded,filled\"; fillcolor=\"#eef3fb\";"
        for port in (BEGIN, END):
            if (activity.name, port) in self.activity_ports:
                yield (f"  {activity_port_node(activity.name, port)} [label={quote(port)}, shape=circle, "
                       "fontsize=8, width=0.3, fillcolor=\"#d5e3f5\"];")
        for name in activity.components:
            component = self.definitions.get(name)
            if component is not None:
                yield from ("  " + line for line in self._component(component))
        yield "}"

    def _component(self, component: ComponentSpec) -> Iterator[str]:
        label = f"{component.name}\n({component.task})"
        if not component.peers:
            yield f"{component_node(component.name)} [label={quote(label)}];"
            return
        yield f"subgraph {quote(f'cluster_component_{component.name}')} {{"
        yield f"  label={quote(f'{component.name} and its peers')}; style=\"rounded,dotted\";"
        yield f"  {component_node(component.name)} [label={quote(label)}];"
        for peer in component.peers:
            yield from ("  " + line for line in self._component(peer))
        yield "}"

    def _node(self, ref: PortRef) -> str:
        return activity_port_node(ref.component, ref.port) if ref.activity else component_node(ref.component)

    def _connection(self, index: int, connection: ConnectionSpec) -> Iterator[str]:
        src, dest = self._node(connection.src), self._node(connection.dest)
        between_hosts = self.where is not None and self.where.of_ref(connection.src)[0] != self.where.of_ref(connection.dest)[0]
        crossing = between_hosts or (self.placement.several and self.placement.crosses(connection))
        notes = [word for word, present in (("event", connection.event), ("shared", connection.shared),
                                            ("stamps only", connection.stamps_only),
                                            ("between hosts (DDS)", between_hosts),
                                            ("between processes", crossing and not between_hosts)) if present]
        styles = [word for word, present in (("bold", crossing), ("dashed", connection.stamps_only)) if present]
        style = f", style={quote(','.join(styles))}" if styles else ""
        if connection.filter is None:
            policy = ConnectionPolicy(connection.data, connection.policy, max(1, connection.buffersize))
            label = "\n".join([f"{connection.src.port} -> {connection.dest.port}", str(policy), *notes])
            yield f"{src} -> {dest} [label={quote(label)}{style}];"
            return
        node = quote(f"filter:{index}")
        yield (f"{node} [label={quote(_filter_label(connection.filter, connection.buffersize))}, shape=diamond, "
               "fillcolor=\"#fde9c8\"];")
        before = "\n".join([connection.src.port, *notes])
        after = f"{connection.dest.port}\n{connection.policy.value}"
        yield f"{src} -> {node} [label={quote(before)}{style}];"
        yield f"{node} -> {dest} [label={quote(after)}{style}];"


def _filter_label(spec: FilterSpec, buffersize: int) -> str:
    if spec.type == "PreSignal":
        return f"PreSignal\ntokens={spec.tokens}, buffer {buffersize}"
    if spec.type == "MaxFrequency":
        return f"MaxFrequency\n{spec.hz:g} Hz"
    if spec.type == "Split":
        return f"Split\nby {spec.by}" if spec.by else "Split\nin turn"
    if spec.type == "Cull" and spec.frustum is not None:
        return f"Cull\n{spec.stamp} in {spec.frustum.given}"
    if spec.type == "Cull":
        return f"Cull\n{spec.stamp} meets {' '.join(f'{value:g}' for value in spec.region)}"
    return spec.type
