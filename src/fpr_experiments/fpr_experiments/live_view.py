"""Live view of a running graph in the Foxglove app over WebSocket (issue 14), with the report MCAP's topics.

:class:`LiveView` serves the topics the experiment records (:func:`fpr_experiments.recording.recorded_topics`)
through the Foxglove SDK's WebSocket server (``foxglove-sdk``, the maintained implementation of the Foxglove
WebSocket protocol; weighed against ``foxglove_bridge``, a C++ ROS package not in the PyPI wheels this project
builds on, and a hand-written server, which would re-implement the protocol). Each channel carries the CDR bytes
the recorder already receives (raw subscriptions: no deserialisation) with the same ``ros2msg`` schema text the
MCAP embeds (:func:`fpr_experiments.mcap_log.message_definition`), so the app decodes the live stream exactly
as it decodes the report's MCAP and the shipped layout (config/viz/fpr_foxglove_layout.json) works on both.

Network: the server binds ``127.0.0.1`` only. Under ``scripts/isolated.sh`` (every run here) only clients in the
same network namespace reach it; on a workstation run the experiment without isolation (a real Jazzy install) and
open ``ws://localhost:<port>`` in Foxglove (Open connection -> Foxglove WebSocket).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from fpr_experiments.mcap_log import message_definition, type_name

DEFAULT_PORT = 8765


class LiveView:
    """A Foxglove WebSocket server with one channel per topic; :meth:`log` forwards one serialized message."""

    def __init__(self, topics: Iterable[Any], port: int = DEFAULT_PORT, host: str = "127.0.0.1",
                 name: str = "fpr") -> None:
        import foxglove
        from foxglove import Channel, Schema

        if host not in ("127.0.0.1", "localhost", "::1"):
            raise ValueError(f"live view host {host!r}: only the loopback interface is allowed (network safety)")
        self._context = foxglove.Context()
        self.server = foxglove.start_server(name=name, host=host, port=port, context=self._context)
        self.channels = {}
        for topic in topics:
            schema = Schema(name=type_name(topic.msg_type), encoding="ros2msg",
                            data=message_definition(topic.msg_type).encode())
            self.channels[topic.name] = Channel(topic.name, message_encoding="cdr", schema=schema,
                                                context=self._context)
        self.logged = 0

    @property
    def port(self) -> int:
        return int(self.server.port)

    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    def log(self, topic: str, data: bytes, log_time_ns: int | None = None) -> None:
        channel = self.channels.get(topic)
        if channel is not None:
            channel.log(bytes(data), log_time=log_time_ns)
            self.logged += 1

    def stop(self) -> None:
        self.server.stop()


__all__ = ["DEFAULT_PORT", "LiveView"]
