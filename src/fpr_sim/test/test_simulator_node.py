"""simulator node in process with real rclpy: /clock, /fpr/ground_truth and camera topics are published."""

import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402

from fpr_msgs.msg import FprState  # noqa: E402


def test_simulator_node_publishes_clock_truth_and_images():
    rclpy.init()
    try:
        from fpr_sim.simulator import SimulatorNode

        listener = rclpy.create_node("sim_listener")
        clocks, truths, images = [], [], []
        listener.create_subscription(Clock, "/clock", clocks.append, 500)
        listener.create_subscription(FprState, "/fpr/ground_truth", truths.append, 500)
        listener.create_subscription(Image, "/fpr/uav2/camera/image_raw", images.append, qos_profile_sensor_data)
        overrides = [Parameter("real_time_factor", value=1.0), Parameter("duration", value=1.0),
                     Parameter("local_base_port", value=0), Parameter("remote_base_port", value=0)]
        sim_node = SimulatorNode(parameter_overrides=overrides)
        executor = SingleThreadedExecutor()
        executor.add_node(listener)
        deadline = time.monotonic() + 5.0
        while (sim_node.clock_pub.get_subscription_count() == 0 or sim_node.truth_pub.get_subscription_count() == 0
               or sim_node.image_pubs[1].get_subscription_count() == 0):
            executor.spin_once(timeout_sec=0.05)
            assert time.monotonic() < deadline, "discovery timed out"
        thread = threading.Thread(target=sim_node.run)
        thread.start()
        while thread.is_alive():
            executor.spin_once(timeout_sec=0.02)
        for _ in range(20):
            executor.spin_once(timeout_sec=0.02)
        thread.join()
        sim_node.destroy_node()
        listener.destroy_node()
        assert len(clocks) >= 100  # 250 Hz over 1 s simulated
        stamps = [c.clock.sec + 1e-9 * c.clock.nanosec for c in clocks]
        assert all(b > a for a, b in zip(stamps, stamps[1:], strict=False))
        assert stamps[-1] == pytest.approx(1.0, abs=0.01)
        assert truths and len(truths[-1].leg_angles) == 3 and len(truths[-1].external_wrench) == 9
        assert truths[-1].platform_pose.position.z > 0.9  # resting on the ground, legs at 60°
        assert images and images[-1].encoding == "mono8" and images[-1].width == 640
    finally:
        rclpy.shutdown()


def test_simulator_node_publishes_the_emulated_target(tmp_path):
    """Scenario ``target`` enabled: /fpr/target (PoseStamped, sensor-data QoS) at 50 Hz of simulation time, in the
    flat platform frame, stamped with the simulation time (the values: fpr_sim.target, test_target.py)."""
    from geometry_msgs.msg import PoseStamped

    scenario = tmp_path / "target.yaml"
    scenario.write_text("name: target\ncameras: {enabled: false}\n"
                        "target: {enabled: true, position: [1.0, 0.5, 2.0], yaw: 0.4, position_noise: 0.0, "
                        "yaw_noise: 0.0}\n")
    rclpy.init()
    try:
        from fpr_sim.simulator import SimulatorNode

        listener = rclpy.create_node("target_listener")
        targets = []
        listener.create_subscription(PoseStamped, "/fpr/target", targets.append, qos_profile_sensor_data)
        overrides = [Parameter("real_time_factor", value=1.0), Parameter("duration", value=0.5),
                     Parameter("scenario_file", value=str(scenario)), Parameter("local_base_port", value=0),
                     Parameter("remote_base_port", value=0)]
        sim_node = SimulatorNode(parameter_overrides=overrides)
        executor = SingleThreadedExecutor()
        executor.add_node(listener)
        deadline = time.monotonic() + 5.0
        while sim_node.target_pub.get_subscription_count() == 0:
            executor.spin_once(timeout_sec=0.05)
            assert time.monotonic() < deadline, "discovery timed out"
        thread = threading.Thread(target=sim_node.run)
        thread.start()
        while thread.is_alive():
            executor.spin_once(timeout_sec=0.02)
        for _ in range(20):
            executor.spin_once(timeout_sec=0.02)
        thread.join()
        platform = sim_node.sim.plant.state.position
        sim_node.destroy_node()
        listener.destroy_node()
    finally:
        rclpy.shutdown()
    assert 20 <= len(targets) <= 26  # 50 Hz over 0.5 s (sensor-data QoS: best effort)
    last = targets[-1]
    assert last.header.frame_id == "flat_platform"
    stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in targets]
    # the first one on the first /clock period (due at t = 0, as /fpr/ground_truth), then every 20 ms
    assert all(b - a == pytest.approx(0.02, abs=1e-6) for a, b in zip(stamps[1:], stamps[2:], strict=False))
    assert last.pose.position.x == pytest.approx(1.0 - platform[0], abs=0.01)  # the robot rests at yaw 0
    assert last.pose.position.z == pytest.approx(2.0 - platform[2], abs=0.01)
    assert last.pose.orientation.z == pytest.approx(np.sin(0.2), abs=1e-3)


class _SimulatorProcess:
    """``python -m fpr_sim.simulator`` (emulated cameras, no MAVLink peers) with a listener of its /clock times."""

    def __init__(self, real_time_factor: float) -> None:
        import os
        import subprocess
        import sys

        self.listener = rclpy.create_node("simulator_process_listener")
        self.clocks: list[float] = []
        self.listener.create_subscription(
            Clock, "/clock", lambda m: self.clocks.append(m.clock.sec + 1e-9 * m.clock.nanosec), 500)
        self.process = subprocess.Popen(
            [sys.executable, "-m", "fpr_sim.simulator", "--ros-args", "-p", f"real_time_factor:={real_time_factor}",
             "-p", "local_base_port:=0", "-p", "remote_base_port:=0", "-p", "emulated_cameras:=true"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ))

    def spin_until(self, condition, what: str, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            rclpy.spin_once(self.listener, timeout_sec=0.05)
            assert self.process.poll() is None, self.process.stdout.read()
            assert time.monotonic() < deadline, what

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(self.listener, timeout_sec=0.05)

    def stop(self, signum) -> tuple[int, str]:
        """Send ``signum``; the exit status and the whole output."""
        self.process.send_signal(signum)
        output, _ = self.process.communicate(timeout=20.0)
        return self.process.returncode, output

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.communicate()
        self.listener.destroy_node()


@pytest.mark.parametrize("signal_name", ["SIGTERM", "SIGINT"])
def test_simulator_process_exits_quietly_on_a_signal_while_running(signal_name):
    """Integration defect: SIGTERM/SIGINT during run() shut the context down while step() published ->
    RCLError "publisher's context is invalid" traceback. The node must exit with status 0 and no traceback, and
    say at start which plant kernel runs."""
    import os
    import signal

    from fpr_sim._kernels import KERNEL_ENV, resolve_kernel

    rclpy.init()
    try:
        simulator = _SimulatorProcess(real_time_factor=0.0)  # stepping and publishing as fast as it can
        try:
            simulator.spin_until(lambda: len(simulator.clocks) >= 20, "no /clock from the simulator process")
            status, output = simulator.stop(getattr(signal, signal_name))
        finally:
            simulator.close()
    finally:
        rclpy.shutdown()
    assert status == 0, output
    assert "Traceback" not in output and "RCLError" not in output, output
    expected = resolve_kernel(os.environ.get(KERNEL_ENV), 3)
    assert f"plant kernel: {expected} (" in output, output


def test_sigusr1_holds_the_world_and_sigusr2_resumes_it():
    """The fault injector's restart (fpr_experiments.processes): SIGUSR1 pauses the simulation between two steps
    (/clock repeated at the same time, no new time), SIGUSR2 resumes it; both said in the log."""
    import signal

    rclpy.init()
    try:
        simulator = _SimulatorProcess(real_time_factor=1.0)
        clocks = simulator.clocks
        try:
            simulator.spin_until(lambda: len(clocks) >= 20, "no /clock from the simulator process")
            simulator.process.send_signal(signal.SIGUSR1)
            simulator.spin_for(0.5)  # the step in progress ends, and its /clock arrives
            held_from = len(clocks)
            simulator.spin_for(1.5)
            held = clocks[held_from - 1:]
            assert len(held) >= 4  # repeated every 0.25 s of wall time (CLOCK_REPEAT_S)
            assert max(held) == min(held), held  # one and the same time: the world holds
            paused_at = held[-1]
            simulator.process.send_signal(signal.SIGUSR2)
            simulator.spin_until(lambda: clocks[-1] > paused_at + 0.2, "no /clock after SIGUSR2")
            status, output = simulator.stop(signal.SIGTERM)
        finally:
            simulator.close()
    finally:
        rclpy.shutdown()
    assert status == 0, output
    assert f"paused at t = {paused_at:.3f} s (SIGUSR1)" in output, output
    assert f"resumed at t = {paused_at:.3f} s after" in output, output


def test_simulator_process_with_an_unknown_scenario_says_so_in_one_line_and_exits_2():
    import subprocess
    import sys

    result = subprocess.run([sys.executable, "-m", "fpr_sim.simulator", "--ros-args", "-p", "scenario_file:=hoover"],
                            capture_output=True, text=True, timeout=60.0)
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "scenario 'hoover'" in lines[0] and "hover" in lines[0], result.stderr
    assert "Traceback" not in result.stderr + result.stdout


def test_simulator_node_publishes_tf_and_the_robot_description():
    """/tf (1 + 2n true transforms at tf_rate), latched /tf_static (camera mounts) and /robot_description (URDF),
    received by a late subscriber as robot_state_publisher's are."""
    import xml.etree.ElementTree as ElementTree

    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String
    from tf2_msgs.msg import TFMessage

    rclpy.init()
    try:
        from fpr_sim.simulator import SimulatorNode

        overrides = [Parameter("real_time_factor", value=0.0), Parameter("duration", value=0.5),
                     Parameter("local_base_port", value=0), Parameter("remote_base_port", value=0),
                     Parameter("emulated_cameras", value=True)]
        sim_node = SimulatorNode(parameter_overrides=overrides)
        listener = rclpy.create_node("tf_listener")   # joins after the latched messages went out
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        tfs, statics, descriptions = [], [], []
        listener.create_subscription(TFMessage, "/tf", tfs.append, 100)
        listener.create_subscription(TFMessage, "/tf_static", statics.append, latched)
        listener.create_subscription(String, "/robot_description", descriptions.append, latched)
        executor = SingleThreadedExecutor()
        executor.add_node(listener)
        deadline = time.monotonic() + 5.0
        while sim_node.tf_pub.get_subscription_count() == 0 or not (statics and descriptions):
            executor.spin_once(timeout_sec=0.05)
            assert time.monotonic() < deadline, "discovery / latched messages timed out"
        thread = threading.Thread(target=sim_node.run)
        thread.start()
        while thread.is_alive():
            executor.spin_once(timeout_sec=0.02)
        for _ in range(20):
            executor.spin_once(timeout_sec=0.02)
        thread.join()
        sim_node.destroy_node()
        listener.destroy_node()
        assert 20 <= len(tfs) <= 27                                # 50 Hz over 0.5 s simulated
        children = [t.child_frame_id for t in tfs[-1].transforms]
        assert children == ["platform", "leg1", "uav1/base_link", "leg2", "uav2/base_link", "leg3", "uav3/base_link"]
        assert [t.child_frame_id for t in statics[0].transforms] == [f"uav{i}/camera_optical" for i in (1, 2, 3)]
        links = {link.get("name") for link in ElementTree.fromstring(descriptions[0].data).iter("link")}
        assert {"platform", "leg1", "uav3/base_link"} <= links and len(links) == 7
    finally:
        rclpy.shutdown()


def test_simulator_builds_tf_only_while_someone_listens(monkeypatch):
    """/tf is lazy (issue 15): no message is built while /tf has no subscriber; once one joins, every tf_rate
    instant is published again."""
    rclpy.init()
    try:
        from fpr_sim.simulator import SimulatorNode

        overrides = [Parameter("real_time_factor", value=0.0), Parameter("local_base_port", value=0),
                     Parameter("remote_base_port", value=0), Parameter("emulated_cameras", value=True)]
        sim_node = SimulatorNode(parameter_overrides=overrides)
        built = []
        original = sim_node._publish_tf
        monkeypatch.setattr(sim_node, "_publish_tf", lambda: (built.append(sim_node.sim.time), original()))
        while sim_node.sim.time < 0.3 - 1e-9:
            sim_node.step()
        assert built == []
        from tf2_msgs.msg import TFMessage

        listener = rclpy.create_node("late_tf_listener")
        listener.create_subscription(TFMessage, "/tf", lambda _: None, 100)
        deadline = time.monotonic() + 5.0
        while sim_node.tf_pub.get_subscription_count() == 0:
            time.sleep(0.01)
            assert time.monotonic() < deadline, "discovery timed out"
        while sim_node.sim.time < 0.6 - 1e-9:
            sim_node.step()
        assert built == pytest.approx([0.32 + 0.02 * k for k in range(15)])  # every 50 Hz instant after it joined
        listener.destroy_node()
        sim_node.destroy_node()
    finally:
        rclpy.shutdown()


def test_a_waiting_lockstep_keeps_the_mavlink_links_alive():
    """While the lockstep waits for a setpoint, /clock is repeated every CLOCK_REPEAT_S of wall time and every
    emulated PX4 sends a HEARTBEAT with it: a live simulator is never silent for the bridges' wall watchdog
    (wall_silence_timeout 0.5 s), a dead one is (tests/test_fault_response.py)."""
    import socket

    from fpr_px4_bridge import px4_protocol as p

    mavlink = p.import_mavlink()
    rclpy.init()
    try:
        from fpr_sim.simulator import CLOCK_REPEAT_S, SimulatorNode

        overrides = [Parameter("local_base_port", value=0), Parameter("remote_base_port", value=0)]
        sim_node = SimulatorNode(parameter_overrides=overrides)
        bridge = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        bridge.bind(("127.0.0.1", 0))
        bridge.settimeout(0.5)
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
        emulator = sim_node.sim.emulators[0]
        bridge.sendto(mav.heartbeat_encode(18, 8, 0, 0, 4).pack(mav), emulator.sock.getsockname())
        emulator.poll(0.0)  # the bridge becomes the link's partner
        parser = mavlink.MAVLink(None)

        def heartbeats() -> int:
            count = 0
            bridge.settimeout(0.05)
            try:
                while True:
                    for m in parser.parse_buffer(bridge.recv(65535)) or []:
                        count += m.get_type() == "HEARTBEAT"
            except TimeoutError:
                return count

        heartbeats()
        sim_node._on_lockstep_wait(0.05)  # within the first CLOCK_REPEAT_S of a wait: nothing yet
        assert heartbeats() == 0
        sim_node._on_lockstep_wait(CLOCK_REPEAT_S + 0.01)
        assert heartbeats() == 1
        sim_node._on_lockstep_wait(CLOCK_REPEAT_S + 0.02)  # not again before another CLOCK_REPEAT_S
        assert heartbeats() == 0
        sim_node._on_lockstep_wait(2 * CLOCK_REPEAT_S + 0.02)
        assert heartbeats() == 1
        bridge.close()
        sim_node.destroy_node()
    finally:
        rclpy.shutdown()


def test_a_stalled_simulator_does_not_race_to_catch_up():
    """Pacing at real_time_factor: a small debt is caught up, a stall beyond PACING_MAX_DEBT_S (machine load) is
    dropped, counted and the pacing restarts from there, so the simulation never runs ahead of the wall clock's
    rate (a catch-up burst ran a CI flight at 1.6x and starved the MAVSDK clients' rate count)."""
    rclpy.init()
    try:
        from fpr_sim.simulator import PACING_MAX_DEBT_S, SimulatorNode

        overrides = [Parameter("local_base_port", value=0), Parameter("remote_base_port", value=0),
                     Parameter("real_time_factor", value=1.0)]
        sim_node = SimulatorNode(parameter_overrides=overrides)
        sim_node._wall_start, sim_node._sim_start = time.monotonic() - 0.5 * PACING_MAX_DEBT_S, 0.0
        sim_node._pace(0.0)  # a small debt: kept (caught up)
        assert sim_node.pacing_debt_dropped == 0.0 and sim_node._sim_start == 0.0
        sim_node._wall_start = time.monotonic() - 5.0  # a 5 s stall
        sim_node._pace(1.0)
        assert 3.9 < sim_node.pacing_debt_dropped < 4.5
        assert sim_node._sim_start == 1.0  # the pacing restarts at t = 1 s, now
        ahead = (1.002 - sim_node._sim_start) - (time.monotonic() - sim_node._wall_start)
        assert ahead > -PACING_MAX_DEBT_S  # the next step is paced again, not part of a burst
        sim_node.destroy_node()
    finally:
        rclpy.shutdown()
