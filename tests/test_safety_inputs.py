"""Safety (issue 12): finite but absurd inputs are refused, not flown. The whole simulated swarm (fpr_experiments'
deterministic in-process runner, the ``comm_loss`` experiment's graph without its link outage: take-off from the
ground to a 2 m hover, mode C, emulated cameras) hovers while an intruder node publishes, one after the other for
1 s each with 2 s to settle between:

- A: ``/fpr/teleop`` with legs 150°, roll 80° and every other field 1e9 (alternating with the real teleop);
- B: ``/fpr/uav2/setpoint`` with 1e9 N (alternating with UAV 2's controller);
- C: a forged ζ claiming ``uav_id`` 2 on ``/fpr/info`` with a velocity of 1e3 m/s (a second publisher);
- D: ``/fpr/uav2/imu`` with body rates of 1e9 rad/s;
- E: a burst of forged marker detections on ``/fpr/uav2/marker``, consistent among themselves, 20 cm / 20° off.

Asserted on the ground truth and on every SET_ATTITUDE_TARGET the emulated PX4s receive: the platform's roll and
pitch stay under 10°, no UAV is commanded a thrust above what it flew with in the clean hover before (×1.5, and
never above full thrust), and each refusal is said in the log (at most 10 lines per kind: rate-limited). Measured
before the guards (main at ba0b218): the absurd teleop alone flipped the robot (roll 180°, pitch 87°).
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np
import pytest
from fpr_experiments.catalog import load_experiment
from fpr_experiments.graph import describe_graph
from fpr_experiments.inprocess import InProcessGraph
from fpr_experiments.recording import flight_record, recorded_topics
from fpr_experiments.resources import SCENARIOS
from fpr_experiments.runner import graph_options

EXPERIMENT = "comm_loss"
CLEAN = (9.0, 12.0)  # [s] hover before any injection: the reference thrusts
WINDOWS = {"teleop": (12.0, 13.0), "setpoint": (15.0, 16.0), "info": (18.0, 19.0), "imu": (21.0, 22.0),
           "marker": (24.0, 25.0)}
END = 28.0
ATTITUDE_LIMIT = math.radians(10.0)


class Intruder:
    """Publishes the absurd inputs from inside the graph's context (an ordinary ROS publisher: nothing special)."""

    def __init__(self, swarm: InProcessGraph) -> None:
        import rclpy
        from geometry_msgs.msg import Quaternion
        from rclpy.parameter import Parameter
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import Imu

        from fpr_msgs.msg import AttitudeThrustSetpoint, InformationVector, MarkerDetection, TeleopCommand

        self.node = rclpy.create_node("intruder", context=swarm.context,
                                      parameter_overrides=[Parameter("use_sim_time", value=True)])
        self.swarm = swarm
        self.types = {"teleop": TeleopCommand, "setpoint": AttitudeThrustSetpoint, "info": InformationVector,
                      "imu": Imu, "marker": MarkerDetection, "quat": Quaternion}
        self.pubs = {
            "teleop": self.node.create_publisher(TeleopCommand, "/fpr/teleop", 10),
            "setpoint": self.node.create_publisher(AttitudeThrustSetpoint, "/fpr/uav2/setpoint", 10),
            "info": self.node.create_publisher(InformationVector, "/fpr/info", 10),
            "imu": self.node.create_publisher(Imu, "/fpr/uav2/imu", qos_profile_sensor_data),
            "marker": self.node.create_publisher(MarkerDetection, "/fpr/uav2/marker", qos_profile_sensor_data),
        }
        self.last_marker = None
        self.count = {k: 0 for k in self.pubs}

    def stamp(self):
        from builtin_interfaces.msg import Time

        t = self.swarm.sim_time
        return Time(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)) % 1_000_000_000)

    def publish(self, kind: str) -> None:
        msg = self.types[kind]()
        if kind == "teleop":
            msg.header.stamp = self.stamp()
            msg.mode = msg.MODE_FLY
            msg.leg_angles = [math.radians(150.0)] * 3
            msg.roll = math.radians(80.0)
            msg.pitch = 1e9
            msg.platform_velocity.x = msg.platform_velocity.y = msg.platform_velocity.z = 1e9
            msg.yaw_rate = msg.roll_rate = msg.pitch_rate = 1e9
            msg.leg_rates = [1e9] * 3
        elif kind == "setpoint":
            msg.header.stamp = self.stamp()
            msg.uav_id = 2
            msg.attitude.w, msg.attitude.x, msg.attitude.y, msg.attitude.z = 1.0, 0.0, 0.0, 0.0
            msg.thrust = 1e9
        elif kind == "info":
            msg.header.stamp = self.stamp()
            msg.header.frame_id = "flat_platform"
            msg.uav_id = 2
            msg.leg_angle = math.radians(60.0)
            msg.velocity.x = 1e3
            msg.attitude.w = 1.0
            msg.thrust = 8.0
            msg.valid = True
        elif kind == "imu":
            msg.header.stamp = self.stamp()
            msg.header.frame_id = "uav2/base_link"
            msg.orientation.w = 1.0
            msg.angular_velocity.x = msg.angular_velocity.y = msg.angular_velocity.z = 1e9
            msg.linear_acceleration.z = 9.81
        elif kind == "marker":
            if self.last_marker is None:
                return
            forged = self.last_marker
            forged.header.stamp = self.stamp()
            forged.pose.position.x += 0.2  # 20 cm off, and 20° about the camera's optical axis
            half = math.radians(20.0) / 2.0
            q = forged.pose.orientation
            w, x, y, z = q.w, q.x, q.y, q.z
            c, s = math.cos(half), math.sin(half)
            q.w, q.x, q.y, q.z = c * w - s * z, c * x + s * y, c * y - s * x, c * z + s * w
            msg = forged
        self.pubs[kind].publish(msg)
        self.count[kind] += 1


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    log_path = tmp_path_factory.mktemp("safety") / "nodes.log"
    saved_stderr = os.dup(2)  # the nodes log through rcutils to fd 2: keep it for the log-line checks
    log_file = open(log_path, "w")  # noqa: SIM115 - closed below, after fd 2 is restored
    os.dup2(log_file.fileno(), 2)
    try:
        yield from _fly()
    finally:
        os.dup2(saved_stderr, 2)
        os.close(saved_stderr)
        log_file.close()


@pytest.fixture(scope="module")
def node_log(flight, tmp_path_factory) -> str:
    return next(tmp_path_factory.getbasetemp().glob("safety*/nodes.log")).read_text()


def _fly():
    experiment = load_experiment(EXPERIMENT)
    variant = experiment.variants[0]
    options = graph_options(experiment, variant, SCENARIOS.resolve(experiment.scenario), "emulated", 3,
                            realism="ideal")  # the nodes' input guards under test, on the plant they model exactly
    options = dataclasses.replace(options, info_link=False)  # the hover of comm_loss, without its link outage
    specs = describe_graph(options)
    with InProcessGraph(specs, recorded_topics(3)) as swarm:
        swarm.wait_for_discovery()
        intruder = Intruder(swarm)
        received = {i: [] for i in range(3)}  # (sim time, normalized thrust) of every SET_ATTITUDE_TARGET
        for i, emulator in enumerate(swarm.simulator.sim.emulators):
            original = emulator._handle

            def spy(msg, address, i=i, original=original, emulator=emulator) -> None:
                if msg.get_type() == "SET_ATTITUDE_TARGET":
                    received[i].append((emulator.time, float(msg.thrust)))
                original(msg, address)

            emulator._handle = spy
        markers = swarm.recorder  # the last genuine detection of UAV 2, to forge from
        period = 0.02
        next_publish = 0.0
        while swarm.sim_time < END:
            swarm.run_until(lambda due=next_publish: swarm.sim_time >= due, wall_timeout=60.0)
            next_publish = swarm.sim_time + period
            t = swarm.sim_time
            for kind, (start, end) in WINDOWS.items():
                if kind == "marker" and t < start:
                    intruder.last_marker = markers.latest("/fpr/uav2/marker")
                if start <= t < end:
                    intruder.publish(kind)
        assert swarm.wait_for_recorder()
        recording = swarm.recorder.snapshot()
        record = flight_record(recording, 3, experiment=EXPERIMENT, sim_time=swarm.sim_time)
        yield {"record": record, "received": {i: np.array(v) for i, v in received.items()},
               "errors": list(swarm.errors), "intruder": dict(intruder.count),
               "bridges": [swarm.node(f"/fpr/uav{i}/px4_bridge") for i in (1, 2, 3)]}


def test_every_intrusion_was_sent(flight):
    assert flight["errors"] == []
    assert all(count >= 40 for count in flight["intruder"].values()), flight["intruder"]


def test_the_platform_stays_within_10_degrees(flight):
    truth = flight["record"].truth
    airborne = truth.t >= CLEAN[0]
    worst = np.degrees(np.abs(truth.rpy[airborne, :2]).max(axis=0))
    assert np.all(np.abs(truth.rpy[airborne, :2]) < ATTITUDE_LIMIT), f"max |roll|, |pitch| = {worst} deg"


@pytest.mark.parametrize("kind", list(WINDOWS))
def test_no_absurd_thrust_reaches_mavlink(flight, kind):
    start, end = WINDOWS[kind]
    for i, samples in flight["received"].items():
        t, thrust = samples[:, 0], samples[:, 1]
        clean = thrust[(t >= CLEAN[0]) & (t < CLEAN[1])]
        during = thrust[(t >= start) & (t < end + 2.0)]
        assert len(clean) > 100 and len(during) > 50
        assert np.all(during <= 1.0), f"uav{i + 1}: full thrust commanded during {kind}"
        assert during.max() <= 1.5 * clean.max(), (
            f"uav{i + 1}: thrust {during.max():.2f} during {kind}, clean hover at most {clean.max():.2f}")


#: per intrusion, what the refusing node says (one rate-limited line per kind)
REFUSALS = {"teleop": "TeleopCommand refused", "setpoint": "setpoint thrust 1e+09 N above the ceiling",
            "info": "/fpr/info: zeta_2", "imu": "IMU body rate", "marker": "detection rejected by the gate"}


@pytest.mark.parametrize("kind", list(WINDOWS))
def test_each_refusal_is_said(node_log, kind):
    lines = [line for line in node_log.splitlines() if REFUSALS[kind] in line and ("refused" in line or
                                                                                   "rejected" in line)]
    assert lines, f"no log line refusing the {kind} intrusion"
    assert len(lines) <= 10, f"{kind}: {len(lines)} lines, not rate-limited: {lines[:3]}"
