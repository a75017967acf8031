"""ROS 2 MCAP log writer of the experiment reports: files Foxglove and ``ros2 bag`` (rosbag2_storage_mcap) read.

The MCAP "ros2" profile, as rosbag2 writes it:

- header profile ``ros2``;
- one schema per message type, named ``pkg/msg/Type``, encoding ``ros2msg``, data = the complete message
  definition: the type's ``.msg`` text, then for every field type it depends on (recursively, each once)
  a line of 80 ``=``, a line ``MSG: pkg/Type`` and that type's ``.msg`` text (rosbag2's
  ``LocalMessageDefinitionSource``, documented in rosbag2's docs/message_definition_encoding.md);
- channels with message encoding ``cdr``; message data = ``rclpy.serialization.serialize_message``.

Log and publish times are the simulation time [ns] of the message: its ``header.stamp``
(``rosgraph_msgs/Clock``: its ``clock``), unless the caller gives one.
"""

from __future__ import annotations

import os
import re
import sys
from typing import Any

from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import Writer
from rclpy.serialization import serialize_message

#: the delimiter line between the definitions of a complete ros2msg definition
DELIMITER = "=" * 80
#: field types of a .msg text (rosbag2's MSG_FIELD_TYPE_REGEX): "pkg/Type" in "pkg/Type[] name", "uint8 X=1"
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
               "uint32", "int64", "uint64", "string", "wstring"}


def type_name(msg_type: type) -> str:
    """``pkg/msg/Type`` of a generated rclpy message class."""
    return f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"


def _share_dirs(package: str) -> list[str]:
    """Where ``share/<package>`` may be: the ament index, this Python's prefix (the venv with the ROS wheels),
    and above the package's Python module."""
    dirs = []
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(get_package_share_directory(package))
    except Exception:  # noqa: BLE001 - not in the ament index (ROS wheels in a venv)
        pass
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) + [sys.prefix]:
        if prefix:
            dirs.append(os.path.join(prefix, "share", package))
    module = sys.modules.get(package)
    if module is not None and getattr(module, "__file__", None):
        folder = os.path.dirname(os.path.abspath(module.__file__))
        for _ in range(6):
            folder = os.path.dirname(folder)
            dirs.append(os.path.join(folder, "share", package))
    return dirs


def msg_text(name: str) -> str:
    """The ``.msg`` file text of ``pkg/Type`` or ``pkg/msg/Type``."""
    parts = name.split("/")
    package, type_ = parts[0], parts[-1]
    candidates = [os.path.join(d, "msg", f"{type_}.msg") for d in _share_dirs(package)]
    for path in candidates:
        if os.path.isfile(path):
            with open(path, encoding="utf-8") as stream:
                return stream.read()
    raise FileNotFoundError(f"no .msg definition of {name}; looked in: {candidates}")


def _dependencies(text: str, package: str) -> list[str]:
    found = set()
    for match in _FIELD_TYPE.finditer(text):
        field_type = match.group(1)
        if field_type in _PRIMITIVES:
            continue
        found.add(field_type if "/" in field_type else f"{package}/{field_type}")
    return sorted(found)


def message_definition(msg_type: type | str) -> str:
    """Complete ``ros2msg`` definition of a message type (class or ``pkg/msg/Type``), as rosbag2 stores it:
    depth first, each dependency once, in sorted order per level."""
    root = msg_type if isinstance(msg_type, str) else type_name(msg_type)
    seen: set[str] = set()

    def expand(name: str) -> str:
        text = msg_text(name)
        for dependency in _dependencies(text, name.split("/")[0]):
            if dependency not in seen:
                seen.add(dependency)
                text += f"\n{DELIMITER}\nMSG: {dependency}\n" + expand(dependency)
        return text

    return expand(root)


def stamp_ns(msg: Any) -> int:
    """Simulation time [ns] of a message: ``header.stamp``, or ``clock`` of a rosgraph_msgs/Clock."""
    stamp = msg.header.stamp if hasattr(msg, "header") else msg.clock
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


class RosMcapWriter:
    """Writes ROS 2 messages to an MCAP file (see the module doc). Register every topic first (so a missing
    definition fails before a long flight), then write; ``close()`` (or the context manager) finishes the
    file (summary, indexes)."""

    def __init__(self, path: str, metadata: dict[str, str] | None = None) -> None:
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        self.path = path
        self._stream = open(path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._stream)
        self._writer.start(profile=Profile.ROS2, library="fpr_experiments (mcap python)")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, type]] = {}
        self.counts: dict[str, int] = {}
        if metadata:
            self._writer.add_metadata("fpr_experiment", {k: str(v) for k, v in metadata.items()})

    def add_channel(self, topic: str, msg_type: type) -> int:
        """Register ``topic`` carrying ``msg_type`` (a generated message class); returns the channel id."""
        if topic in self._channels:
            return self._channels[topic][0]
        name = type_name(msg_type)
        if name not in self._schemas:
            self._schemas[name] = self._writer.register_schema(
                name=name, encoding=SchemaEncoding.ROS2, data=message_definition(name).encode("utf-8"))
        channel_id = self._writer.register_channel(topic=topic, message_encoding=MessageEncoding.CDR,
                                                   schema_id=self._schemas[name])
        self._channels[topic] = (channel_id, msg_type)
        self.counts[topic] = 0
        return channel_id

    def write(self, topic: str, msg: Any, log_time_ns: int | None = None) -> None:
        """Serialize ``msg`` (CDR) and add it to ``topic`` (registered on first use) at ``log_time_ns``
        (default: the message's own stamp)."""
        if topic not in self._channels:
            self.add_channel(topic, type(msg))
        channel_id, msg_type = self._channels[topic]
        if not isinstance(msg, msg_type):
            raise TypeError(f"{topic}: {type(msg).__name__} on a {msg_type.__name__} channel")
        time_ns = stamp_ns(msg) if log_time_ns is None else int(log_time_ns)
        self._writer.add_message(channel_id=channel_id, log_time=time_ns, publish_time=time_ns,
                                 data=serialize_message(msg), sequence=self.counts[topic])
        self.counts[topic] += 1

    def write_serialized(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Add an already CDR-serialized message (as a raw subscription delivers it) to a registered ``topic``."""
        channel_id, _ = self._channels[topic]
        self._writer.add_message(channel_id=channel_id, log_time=int(log_time_ns), publish_time=int(log_time_ns),
                                 data=bytes(data), sequence=self.counts[topic])
        self.counts[topic] += 1

    def close(self) -> None:
        if self._stream.closed:
            return
        self._writer.finish()
        self._stream.close()

    def __enter__(self) -> RosMcapWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
