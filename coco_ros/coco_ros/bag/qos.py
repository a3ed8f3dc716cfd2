"""QoS profiles as rosbag2 stores them: ``offered_qos_profiles``, the profiles the publishers offered.

rosbag2 keeps them twice: in ``metadata.yaml`` (a YAML list since metadata version 9, a YAML *string*
holding that list before) and in the ``offered_qos_profiles`` entry of each MCAP channel's metadata
(always a string). Version 9 spells policies with rmw's names (``keep_last``, ``transient_local``);
older bags use rmw's enum numbers. Both are read here; version 9 is written.

A :class:`Qos` is a frozen value independent of rclpy, so bags can be read without a ROS context;
:meth:`Qos.to_rclpy` gives the ``rclpy.qos.QoSProfile`` a replay publisher needs.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Iterable, Sequence

import yaml
from coco_core.errors import BagFormatError

# rmw enum numbers (rmw/types.h) -> rmw's string names (rmw/qos_string_conversions.c).
_HISTORY = {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"}
_RELIABILITY = {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"}
_DURABILITY = {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"}
_LIVELINESS = {
    0: "system_default",
    1: "automatic",
    2: "manual_by_node",  # deprecated in rmw, still found in old bags
    3: "manual_by_topic",
    4: "unknown",
    5: "best_available",
}

Time = tuple[int, int]
"""A QoS duration as rmw stores it: (seconds, nanoseconds)."""

UNSPECIFIED: Time = (0, 0)
INFINITE: Time = (9223372036, 854775807)
"""RMW_DURATION_INFINITE: 2**63 - 1 nanoseconds."""

# What Foxy-era RMW implementations wrote for "infinite"; rosbag2 maps them to INFINITE on reading.
_FOXY_INFINITE = {(9223372036, 854775807), (0x7FFFFFFF, 0xFFFFFFFF), (0x7FFFFFFF, 0x7FFFFFFF)}


@dataclass(frozen=True)
class Qos:
    """One offered QoS profile, with rmw's policy names."""

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline: Time = UNSPECIFIED
    lifespan: Time = UNSPECIFIED
    liveliness: str = "automatic"
    liveliness_lease_duration: Time = UNSPECIFIED
    avoid_ros_namespace_conventions: bool = False

    @property
    def transient_local(self) -> bool:
        """Whether a late subscriber gets the publisher's last messages (latched, like /tf_static)."""
        return self.durability == "transient_local"

    def to_dict(self) -> dict[str, Any]:
        """The rosbag2 metadata version 9 mapping of this profile."""
        return {
            "history": self.history,
            "depth": self.depth,
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": {"sec": self.deadline[0], "nsec": self.deadline[1]},
            "lifespan": {"sec": self.lifespan[0], "nsec": self.lifespan[1]},
            "liveliness": self.liveliness,
            "liveliness_lease_duration": {
                "sec": self.liveliness_lease_duration[0],
                "nsec": self.liveliness_lease_duration[1],
            },
            "avoid_ros_namespace_conventions": self.avoid_ros_namespace_conventions,
        }

    @classmethod
    def from_dict(cls, item: dict[str, Any]) -> Qos:
        """Read one profile in either spelling (version 9 names or older enum numbers)."""
        if not isinstance(item, dict):
            raise BagFormatError(f"expected a QoS profile mapping, got {item!r}")
        try:
            return cls(
                history=_policy(item["history"], _HISTORY, "history"),
                depth=int(item["depth"]),
                reliability=_policy(item["reliability"], _RELIABILITY, "reliability"),
                durability=_policy(item["durability"], _DURABILITY, "durability"),
                deadline=_time(item["deadline"], "deadline"),
                lifespan=_time(item["lifespan"], "lifespan"),
                liveliness=_policy(item["liveliness"], _LIVELINESS, "liveliness"),
                liveliness_lease_duration=_time(
                    item["liveliness_lease_duration"], "liveliness_lease_duration"
                ),
                avoid_ros_namespace_conventions=bool(item.get("avoid_ros_namespace_conventions", False)),
            )
        except KeyError as missing:
            raise BagFormatError(f"QoS profile without the {missing} field: {item!r}") from None

    def to_rclpy(self):  # -> rclpy.qos.QoSProfile (rclpy imported lazily)
        """The rclpy profile a publisher replaying this topic should offer."""
        from rclpy.duration import Duration
        from rclpy.qos import (
            DurabilityPolicy,
            HistoryPolicy,
            LivelinessPolicy,
            QoSProfile,
            ReliabilityPolicy,
        )

        def duration(value: Time) -> Duration:
            return Duration(seconds=value[0], nanoseconds=value[1])

        def policy(enum: Any, name: str) -> Any:
            # "unknown" and names rclpy lacks (manual_by_node) fall back to the system default.
            return enum.__members__.get(name.upper(), enum.SYSTEM_DEFAULT)

        history = policy(HistoryPolicy, self.history)
        return QoSProfile(
            history=history,
            depth=max(self.depth, 1) if history == HistoryPolicy.KEEP_LAST else self.depth,
            reliability=policy(ReliabilityPolicy, self.reliability),
            durability=policy(DurabilityPolicy, self.durability),
            deadline=duration(self.deadline),
            lifespan=duration(self.lifespan),
            liveliness=policy(LivelinessPolicy, self.liveliness),
            liveliness_lease_duration=duration(self.liveliness_lease_duration),
            avoid_ros_namespace_conventions=self.avoid_ros_namespace_conventions,
        )

    @classmethod
    def from_rclpy(cls, profile: Any) -> Qos:
        """A profile from an ``rclpy.qos.QoSProfile`` (e.g. what ``get_publishers_info_by_topic`` offers)."""

        def time(duration: Any) -> Time:
            nanoseconds = int(duration.nanoseconds)
            return (nanoseconds // 1_000_000_000, nanoseconds % 1_000_000_000)

        return cls(
            history=profile.history.name.lower(),
            depth=int(profile.depth),
            reliability=profile.reliability.name.lower(),
            durability=profile.durability.name.lower(),
            deadline=time(profile.deadline),
            lifespan=time(profile.lifespan),
            liveliness=profile.liveliness.name.lower(),
            liveliness_lease_duration=time(profile.liveliness_lease_duration),
            avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
        )


TF_STATIC = Qos(depth=1, durability="transient_local")
"""What tf2_ros' StaticTransformBroadcaster offers on /tf_static."""


def parse_profiles(value: str | Sequence[dict[str, Any]] | None) -> tuple[Qos, ...]:
    """Profiles from a metadata.yaml entry or a channel's metadata string ('' or None: none)."""
    if value is None or value == "":
        return ()
    if isinstance(value, str):
        try:
            value = yaml.safe_load(value)
        except yaml.YAMLError as error:
            raise BagFormatError(f"offered_qos_profiles is not valid YAML: {error}") from None
        if value is None:
            return ()
    if not isinstance(value, list):
        raise BagFormatError(f"expected offered_qos_profiles to be a list of profiles, got {value!r}")
    return tuple(Qos.from_dict(item) for item in value)


def dump_profiles(profiles: Iterable[Qos]) -> list[dict[str, Any]]:
    """The metadata.yaml (version 9) form: a list of mappings."""
    return [profile.to_dict() for profile in profiles]


def dump_profiles_string(profiles: Iterable[Qos]) -> str:
    """The MCAP channel metadata form: the same list, as a YAML string."""
    items = dump_profiles(profiles)
    if not items:
        return ""
    return yaml.safe_dump(items, default_flow_style=False, sort_keys=False).rstrip("\n")


def for_replay(profiles: Sequence[Qos], depth: int | None = None) -> Qos:
    """The profile to offer when replaying a topic recorded with these offers.

    Like rosbag2's ``adapt_offer_to_recorded_offers``: when every recorded publisher offered the same
    compatibility-relevant policies, offer those; otherwise, or with no record at all, the default
    profile. The history is the recorded one too (the deepest KEEP_LAST of the offers), so a late
    subscriber of a transient-local topic gets what the recording's publishers would have kept for
    it (one ``/amcl_pose`` at depth 1, not the replay's last ten); ``depth`` overrides it (KEEP_LAST
    ``depth``). A recorded history rmw could not name (``unknown``, or KEEP_LAST 0 from old bags)
    becomes KEEP_LAST 10, rclpy's default.
    """
    if not profiles:
        return replace(Qos(), depth=depth or Qos().depth)
    first = profiles[0]

    def key(qos: Qos) -> tuple:
        return (qos.reliability, qos.durability, qos.deadline, qos.liveliness, qos.liveliness_lease_duration)

    chosen = first if all(key(profile) == key(first) for profile in profiles) else Qos()
    if depth is not None:
        return replace(chosen, history="keep_last", depth=depth)
    if chosen is not first:
        return chosen
    if all(profile.history == "keep_all" for profile in profiles):
        return replace(chosen, history="keep_all", depth=0)
    recorded = max((p.depth for p in profiles if p.history == "keep_last"), default=0)
    return replace(chosen, history="keep_last", depth=recorded or Qos().depth)


def _policy(value: Any, names: dict[int, str], field: str) -> str:
    if isinstance(value, bool):
        raise BagFormatError(f"QoS {field}: expected a policy name or number, got {value!r}")
    if isinstance(value, int):
        return names.get(value, "unknown")
    if isinstance(value, str):
        name = value.strip().lower()
        if name in names.values():
            return name
        valid = ", ".join(sorted(set(names.values())))
        raise BagFormatError(f"QoS {field}: expected one of {valid}, got {value!r}")
    raise BagFormatError(f"QoS {field}: expected a policy name or number, got {value!r}")


def _time(value: Any, field: str) -> Time:
    try:
        time = (int(value["sec"]), int(value["nsec"]))
    except (TypeError, KeyError, ValueError):
        raise BagFormatError(f"QoS {field}: expected {{sec: int, nsec: int}}, got {value!r}") from None
    return INFINITE if time in _FOXY_INFINITE else time
