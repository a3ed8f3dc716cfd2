"""``metadata.yaml``, the file rosbag2 keeps beside the storage files of a bag folder.

Read: any version rosbag2 has written (1 to 9); the fields used are the file list, the storage
identifier and, per topic, type, serialization format, offered QoS profiles and count.
Written: version 9, the format of ROS 2 Jazzy (``offered_qos_profiles`` as a YAML list, policy names
spelt out, ``type_description_hash``, ``ros_distro``), so ``ros2 bag info`` and rosbags accept it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from coco_core.errors import BagError
from coco_core.files import DATA_FILE_LIMIT, read_regular_file

from .qos import dump_profiles, parse_profiles
from .topic import TopicInfo

FILE_NAME = "metadata.yaml"
VERSION = 9
ROS_DISTRO = "jazzy"


@dataclass(frozen=True)
class FileRecord:
    """What metadata.yaml says about one storage file (``files`` entry, version 5 and later)."""

    path: str
    starting_time: int
    duration: int
    message_count: int


@dataclass(frozen=True)
class BagMetadata:
    """The parts of ``rosbag2_bagfile_information`` a reader needs."""

    version: int
    storage_identifier: str
    relative_file_paths: tuple[str, ...]
    starting_time: int
    duration: int
    message_count: int
    topics: tuple[TopicInfo, ...]
    compression_format: str
    compression_mode: str
    ros_distro: str
    custom_data: dict[str, str]
    files: tuple[FileRecord, ...] = ()
    """Per storage file (version 5 and later): what the recorder wrote into each."""


def read_metadata(folder: str | Path) -> BagMetadata | None:
    """The folder's metadata.yaml, or None when there is none; a malformed one is a :class:`BagError`."""
    path = Path(folder) / FILE_NAME
    if not path.is_file():
        return None
    try:
        document = yaml.safe_load(read_regular_file(path, DATA_FILE_LIMIT, "bag metadata").decode("utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
        raise BagError(path, f"cannot read it as YAML: {error}") from None
    info = document.get("rosbag2_bagfile_information") if isinstance(document, dict) else None
    if not isinstance(info, dict):
        raise BagError(path, "expected a mapping 'rosbag2_bagfile_information' at the top level")
    try:
        version = int(info.get("version", 1))
        topics = []
        for entry in info.get("topics_with_message_count") or []:
            topic = entry["topic_metadata"]
            try:
                profiles = parse_profiles(topic.get("offered_qos_profiles"))
            except ValueError:
                profiles = ()  # the channel metadata in the .mcap file has them too
            topics.append(
                TopicInfo(
                    name=str(topic["name"]),
                    type=str(topic["type"]),
                    serialization_format=str(topic.get("serialization_format", "cdr")),
                    offered_qos_profiles=profiles,
                    type_description_hash=str(topic.get("type_description_hash") or ""),
                    message_count=int(entry.get("message_count", 0)),
                )
            )
        return BagMetadata(
            version=version,
            storage_identifier=str(info.get("storage_identifier", "")),
            relative_file_paths=tuple(str(p) for p in info.get("relative_file_paths") or ()),
            starting_time=int((info.get("starting_time") or {}).get("nanoseconds_since_epoch", 0)),
            duration=int((info.get("duration") or {}).get("nanoseconds", 0)),
            message_count=int(info.get("message_count", 0)),
            topics=tuple(topics),
            compression_format=str(info.get("compression_format") or ""),
            compression_mode=str(info.get("compression_mode") or ""),
            ros_distro=str(info.get("ros_distro") or ""),
            custom_data={str(k): str(v) for k, v in (info.get("custom_data") or {}).items()},
            files=tuple(
                FileRecord(
                    path=str(entry["path"]),
                    starting_time=int((entry.get("starting_time") or {}).get("nanoseconds_since_epoch", 0)),
                    duration=int((entry.get("duration") or {}).get("nanoseconds", 0)),
                    message_count=int(entry.get("message_count", 0)),
                )
                for entry in info.get("files") or ()
            ),
        )
    except (KeyError, TypeError, ValueError, AttributeError) as error:
        raise BagError(path, f"unexpected content in rosbag2_bagfile_information: {error!r}") from None


def metadata_document(
    files: list[FileRecord],
    topics: list[TopicInfo],
    custom_data: dict[str, str] | None = None,
) -> dict[str, Any]:
    """The version 9 ``metadata.yaml`` document of a bag made of these files and topics."""
    counted = [f for f in files if f.message_count]
    start = min((f.starting_time for f in counted), default=0)
    end = max((f.starting_time + f.duration for f in counted), default=0)

    def time(ns: int) -> dict[str, int]:
        return {"nanoseconds_since_epoch": ns}

    return {
        "rosbag2_bagfile_information": {
            "version": VERSION,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": end - start},
            "starting_time": time(start),
            "message_count": sum(f.message_count for f in files),
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": t.name,
                        "type": t.type,
                        "serialization_format": t.serialization_format,
                        "offered_qos_profiles": dump_profiles(t.offered_qos_profiles),
                        "type_description_hash": t.type_description_hash,
                    },
                    "message_count": t.message_count,
                }
                for t in topics
            ],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [f.path for f in files],
            "files": [
                {
                    "path": f.path,
                    "starting_time": time(f.starting_time),
                    "duration": {"nanoseconds": f.duration},
                    "message_count": f.message_count,
                }
                for f in files
            ],
            "custom_data": dict(custom_data or {}),
            "ros_distro": ROS_DISTRO,
        }
    }


def dump_metadata(document: dict[str, Any]) -> str:
    return yaml.safe_dump(document, default_flow_style=False, sort_keys=False)


def write_metadata(folder: str | Path, document: dict[str, Any]) -> Path:
    """Write metadata.yaml atomically (a reader never sees half a file)."""
    path = Path(folder) / FILE_NAME
    temporary = path.with_name(f".{FILE_NAME}.tmp")
    temporary.write_text(dump_metadata(document), encoding="utf-8")
    os.replace(temporary, path)
    return path
