"""On the ground and at take-off: the plant with its PX4 attitude loops, mixer, landing gear and ground contact.

Regression of the integration report "arming on the ground with a LOW thrust (3.4 N per UAV, hover ≈ 11.4 N) makes
the robot jump, the rotors deliver 13-18 N and the legs fold". Causes (all fixed, each pinned below):

1. the quadrotors had no yaw friction on the ground: while disarmed they spun up to ~2 rad/s in yaw under the
   joint-offset moment (2.93) of the legs' horizontal force; at arming the rate loop (3.40) asked for a large yaw
   moment that
2. the mixer (3.41) realised by RAISING the collective (airmode-like), to f_max/4 per rotor: 18 N for a 3.4 N
   command. PX4 (airmode off, the default) only ever reduces the collective and gives up moment authority;
3. the rate integrator integrated against the ground (PX4 freezes it while landed).
"""

import math

import numpy as np
import pytest
from fpr_model.dynamics import gravity, thrusts_from_wrench
from fpr_model.geometry import inverse_geometric_model, leg_anchor_angles, make_configuration
from fpr_model.rotations import quat_to_euler_zyx, quat_to_rotmat
from fpr_sim.plant import Plant
from fpr_sim.quadrotor import AttitudeCommand, mix_one
from fpr_sim.scenario import scenario_from_dict

LEG_ANGLES = math.radians(60.0)  # the ground_start scenario's
ARM, KAPPA = 0.17, 0.016  # QuadrotorConfig defaults [m]


def _ground_plant() -> Plant:
    return Plant(scenario_from_dict({"initial_state": {"mode": "ground", "leg_angles": LEG_ANGLES}}))


def _hover_forces(plant: Plant) -> np.ndarray:
    """J⁻ᵀg: the thrust vectors holding the structure at its present configuration [N], (n, 3)."""
    q = plant.state.configuration()
    return thrusts_from_wrench(plant.params, q, gravity(plant.params, q))


def _yaws(plant: Plant) -> np.ndarray:
    return np.array([quat_to_euler_zyx(q)[2] for q in plant.fleet.quat])


def _run(plant: Plant, quats: np.ndarray, thrust_newton: np.ndarray | None, seconds: float, record=None) -> None:
    """Step the plant for ``seconds`` with the attitude setpoints and thrusts [N] (None: disarmed), normalized
    with the present f_max(V) at the PX4 rate as a user of PX4 does (C.1)."""
    n = plant.n
    for _ in range(int(round(seconds / plant.dt))):
        if plant.steps % 4 == 0:
            armed = thrust_newton is not None
            u = thrust_newton / plant.fleet.max_thrust() if armed else np.zeros(n)
            plant.set_command(AttitudeCommand(quats, u, np.full(n, armed)))
        plant.step()
        if record is not None:
            record(plant)



def _centre_of_mass_height_of(params, state) -> float:
    """Height [m] of the whole robot's centre of mass: platform, legs (CoM s_l along each leg), quadrotors."""
    q = make_configuration(state.position, state.quat, state.leg_angles)
    uavs = inverse_geometric_model(params, q)
    rotation = quat_to_rotmat(state.quat)
    anchors = state.position + (rotation @ (params.platform_radius * np.column_stack(
        [np.cos(leg_anchor_angles(params.n)), np.sin(leg_anchor_angles(params.n)), np.zeros(params.n)])).T).T
    legs = anchors + (params.leg_com[0] / params.leg_length) * (uavs - anchors)
    platform = state.position + rotation @ params.platform_com
    total = params.platform_mass * platform[2] + params.leg_mass * legs[:, 2].sum() + params.uav_masses @ uavs[:, 2]
    return float(total / (params.platform_mass + params.n * params.leg_mass + params.uav_masses.sum()))


def _centre_of_mass_height(plant) -> float:
    return _centre_of_mass_height_of(plant.params, plant.state)

def test_low_thrust_on_the_ground_stays_on_the_ground():
    """The report's sequence: disarmed on the ground while the setpoint stream warms up (1.5 s), then armed with
    the present (level) attitudes and 3.4 N per UAV for 2 s: nothing moves, thrust = command."""
    plant = _ground_plant()
    start = plant.state
    yaw0 = _yaws(plant)
    quats = plant.fleet.quat.copy()
    _run(plant, quats, None, 1.5)
    # root cause 1: the landing gear's friction holds the yaw of a disarmed quadrotor (it spun to ~2 rad/s)
    assert np.degrees(np.abs(_yaws(plant) - yaw0)).max() < 0.5
    assert np.abs(plant.fleet.rate[:, 2]).max() < 0.01
    command = np.full(plant.n, 3.4)
    worst_thrust = []
    feet_down = []

    def record(p: Plant) -> None:
        worst_thrust.append(p.fleet.thrust().max())
        feet_down.append(all(p.uav_landed()))

    _run(plant, quats, command, 2.0, record)
    end = plant.state
    print(f"platform moved {1e3 * np.abs(end.position - start.position).max():.3f} mm, legs "
          f"{np.degrees(np.abs(end.leg_angles - start.leg_angles)).max():.4f} deg, thrust {plant.fleet.thrust()} N, "
          f"max {max(worst_thrust):.3f} N")
    assert np.abs(end.position - start.position).max() < 0.01
    assert np.degrees(np.abs(end.leg_angles - start.leg_angles)).max() < 1.0
    assert all(feet_down)  # never left the ground
    # the actual thrust is the commanded one (motor lag from 0: it never overshoots the command)
    assert plant.fleet.thrust() == pytest.approx(command, rel=0.02)
    assert max(worst_thrust) <= 1.02 * 3.4
    # PX4 freezes the rate integrator while landed: it never integrated the ground's reaction
    assert np.abs(plant.fleet.rate_integral).max() == 0.0
    assert np.degrees(np.abs(_yaws(plant) - yaw0)).max() < 0.5


def test_liftoff_slightly_above_the_weight_is_smooth_and_vertical():
    """Thrust vectors 1.05·J⁻ᵀg (attitudes by (3.36)-(3.37)), after 1 s armed on the ground at 0.3·J⁻ᵀg: the robot
    lifts off at once, vertically, at ≈ 0.05 g, with the commanded thrust and the legs near their angle.

    Level attitudes cannot do it: J⁻ᵀg has an inward component of 0.63 N per UAV (3.2° tilt) that balances the
    platform's weight along the 60° legs; with vertical thrusts the legs splay by statics (−25° in 1 s in this
    plant). And the legs do move a little in open loop: at lift-off the attitude loops (τ = 1/6.5 s) are still
    tilting the quadrotors from their landing-gear attitude, the resulting leg-rate perturbation persists (the
    leg mode of the passive structure under constant thrust vectors is not damped: the controller's job), ≈ −2.5°
    after 1 s (≈ −6° without the ground phase that pre-tilts the quadrotors; −2.0° with d = 0).
    """
    plant = _ground_plant()
    forces = _hover_forces(plant)
    quats = plant.default_uav_attitudes(forces)
    hover = np.linalg.norm(forces, axis=1)
    _run(plant, quats, 0.3 * hover, 1.0)
    assert all(plant.uav_landed())
    start = plant.state
    command = 1.05 * hover
    samples = []

    def record(p: Plant) -> None:
        s = p.state
        samples.append((p.time, s.position.copy(), s.leg_angles.copy(), p.fleet.thrust().copy(), any(p.uav_landed()),
                        s.quat.copy(), _centre_of_mass_height(p)))

    _run(plant, quats, command, 1.0, record)
    times = np.array([s[0] for s in samples]) - samples[0][0]
    positions = np.array([s[1] for s in samples])
    legs = np.degrees(np.array([s[2] for s in samples]) - start.leg_angles)
    thrusts = np.array([s[3] for s in samples])
    on_ground = np.array([s[4] for s in samples])
    tilts = np.degrees([2.0 * math.asin(min(1.0, math.hypot(q[1], q[2]))) for q in (s[5] for s in samples)])
    rise = positions[:, 2] - start.position[2]
    com_rise = np.array([s[6] for s in samples]) - _centre_of_mass_height_of(plant.params, start)
    half = times <= 0.5
    print(f"lift-off after {times[np.argmax(~on_ground)]:.3f} s; rise {rise[-1]:.3f} m (CoM {com_rise[-1]:.3f}); legs "
          f"{np.abs(legs[half]).max():.2f} deg (0.5 s), {np.abs(legs).max():.2f} deg (1 s); horizontal "
          f"{1e3 * np.abs(positions[:, :2] - start.position[:2]).max():.2f} mm; tilt {tilts.max():.3f} deg; "
          f"thrust max/command {(thrusts / command).max():.4f}")
    assert not on_ground[times >= 0.1].any()  # all feet off within 0.1 s, for good
    assert (thrusts <= 1.01 * command).all()  # no jump: the commanded thrust, never more
    assert thrusts[-1] == pytest.approx(command, rel=0.01)
    assert np.all(np.diff(rise[times >= 0.05]) > 0.0)  # climbs steadily
    # Newton on the whole robot: Σ thrust_z − m g = 0.05 m g, so the centre of mass rises ½·(0.05 g)·(1 s)² =
    # 0.245 m at most (minus the motor and lift-off lag); the platform alone also moves with the leg angles.
    assert 0.20 < com_rise[-1] <= 0.2453
    assert np.abs(positions[:, :2] - start.position[:2]).max() < 0.01  # vertical
    assert tilts.max() < 0.5
    assert np.abs(legs[half]).max() < 1.0
    assert np.abs(legs).max() < 4.0  # not folding (the report: -160 deg within 0.3 s)


@pytest.mark.parametrize("moments", [[0.4, -0.3, 0.0], [0.0, 0.0, 0.5], [0.3, 0.2, -0.4]])
def test_mixer_never_raises_the_collective_above_the_command(moments):
    """PX4 airmode off: a low collective with a large moment demand gives up moment authority, never thrust."""
    top = 9.4  # f_max/4 at 12.4 V [N]
    for collective in (0.0, 1.0, 3.4, 10.0):
        rotors = mix_one(collective, list(moments), ARM, KAPPA, top)
        assert sum(rotors) <= collective + 1e-9
        assert min(rotors) >= 0.0 and max(rotors) <= top
    # the moments keep their sign (reduced, not reversed) when some authority remains
    rotors = mix_one(3.4, [0.4, -0.3, 0.0], ARM, KAPPA, top)
    assert ARM * (rotors[1] - rotors[3]) > 0.0 and ARM * (rotors[2] - rotors[0]) < 0.0


def test_mixer_reduces_the_collective_at_the_top_and_yaw_first():
    top = 9.4
    # near full thrust with a roll demand: the collective is reduced, the roll moment kept
    rotors = mix_one(4 * top, [0.3, 0.0, 0.0], ARM, KAPPA, top)
    assert sum(rotors) < 4 * top
    assert ARM * (rotors[1] - rotors[3]) == pytest.approx(0.3)
    # a yaw demand far beyond the rotors' reach: yaw is cut (PX4 lets it use 15 % headroom above the top, then
    # takes that back from the collective, reduce only); the collective is never raised
    rotors = mix_one(20.0, [0.2, -0.1, 2.0], ARM, KAPPA, top)
    assert 20.0 - 4 * 0.15 * top <= sum(rotors) <= 20.0
    assert ARM * (rotors[1] - rotors[3]) > 0.0 and ARM * (rotors[2] - rotors[0]) < 0.0
    assert 0.0 < KAPPA * (-rotors[0] + rotors[1] - rotors[2] + rotors[3]) < 0.5
    # a moderate yaw demand that fits: roll, pitch, yaw and the collective all exact
    rotors = mix_one(20.0, [0.2, -0.1, 0.15], ARM, KAPPA, top)
    assert sum(rotors) == pytest.approx(20.0)
    assert ARM * (rotors[1] - rotors[3]) == pytest.approx(0.2)
    assert KAPPA * (-rotors[0] + rotors[1] - rotors[2] + rotors[3]) == pytest.approx(0.15)
    # unsaturated: the exact inverse of (3.41)
    rotors = mix_one(20.0, [0.1, -0.2, 0.03], ARM, KAPPA, top)
    assert sum(rotors) == pytest.approx(20.0)
    assert KAPPA * (-rotors[0] + rotors[1] - rotors[2] + rotors[3]) == pytest.approx(0.03)


def test_rate_integrator_frozen_while_landed_and_reset_while_disarmed():
    plant = _ground_plant()
    fleet = plant.fleet
    tilted = np.tile([math.cos(0.05), math.sin(0.05), 0.0, 0.0], (plant.n, 1))  # 5.7 deg roll setpoint
    command = AttitudeCommand(tilted, np.full(plant.n, 0.2), np.ones(plant.n, dtype=bool))
    fleet.control(command, landed=[True] * plant.n)
    assert np.abs(fleet.rate_integral).max() == 0.0
    fleet.control(command, landed=[False, True, True])
    airborne = fleet.rate_integral
    assert abs(airborne[0, 0]) > 0.0 and np.abs(airborne[1:]).max() == 0.0
    fleet.control(command, landed=[True] * plant.n)
    assert np.array_equal(fleet.rate_integral, airborne)  # frozen, not reset
    fleet.control(AttitudeCommand(tilted, np.zeros(plant.n), np.zeros(plant.n, dtype=bool)))
    assert np.abs(fleet.rate_integral).max() == 0.0  # disarmed: reset
