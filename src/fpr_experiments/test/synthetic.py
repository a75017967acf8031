"""A synthetic recorded flight (ROS-free) for the metric, plot and report tests: every error is known exactly."""

from __future__ import annotations

import math

import numpy as np
from fpr_experiments.records import CommandSeries, FlightRecord, StateNames, TruthSeries, UavSeries

N = 3
RATE = 0.3                       # [m/s] commanded climb / descent
ROLL_RIPPLE = math.radians(1.0)  # amplitude of the roll error (sinusoid): RMSE = amplitude / sqrt(2)
LEG2_OFFSET = math.radians(0.5)  # constant error of leg 2
POSITION_OFFSET = 0.03           # [m] constant x error vs the desired position
FORCE_BIAS = 0.4                 # [N] the observer's z force is this much above the truth
GEAR = 0.10                      # [m] landing-gear height
NAMES = StateNames(teleop_mode={0: "IDLE", 1: "ARM", 2: "FLY", 3: "LAND"},
                   bridge_state={1: "IDLE", 2: "ARMING", 4: "OFFBOARD", 5: "LANDING"},
                   controller_mode={1: "COMMUNICATING", 2: "NON_COMMUNICATING"})


def synthetic_record(ground_truth_mode: bool = True) -> FlightRecord:
    """20 s: ARM at 1 s, FLY at 2 s (every bridge OFFBOARD from 3 s), climb 6-10 s at 0.3 m/s from the ground,
    roll step 11-13 s, descend 14-18 s, LAND at 18 s. The truth follows the desired state but for a 1 deg roll
    ripple, a 0.5 deg leg-2 offset, a 3 cm x offset; a 0.2 kg payload from 12 s; the observer is 0.4 N high."""
    t_cmd = np.arange(0.0, 20.0, 0.02)
    mode = np.select([t_cmd < 1.0, t_cmd < 2.0, t_cmd < 18.0], [0, 1, 2], 3)
    vz = np.where((t_cmd >= 6.0) & (t_cmd < 10.0), RATE, 0.0) - np.where((t_cmd >= 14.0) & (t_cmd < 18.0), RATE, 0.0)
    roll = np.clip((t_cmd - 11.0) / 2.0, 0.0, 1.0) * math.radians(10.0)
    legs_cmd = np.full((len(t_cmd), N), math.radians(60.0))
    command = CommandSeries(t=t_cmd, mode=mode, velocity=np.column_stack([0 * t_cmd, 0 * t_cmd, vz]),
                            yaw_rate=0 * t_cmd, roll=roll, pitch=0 * t_cmd, contact_force=0 * t_cmd, legs=legs_cmd)
    t = np.arange(0.0, 20.0, 0.01)
    rise = np.interp(t, t_cmd, np.concatenate([[0.0], np.cumsum(vz[:-1] * 0.02)]))
    z = 1.0 + rise
    rpy = np.column_stack([np.interp(t, t_cmd, roll) + ROLL_RIPPLE * np.sin(2 * np.pi * t), 0 * t, 0 * t])
    legs = np.full((len(t), N), math.radians(60.0))
    legs[:, 1] += LEG2_OFFSET
    position = np.column_stack([POSITION_OFFSET + 0 * t, 0 * t, z])
    half = 0.5 * rpy[:, 0]
    quat = np.column_stack([np.cos(half), np.sin(half), 0 * t, 0 * t])
    uav_positions = np.zeros((len(t), N, 3))
    uav_positions[:, :, 2] = (z - 1.0 + GEAR)[:, None]  # the feet on the ground at z = 1 m, lifting with the rise
    uav_quats = np.tile([1.0, 0.0, 0.0, 0.0], (len(t), N, 1))
    payload = np.where(t >= 12.0, 0.2, 0.0)
    wrench = np.zeros((len(t), 6 + N))
    wrench[:, 2] = -9.81 * payload
    truth = TruthSeries(t=t, position=position, quat=quat, rpy=rpy, legs=legs, leg_rates=0 * legs,
                        velocity=np.column_stack([0 * t, 0 * t, np.interp(t, t_cmd, vz)]), rate=0 * position,
                        thrusts=np.full((len(t), N), 11.5), uav_positions=uav_positions, uav_quats=uav_quats,
                        external_wrench=wrench, contact_force=0 * t, payload_mass=payload,
                        battery=np.full((len(t), N), 12.1))
    t_status = np.arange(0.0, 20.0, 0.1)
    state = np.select([t_status < 1.0, t_status < 3.0, t_status < 18.0], [1, 2, 4], 5)
    t_diag = np.arange(0.0, 20.0, 0.02)
    desired_position = np.column_stack([0 * t_diag, 0 * t_diag, np.interp(t_diag, t, z)])
    if not ground_truth_mode:
        desired_position[:] = 0.0
    uavs = []
    for i in range(1, N + 1):
        uavs.append(UavSeries(
            uav_id=i, status_t=t_status, bridge_state=state, diagnostics_t=t_diag,
            active_mode=np.where(t_diag < 0.5, 2, 1), fallback=t_diag < 0.5, desired_position=desired_position,
            desired_rpy=np.column_stack([np.interp(t_diag, t_cmd, roll), 0 * t_diag, 0 * t_diag]),
            desired_legs=np.full((len(t_diag), N), math.radians(60.0)), desired_contact_force=0 * t_diag,
            setpoint_t=t_diag, setpoint_thrust=np.full(len(t_diag), 11.6), wrench_t=t_diag,
            wrench_force=np.column_stack([0 * t_diag, 0 * t_diag, np.interp(t_diag, t, wrench[:, 2]) + FORCE_BIAS]),
            wrench_moment=np.zeros((len(t_diag), 3)), wrench_contact=0 * t_diag,
            wrench_legs=np.zeros((len(t_diag), N))))
    return FlightRecord(n=N, truth=truth, command=command, uavs=uavs, names=NAMES, experiment="synthetic",
                        variant="v1", scenario="synthetic.yaml", script="synthetic_script.yaml",
                        controller_mode="impedance", cameras="emulated", sim_time=20.0, wall_time=25.0,
                        lockstep_timeouts=2, landing_gear_height=GEAR)
