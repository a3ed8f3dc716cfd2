"""The application as it is being read, before the checks that need all of it.

Files are read in document order (an included file where its ``<include>`` stands), but a
connection may name a component defined further down or in another file, and a ``type="file"``
attribute is searched in resource paths declared anywhere. So the element readers only append to
a :class:`Draft`, noting what must be checked later; :mod:`.references` checks it as a whole.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..errors import Location
from ..model import (
    ActivitySpec, AttributeSpec, ComponentSpec, CompositeSpec, ConnectionSpec, HostSpec, LogSpec, PortRef,
    ProcessSpec, TopicMirrorSpec,
)

if TYPE_CHECKING:
    from .farm import FarmDraft
    from .transforms import TransformsDraft


@dataclass
class Scheduled:
    """One component named by an activity or pipeline, and where."""

    component: str
    activity: str
    location: Location


@dataclass
class FileAttribute:
    """A ``type="file"`` attribute and the directory of the file that holds it."""

    spec: AttributeSpec
    directory: str


@dataclass
class Draft:
    """Everything read so far, in document order."""

    components: list[ComponentSpec] = field(default_factory=list)
    connections: list[ConnectionSpec] = field(default_factory=list)
    activities: list[ActivitySpec] = field(default_factory=list)
    processes: list[ProcessSpec] = field(default_factory=list)
    hosts: list[HostSpec] = field(default_factory=list)
    paths: list[str] = field(default_factory=list)
    log: LogSpec | None = None
    scheduled: list[Scheduled] = field(default_factory=list)
    file_attributes: list[FileAttribute] = field(default_factory=list)
    pipeline_inputs: list[PortRef] = field(default_factory=list)
    """The input port of each pipeline's first stage: connections into it wake the pipeline."""
    transforms: TransformsDraft | None = None
    """The ``<transforms>`` sections read so far, merged; None while there is none."""
    farms: list[FarmDraft] = field(default_factory=list)
    """Farms read so far, expanded once every component is defined (see :mod:`.farm`)."""
    ports: dict[str, PortRef] = field(default_factory=dict)
    """The exposed ports a composite file declares (``<ports>``), by name, each the inner port it
    stands for (see :mod:`.composite`)."""
    composites: list[CompositeSpec] = field(default_factory=list)
    """The composite instances read so far, with scoped names."""
    topics: list[TopicMirrorSpec] = field(default_factory=list)
    """The ``<topic>`` mirrors read so far (see :mod:`.topics`)."""
    activity_count: int = 0
    pipeline_count: int = 0
    farm_count: int = 0
