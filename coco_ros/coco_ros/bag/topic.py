"""A topic of a rosbag2 bag, as metadata.yaml declares it and as the reader finds it."""

from __future__ import annotations

from dataclasses import dataclass

from .qos import Qos


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag: what ``metadata.yaml`` declares of it, and what a reader found in the
    storage files (the schema's definition, the channel's QoS). One description for both, so that
    the reader's view is the declared one completed, and the writer declares what it wrote."""

    name: str
    type: str
    """``pkg/msg/Name``."""
    serialization_format: str
    """``cdr`` for every ROS 2 bag."""
    offered_qos_profiles: tuple[Qos, ...]
    """The QoS the recorded publishers offered (from the channel, else from metadata.yaml)."""
    message_count: int
    """Declared in metadata.yaml; from a reader, the readable messages (in a damaged bag, fewer)."""
    definition: str = ""
    """The complete message definition stored in the bag's schema."""
    definition_encoding: str = ""
    type_description_hash: str = ""

    @property
    def latched(self) -> bool:
        """Whether a late subscriber would have received this topic's last messages.

        True when every recorded publisher offered TRANSIENT_LOCAL durability, as rosbag2 decides
        its playback QoS; a ``/tf_static`` recorded without QoS information (old bags) counts too.
        """
        if not self.offered_qos_profiles:
            return self.name == "/tf_static" or self.name.endswith("/tf_static")
        return all(profile.transient_local for profile in self.offered_qos_profiles)
