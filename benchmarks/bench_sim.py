"""fpr_sim benchmarks: physics real-time factor (n = 3, 1 kHz, no ROS) for both plant implementations (the
pure-Python reference and the compiled C kernel of fpr_sim._kernels), render time per image, and the simulator
core with 3 scripted MAVLink setpoint clients in lockstep (UDP on 127.0.0.1: run via scripts/isolated.sh).

    bash scripts/isolated.sh python benchmarks/bench_sim.py

The compiled kernel must have been built (scripts/setup.sh / colcon build); otherwise only the Python figures
are printed.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for package in ("fpr_model", "fpr_sim", "fpr_px4_bridge"):
    sys.path.insert(0, str(ROOT / "src" / package))
os.environ["MAVLINK20"] = "1"

import numpy as np  # noqa: E402
from fpr_model.dynamics import forward_dynamics, gravity, thrusts_from_wrench  # noqa: E402
from fpr_sim._kernels import KERNEL_ENV, kernel_status  # noqa: E402
from fpr_sim.cameras import CameraRig  # noqa: E402
from fpr_sim.plant import Plant  # noqa: E402
from fpr_sim.quadrotor import AttitudeCommand  # noqa: E402
from fpr_sim.scenario import CameraConfig, scenario_from_dict  # noqa: E402
from fpr_sim.simulation import Simulation, SimulationOptions  # noqa: E402
from fpr_sim.structure import StructureDynamics  # noqa: E402

KERNELS = ("python", "compiled") if kernel_status().available else ("python",)

#: the step-time cases: hovering (no ground), hovering in wind + gust, resting armed on the ground
PHYSICS_CASES = {
    "hover": {"initial_state": {"mode": "hover", "leg_angles": 0.8, "armed": True}, "ground": {"enabled": False}},
    "wind": {"initial_state": {"mode": "hover", "leg_angles": 0.8, "armed": True}, "ground": {"enabled": False},
             "wind": {"velocity": [1.0, 0.5, 0.0], "gusts": [{"start": 0.5, "duration": 2.0,
                                                              "velocity": [0.0, 1.0, 0.0]}]}},
    "on_ground": {"initial_state": {"mode": "ground", "leg_angles": 1.0}},
}


def _hovering_plant(case: str, kernel: str) -> Plant:
    plant = Plant(scenario_from_dict(PHYSICS_CASES[case]), kernel=kernel)
    q = plant.state.configuration()
    forces = thrusts_from_wrench(plant.params, q, gravity(plant.params, q))
    if case == "on_ground":  # armed on the ground at 30 % of the hover thrust
        u = 0.3 * np.linalg.norm(forces, axis=1) / plant.fleet.max_thrust()
        quats = plant.default_uav_attitudes()
    else:
        u = np.linalg.norm(forces, axis=1) / plant.fleet.max_thrust()
        quats = plant.default_uav_attitudes(forces)
    plant.set_command(AttitudeCommand(quats, u, np.ones(plant.n, dtype=bool)))
    return plant


def step_time(case: str, kernel: str, steps: int = 1000, repeats: int = 3) -> float:
    """Best of ``repeats`` × ``steps`` plant steps [s per step]."""
    plant = _hovering_plant(case, kernel)
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            plant.step()
        best = min(best, (time.perf_counter() - start) / steps)
    return best


def bench_physics() -> None:
    print(f"compiled kernel: {kernel_status().reason}")
    for case in PHYSICS_CASES:
        times = {kernel: step_time(case, kernel) for kernel in KERNELS}
        text = ", ".join(f"{kernel} {1e6 * t:.1f} us/step (RTF {1e-3 / t:.1f}x)" for kernel, t in times.items())
        ratio = f", compiled/python speed-up {times['python'] / times['compiled']:.1f}x" if len(times) == 2 else ""
        print(f"plant step n=3 1 kHz [{case}]: {text}{ratio}")
    plant = _hovering_plant("hover", "python")
    state = plant.state
    xi = np.concatenate([state.velocity, state.rate, state.leg_rates]).tolist()
    c = np.cos(state.leg_angles).tolist()
    s = np.sin(state.leg_angles).tolist()
    g = [0.0, 0.0, -9.81]
    qf = [0.0] * 9
    reps = 5000
    calls = {}
    for kernel in KERNELS:
        sd = StructureDynamics(plant.params, kernel=kernel)
        start = time.perf_counter()
        for _ in range(reps):
            sd.accelerate(c, s, xi, g, qf)
        calls[kernel] = (time.perf_counter() - start) / reps
    q = state.configuration()
    nu = state.generalized_velocity()
    reps_ref = 500
    start = time.perf_counter()
    for _ in range(reps_ref):
        forward_dynamics(plant.params, q, nu, qf)
    ref = (time.perf_counter() - start) / reps_ref
    text = ", ".join(f"{kernel} {1e6 * t:.1f} us/call" for kernel, t in calls.items())
    print(f"structure forward dynamics (StructureDynamics.accelerate, incl. the ctypes call): {text}; "
          f"fpr_model.forward_dynamics {1e6 * ref:.1f} us/call")
    start = time.perf_counter()
    StructureDynamics(plant.params, kernel="python")
    print(f"per-parameter basis fit: {1e3 * (time.perf_counter() - start):.1f} ms once")


def bench_render(frames: int = 200) -> None:
    plant = Plant(scenario_from_dict({"initial_state": {"mode": "hover", "leg_angles": 1.0},
                                      "ground": {"enabled": False}}))
    truth = plant.ground_truth()
    rig = CameraRig(CameraConfig(pixel_noise=0.0), 3, seed=0)
    rig.render(truth)
    start = time.perf_counter()
    for _ in range(frames):
        rig.render(truth)
    plain = (time.perf_counter() - start) / (3 * frames)
    rig = CameraRig(CameraConfig(pixel_noise=2.0, blur_sigma=0.5), 3, seed=0)
    start = time.perf_counter()
    for _ in range(frames):
        rig.render(truth)
    noisy = (time.perf_counter() - start) / (3 * frames)
    print(f"render 640x480 mono8: {1e3 * plain:.2f} ms/image (no noise), {1e3 * noisy:.2f} ms/image "
          f"(noise 2 + blur 0.5)")


def bench_lockstep(kernel: str, seconds: float = 3.0) -> None:
    from fpr_model.frames import quat_enu_flu_to_ned_frd
    from pymavlink import mavutil

    scenario = scenario_from_dict({"initial_state": {"mode": "hover", "leg_angles": 0.8, "armed": True},
                                   "ground": {"enabled": False}, "cameras": {"enabled": False}})
    os.environ[KERNEL_ENV] = kernel  # the Simulation builds its Plant with the default selection
    try:
        sim = Simulation(scenario, SimulationOptions(local_base_port=0, remote_base_port=0, lockstep=True,
                                                     lockstep_timeout=0.5))
    finally:
        del os.environ[KERNEL_ENV]
    assert sim.plant.kernel == kernel
    targets = [(e.quat_local.copy(), e.thrust) for e in sim.emulators]
    stop = threading.Event()

    def client(i: int) -> None:
        link = mavutil.mavlink_connection(f"udpout:127.0.0.1:{sim.ports[i]}", source_system=200 + i)
        q = [float(v) for v in quat_enu_flu_to_ned_frd(targets[i][0])]
        last_ms = -1
        link.mav.set_attitude_target_send(time_boot_ms=0, target_system=i + 1, target_component=1, type_mask=7,
                                          q=q, body_roll_rate=0.0, body_pitch_rate=0.0, body_yaw_rate=0.0,
                                          thrust=targets[i][1])
        while not stop.is_set():  # a scripted controller: one setpoint per 20 ms of simulated time
            msg = link.recv_match(type="ATTITUDE_QUATERNION", blocking=True, timeout=0.2)
            if msg is None or msg.time_boot_ms // 20 == last_ms // 20:
                continue
            last_ms = msg.time_boot_ms
            link.mav.set_attitude_target_send(time_boot_ms=msg.time_boot_ms, target_system=i + 1,
                                              target_component=1, type_mask=7, q=q, body_roll_rate=0.0,
                                              body_pitch_rate=0.0, body_yaw_rate=0.0, thrust=targets[i][1])

    threads = [threading.Thread(target=client, args=(i,), daemon=True) for i in range(3)]
    for thread in threads:
        thread.start()
    start = time.perf_counter()
    sim.advance(seconds)
    wall = time.perf_counter() - start
    stop.set()
    for thread in threads:
        thread.join()
    print(f"simulator core [{kernel}], lockstep, 3 scripted MAVLink clients (no ROS, no cameras): real-time "
          f"factor {seconds / wall:.2f}x, lockstep timeouts {sim.lockstep_timeouts}, setpoints "
          f"{[e.counters.setpoints for e in sim.emulators]}")
    sim.close()


def _scripted_bridge(port: int, uav_id: int, quat_ned: list[float], thrust: float, stop, ready) -> None:
    """A scripted stand-in for one px4_bridge (own process, as on the robot): listens on 127.0.0.1:port like
    px4_bridge and answers each new 20 ms instant of PX4's telemetry with one setpoint stamped with it."""
    from pymavlink import mavutil

    link = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=uav_id, source_component=191)
    ready.release()
    last_ms = -1
    while not stop.is_set():
        msg = link.recv_match(type="ATTITUDE_QUATERNION", blocking=True, timeout=0.2)
        if msg is None or msg.time_boot_ms // 20 == last_ms // 20:
            continue
        last_ms = msg.time_boot_ms
        link.mav.set_attitude_target_send(time_boot_ms=msg.time_boot_ms, target_system=uav_id, target_component=1,
                                          type_mask=7, q=quat_ned, body_roll_rate=0.0, body_pitch_rate=0.0,
                                          body_yaw_rate=0.0, thrust=thrust)
    link.close()


def bench_node(cameras: str, seconds: float = 5.0) -> None:
    """The `simulator` NODE (rclpy: /clock at 250 Hz, /fpr/ground_truth, cameras) in lockstep with 3 scripted
    MAVLink peers standing in for the bridges, each in its own process (listening on 15540+i, one setpoint per
    20 ms of simulated time, stamped with that instant). Run under scripts/isolated.sh (rclpy + loopback UDP)."""
    import multiprocessing

    import rclpy
    from fpr_model.frames import quat_enu_flu_to_ned_frd
    from fpr_sim.simulator import SimulatorNode
    from rclpy.parameter import Parameter

    scenario_file = os.path.join(os.path.dirname(__file__), "..", "src", "fpr_sim", "config", "scenarios",
                                 "hover.yaml")
    rclpy.init()
    node = SimulatorNode(parameter_overrides=[
        Parameter("scenario_file", value=os.path.abspath(scenario_file)), Parameter("real_time_factor", value=0.0),
        Parameter("emulated_cameras", value=cameras == "emulated"), Parameter("duration", value=seconds),
        Parameter("remote_base_port", value=15540)])
    sim = node.sim
    stop, ready = multiprocessing.Event(), multiprocessing.Semaphore(0)
    peers = [multiprocessing.Process(target=_scripted_bridge, daemon=True, args=(
        15540 + i, i + 1, [float(v) for v in quat_enu_flu_to_ned_frd(e.quat_local)], float(e.thrust), stop, ready))
        for i, e in enumerate(sim.emulators)]
    for peer in peers:
        peer.start()
    for _ in peers:  # the peers listen before the clock starts (as running bridges would)
        ready.acquire(timeout=30.0)
    start = time.perf_counter()
    node.run()
    wall = time.perf_counter() - start
    stop.set()
    for peer in peers:
        peer.join(timeout=5.0)
    print(f"simulator node [{sim.plant.kernel}], cameras {cameras}, lockstep, 3 scripted MAVLink peer processes: "
          f"real-time factor {sim.time / wall:.2f}x ({sim.time:.1f} s simulated in {wall:.1f} s), lockstep "
          f"timeouts {sim.lockstep_timeouts}")
    node.destroy_node()
    rclpy.try_shutdown()

if __name__ == "__main__":
    bench_physics()
    bench_render()
    for kernel_name in KERNELS:
        bench_lockstep(kernel_name)
    for camera_mode in ("emulated", "images"):
        bench_node(camera_mode)
