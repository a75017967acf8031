"""The live view (issue 14): a Foxglove WebSocket client connected to fpr_experiments.live_view sees the report
MCAP's topics advertised with their ros2msg schemas, subscribes, and receives the very CDR bytes published on the
ROS graph (decoded back to the message). Loopback only."""

from __future__ import annotations

import json
import struct
import time

import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("foxglove")
websockets_sync = pytest.importorskip("websockets.sync.client")

from fpr_experiments.live_view import LiveView  # noqa: E402
from fpr_experiments.recording import Recorder, recorded_topics  # noqa: E402
from geometry_msgs.msg import TransformStamped  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


def _receive_json(ws, op: str, timeout: float = 5.0) -> dict:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        frame = ws.recv(timeout=max(end - time.monotonic(), 0.01))
        if isinstance(frame, str):
            message = json.loads(frame)
            if message.get("op") == op:
                return message
    raise TimeoutError(op)


def test_a_websocket_client_sees_the_graph_live():
    topics = recorded_topics(3)
    view = LiveView(topics, port=0)
    context = rclpy.Context()
    rclpy.init(context=context)
    recorder = None
    try:
        recorder = Recorder(context, topics, use_sim_time=False, live_view=view)
        publisher_node = rclpy.create_node("tf_publisher", context=context)
        publisher = publisher_node.create_publisher(TFMessage, "/tf", 10)
        with websockets_sync.connect(view.url(), subprotocols=SUBPROTOCOLS, open_timeout=5) as ws:
            _receive_json(ws, "serverInfo")
            advertised = {}
            end = time.monotonic() + 5.0
            while len(advertised) < len(topics) and time.monotonic() < end:
                advertised.update({c["topic"]: c for c in _receive_json(ws, "advertise")["channels"]})
            assert set(advertised) == {t.name for t in topics}  # the same topics as the MCAP
            tf = advertised["/tf"]
            assert (tf["encoding"], tf["schemaName"], tf["schemaEncoding"]) == ("cdr", "tf2_msgs/msg/TFMessage",
                                                                                 "ros2msg")
            assert "geometry_msgs/TransformStamped" in tf["schema"]
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": tf["id"]}]}))
            message = TFMessage(transforms=[TransformStamped(child_frame_id="uav1/base_link")])
            message.transforms[0].header.frame_id = "world"
            message.transforms[0].transform.translation.x = 1.25
            received = None
            end = time.monotonic() + 10.0
            while received is None and time.monotonic() < end:
                publisher.publish(message)
                time.sleep(0.05)
                try:
                    frame = ws.recv(timeout=0.2)
                except TimeoutError:
                    continue
                if isinstance(frame, bytes) and frame[0] == 0x01:  # MessageData
                    subscription, _log_time = struct.unpack_from("<IQ", frame, 1)
                    assert subscription == 7
                    received = deserialize_message(frame[13:], TFMessage)
            assert received is not None, "no /tf message reached the WebSocket client"
            (transform,) = received.transforms
            assert (transform.header.frame_id, transform.child_frame_id) == ("world", "uav1/base_link")
            assert transform.transform.translation.x == 1.25
            assert view.logged >= 1
        publisher_node.destroy_node()
    finally:
        if recorder is not None:
            recorder.stop()
        view.stop()
        rclpy.shutdown(context=context)


def test_the_live_view_binds_the_loopback_only():
    with pytest.raises(ValueError, match="loopback"):
        LiveView(recorded_topics(3), port=0, host="0.0.0.0")
