"""MAVLink 2 signing end to end (issue 12): the whole simulated graph with one signing key for every px4_bridge and
every emulated PX4 (GraphOptions.signing_key_file = the launch argument ``signing_key_file``) takes off and hovers
as the unsigned one does, while a local intruder injects 100 unsigned SET_ATTITUDE_TARGET (full thrust, a 60° roll)
into UAV 2's PX4 port: every one is refused (counted as garbage), none reaches the attitude controller, and the
platform stays level. The deterministic in-process runner, the demo's graph (``takeoff_landing``: ground start,
arm, fly, climb)."""

from __future__ import annotations

import dataclasses
import math
import os
import socket

import numpy as np
import pytest

os.environ["MAVLINK20"] = "1"
from fpr_experiments.catalog import load_experiment  # noqa: E402
from fpr_experiments.graph import describe_graph  # noqa: E402
from fpr_experiments.inprocess import InProcessGraph  # noqa: E402
from fpr_experiments.recording import flight_record, recorded_topics  # noqa: E402
from fpr_experiments.resources import SCENARIOS  # noqa: E402
from fpr_experiments.runner import graph_options  # noqa: E402
from fpr_px4_bridge.px4_protocol import import_mavlink  # noqa: E402

INJECT = (10.0, 11.0)  # [s] simulated: the robot climbs under its controllers
END = 13.0
MARK = 0.987654  # the intruder's thrust, recognisable if it ever reached the attitude controller


@pytest.fixture(scope="module")
def signed_flight(tmp_path_factory):
    key_file = tmp_path_factory.mktemp("signing") / "fpr.key"
    key_file.write_text("5a" * 32 + "\n")
    experiment = load_experiment("takeoff_landing")
    variant = experiment.variants[0]
    options = graph_options(experiment, variant, SCENARIOS.resolve(experiment.scenario), "emulated", 3,
                            realism="ideal")  # MAVLink signing under test, not the realism (unit-level: issue 11)
    options = dataclasses.replace(options, signing_key_file=str(key_file))
    specs = describe_graph(options)
    assert all(spec.parameters.get("signing_key_file") == str(key_file) for spec in specs
               if spec.executable in ("simulator", "px4_bridge"))
    mavlink = import_mavlink()
    intruder = mavlink.MAVLink(None, srcSystem=2, srcComponent=191)  # even claiming to be UAV 2's companion
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    with InProcessGraph(specs, recorded_topics(3)) as swarm:
        swarm.wait_for_discovery()
        emulators = swarm.simulator.sim.emulators
        applied = {i: [] for i in range(3)}  # thrusts of the SET_ATTITUDE_TARGET each PX4 accepted
        for i, emulator in enumerate(emulators):
            original = emulator._handle

            def spy(msg, address, i=i, original=original) -> None:
                if msg.get_type() == "SET_ATTITUDE_TARGET":
                    applied[i].append(float(msg.thrust))
                original(msg, address)

            emulator._handle = spy
        swarm.run_until(lambda: swarm.sim_time >= INJECT[0], wall_timeout=120.0)
        garbage_before = emulators[1].counters.garbage
        q = [math.cos(math.radians(30.0)), math.sin(math.radians(30.0)), 0.0, 0.0]
        sent = 0
        while swarm.sim_time < INJECT[1]:
            if sent < 100:
                frame = intruder.set_attitude_target_encode(
                    time_boot_ms=int(swarm.sim_time * 1000), target_system=2, target_component=1, type_mask=7, q=q,
                    body_roll_rate=0.0, body_pitch_rate=0.0, body_yaw_rate=0.0, thrust=MARK).pack(intruder)
                sock.sendto(frame, ("127.0.0.1", swarm.simulator.sim.ports[1]))
                sent += 1
            swarm.run_until(lambda due=swarm.sim_time + 0.01: swarm.sim_time >= due, wall_timeout=30.0)
        refused = emulators[1].counters.garbage - garbage_before
        swarm.run_until(lambda: swarm.sim_time >= END, wall_timeout=120.0)
        assert swarm.wait_for_recorder()
        recording = swarm.recorder.snapshot()
        statuses = {i: recording.get(f"/fpr/uav{i}/status") for i in (1, 2, 3)}
        yield {"record": flight_record(recording, 3, experiment="takeoff_landing", sim_time=swarm.sim_time),
               "applied": applied, "sent": sent, "refused": refused, "errors": list(swarm.errors),
               "statuses": statuses, "signing": [e.signing for e in emulators],
               "bridge_links": [swarm.node(f"/fpr/uav{i}/px4_bridge").link for i in (1, 2, 3)]}
    sock.close()


def test_every_link_is_signed_and_the_robot_flies(signed_flight):
    assert signed_flight["errors"] == []
    assert all(signed_flight["signing"]) and all(link.signing for link in signed_flight["bridge_links"])
    for i, statuses in signed_flight["statuses"].items():
        assert any(s.state == 4 for s in statuses), f"uav{i}: never OFFBOARD over the signed link"
    # the bridges accepted PX4's signed frames and refused none
    assert all(link.counters.rx_frames > 500 and link.counters.rx_unsigned == 0
               for link in signed_flight["bridge_links"])
    truth = signed_flight["record"].truth
    climbed = truth.position[truth.t >= END - 0.5, 2].mean() - truth.position[truth.t <= 1.0, 2].mean()
    assert climbed > 0.3, f"the signed robot did not take off (climbed {climbed:.2f} m)"


def test_unsigned_injection_is_refused_and_changes_nothing(signed_flight):
    assert signed_flight["sent"] == 100
    assert signed_flight["refused"] >= 100  # each unsigned frame counted as garbage by UAV 2's PX4
    assert all(MARK not in thrusts for thrusts in signed_flight["applied"].values())
    assert all(len(thrusts) > 300 for thrusts in signed_flight["applied"].values())  # the genuine stream
    truth = signed_flight["record"].truth
    window = truth.t >= INJECT[0]
    worst = np.degrees(np.abs(truth.rpy[window, :2]).max())
    assert worst < 5.0, f"the platform tilted {worst:.1f} deg during the injection"
