"""Reference trajectories of the plant (oracle for the optimized implementation), and their generator.

``python src/fpr_sim/test/plant_oracle_cases.py`` (with src/fpr_model and src/fpr_sim on the path, e.g.
``PYTHONPATH=src/fpr_model:src/fpr_sim .venv/bin/python src/fpr_sim/test/plant_oracle_cases.py``) runs every
case below and saves the recorded samples to ``data/plant_oracle.npz``, a FROZEN fixture: regenerate it only
after a deliberate change of the physics, and say why in test_plant_oracle.py's docstring (its history is there:
first the numpy plant of commit 99797a6, now the scalar plant after the ground / take-off fix).
``test_plant_oracle.py`` replays the same cases and compares.

Each case is 2 s (or 1.5 s) of the plant at 1 kHz driven by scripted PX4 attitude/thrust commands
(attitude controller (3.39)-(3.41) active unless ``ideal``): hover manoeuvres, a payload attached and dropped,
wind with a gust and a scheduled wrench, take-off from the ground (penalty contact with stick/slip), pushing on
the board, and an n = 4 robot.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent / "data" / "plant_oracle.npz"
RECORD_EVERY = 20  #: steps between recorded samples


@dataclass
class OracleCase:
    name: str
    scenario: dict
    seconds: float = 2.0
    ideal: bool = False
    tilt: float = 0.0  #: amplitude of the scripted roll/pitch commands [rad]
    thrust_scale: list[float] = field(default_factory=lambda: [1.0, 1.0])  #: thrust ratio at t = 0 and at the end
    yaw_rate: float = 0.0  #: rate feed-forward on yaw [rad/s] in the second half


#: The legs' joint stops (scenario ``joint_stops``, on by default since the stops were added) are switched off in
#: the two cases whose legs leave the stop range [10°, 92°]: board_push folds them to −107°, payload_drop swings them
#: from −221° to +132° (open-loop thrust scripts, no leg control). So these cases keep pinning the unstopped
#: structure dynamics, and data/plant_oracle.npz stays the one recorded before the stops existed; the other five
#: stay within 45°-88° and run with the stops enabled (inactive there). The stops themselves are pinned by
#: test_plant_kernels.py (compiled vs Python with the stops engaged) and test_plant.py.
_NO_STOPS = {"enabled": False}

CASES = [
    OracleCase("hover_commands", {"initial_state": {"mode": "hover", "leg_angles": 0.8, "armed": True},
                                  "ground": {"enabled": False}}, tilt=0.08, thrust_scale=[1.0, 1.04], yaw_rate=0.3),
    OracleCase("payload_drop", {"initial_state": {"mode": "hover", "leg_angles": 0.9, "armed": True},
                                "ground": {"enabled": False}, "joint_stops": _NO_STOPS,
                                "payloads": [{"mass": 0.3, "attach_time": 0.2, "release_time": 1.2}]},
               tilt=0.03, thrust_scale=[1.05, 1.0]),
    OracleCase("wind_wrench", {"initial_state": {"mode": "hover", "leg_angles": [0.8, 0.9, 1.0], "armed": True},
                               "ground": {"enabled": False},
                               "wind": {"velocity": [1.0, 0.5, 0.0],
                                        "gusts": [{"start": 0.5, "duration": 0.8, "velocity": [0.0, 2.0, 0.5]}]},
                               "external_wrenches": [{"start": 0.3, "end": 1.1, "force": [0.5, -0.3, 1.0],
                                                      "moment": [0.02, 0.0, -0.03]}]},
               tilt=0.05),
    OracleCase("ground_takeoff", {"initial_state": {"mode": "ground", "leg_angles": 1.0},
                                  "wind": {"velocity": [0.3, 0.0, 0.0]}},
               tilt=0.02, thrust_scale=[0.0, 1.25]),
    OracleCase("board_push", {"initial_state": {"mode": "hover", "leg_angles": 0.8, "armed": True},
                              "ground": {"enabled": False}, "joint_stops": _NO_STOPS,
                              "board": {"enabled": True, "point": [0.0, 0.0, 1.56], "normal": [0.05, 0.0, -1.0]}},
               seconds=1.5, thrust_scale=[1.1, 1.1]),
    OracleCase("n4_ideal", {"n": 4, "initial_state": {"mode": "hover", "leg_angles": 0.9},
                            "ground": {"enabled": False}, "wind": {"velocity": [0.0, 1.0, 0.0]}},
               seconds=1.5, ideal=True, tilt=0.02, thrust_scale=[1.0, 1.02]),
    OracleCase("n4_controlled_ground", {"n": 4, "initial_state": {"mode": "ground", "leg_angles": 0.9},
                                        "payloads": [{"mass": 0.2, "attach_time": 0.0, "release_time": 0.7}]},
               seconds=1.5, tilt=0.03, thrust_scale=[0.3, 1.3]),
]


def run_case(case: OracleCase, kernel: str | None = None) -> dict[str, np.ndarray]:
    """Run one case on the current plant; samples every RECORD_EVERY steps (and the initial state).

    ``kernel``: the plant's kernel ('python' | 'compiled' | 'auto'; None: $FPR_SIM_KERNEL, see fpr_sim._kernels)."""
    from fpr_model.dynamics import gravity, thrusts_from_wrench
    from fpr_model.rotations import quat_from_axis_angle, quat_multiply
    from fpr_sim.plant import Plant
    from fpr_sim.quadrotor import AttitudeCommand
    from fpr_sim.scenario import scenario_from_dict

    scenario = scenario_from_dict(case.scenario)
    plant = Plant(scenario, kernel=kernel)
    plant.ideal_attitude = case.ideal
    n = plant.n
    q = plant.state.configuration()
    hover_forces = thrusts_from_wrench(plant.params, q, gravity(plant.params, q))
    hover_quats = plant.default_uav_attitudes(hover_forces)
    hover_thrust = np.linalg.norm(hover_forces, axis=1)
    steps = int(round(case.seconds / plant.dt))
    records: dict[str, list] = {key: [] for key in (
        "time", "x", "uav_quat", "uav_rate", "rotors", "rate_integral", "charge_used", "external_wrench",
        "contact_force", "specific_forces", "uav_positions", "uav_velocities", "anchors")}

    def record() -> None:
        truth = plant.ground_truth()
        records["time"].append(plant.time)
        records["x"].append(plant._x.copy())
        records["uav_quat"].append(plant.fleet.quat.copy())
        records["uav_rate"].append(plant.fleet.rate.copy())
        records["rotors"].append(plant.fleet.rotors.copy())
        records["rate_integral"].append(plant.fleet.rate_integral.copy())
        records["charge_used"].append(plant.fleet.battery.charge_used.copy())
        records["external_wrench"].append(truth.external_wrench.copy())
        records["contact_force"].append(truth.contact_force)
        records["specific_forces"].append(truth.uav_specific_forces.copy())
        records["uav_positions"].append(truth.uav_positions.copy())
        records["uav_velocities"].append(truth.uav_velocities.copy())
        records["anchors"].append(plant.environment.ground.anchors.copy())

    record()
    for k in range(steps):
        if k % 4 == 0:  # new setpoints at the PX4 controller rate
            t = plant.time
            fraction = t / case.seconds
            scale = case.thrust_scale[0] + (case.thrust_scale[1] - case.thrust_scale[0]) * fraction
            quats = np.empty((n, 4))
            for i in range(n):
                axis = np.array([np.cos(1.3 * i), np.sin(1.3 * i), 0.0])
                tilt = quat_from_axis_angle(axis, case.tilt * np.sin(2.0 * np.pi * 0.8 * t + i))
                quats[i] = quat_multiply(tilt, hover_quats[i])
            u = scale * hover_thrust / plant.fleet.max_thrust()
            feedforward = None
            if case.yaw_rate and fraction > 0.5:
                feedforward = np.tile([0.0, 0.0, case.yaw_rate], (n, 1))
            armed = np.ones(n, dtype=bool)
            plant.set_command(AttitudeCommand(quats, u, armed, feedforward))
        plant.step()
        if (k + 1) % RECORD_EVERY == 0:
            record()
    return {key: np.array(value, dtype=float) for key, value in records.items()}


def main() -> None:
    arrays = {}
    for case in CASES:
        result = run_case(case)
        for key, value in result.items():
            arrays[f"{case.name}/{key}"] = value
        print(f"{case.name}: {len(result['time'])} samples, final P = {result['x'][-1, :3]}, "
              f"max contact {result['contact_force'].max():.3f} N")
    DATA.parent.mkdir(exist_ok=True)
    np.savez_compressed(DATA, **arrays)
    print(f"saved {DATA}")


if __name__ == "__main__":
    main()
