"""Contact guard (fpr_control.contact_guard): a contact-force demand that finds no contact is faded out.

The rule on its own (pure steps), then the decentralized impedance on the fpr_model dynamics (no ROS,
:mod:`closed_loop`): measured before the guard, a 10 N demand in free air climbed at f^d_c / B^d_p = 1 m/s for as
long as it was held, and a board that went away under a 5 N push did the same.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from closed_loop import HARNESS_PLAUSIBILITY, Sim, command, hover_state
from fpr_control.contact_guard import IDLE, LOST, PUSHING, ContactGuard, ContactGuardConfig
from fpr_control.controller import Controller, ControllerConfig, gains_from_dict
from fpr_model.parameters import default_parameters
from fpr_model.rotations import quat_to_euler_zyx

DT = 0.02
PARAMS = default_parameters(3)
YAW_OFFSETS = np.array([0.0, 1.0, -2.0])
LEG = math.radians(45.0)


def _steps(guard: ContactGuard, count: int, demanded: float, estimated: float, speed: float):
    return [guard.step(demanded, estimated, speed, DT) for _ in range(count)]


def test_free_travel_declares_the_contact_lost_then_fades_and_latches():
    guard = ContactGuard()
    steps = _steps(guard, 15, 10.0, 0.0, 1.0)  # 0.30 m after 15 steps: not yet more than max_free_travel
    assert all(s.state == PUSHING and s.applied_force == 10.0 for s in steps)
    lost = guard.step(10.0, 0.0, 1.0, DT)
    assert lost.state == LOST and "contact lost" in lost.event and "max_free_travel" in lost.event
    assert lost.applied_force == pytest.approx(10.0 - 20.0 * DT)
    fading = _steps(guard, 40, 10.0, 0.0, 1.0)
    applied = [s.applied_force for s in fading]
    assert all(b <= a for a, b in zip(applied, applied[1:], strict=False)), "the fade is monotonic"
    assert applied[23] == 0.0 and applied[-1] == 0.0, "10 N at 20 N/s: 0 after 0.5 s"
    assert all(s.event is None and s.state == LOST for s in fading), "latched, said once"
    # a board met again does not restart the push: the operator must release first
    assert guard.step(10.0, 10.0, 0.0, DT).applied_force == 0.0
    released = guard.step(0.0, 0.0, 0.0, DT)
    assert released.state == IDLE and "re-armed" in released.event
    again = guard.step(5.0, 0.0, 0.0, DT)
    assert again.state == PUSHING and again.applied_force == 5.0


def test_a_met_contact_resets_the_search_and_a_blocked_push_times_out():
    guard = ContactGuard()
    for _ in range(20):  # 10 s alternating: slips of 0.25 s, each shorter than the travel and time bounds
        assert _steps(guard, 12, 8.0, 0.5, 1.0)[-1].state == PUSHING
        assert _steps(guard, 13, 8.0, 8.0 * 0.3, 0.0)[-1].state == PUSHING
    # pressing without contact and without moving (stuck on something the observer does not see): max_unmet_time
    guard = ContactGuard(ContactGuardConfig(max_unmet_time=1.01))
    steps = _steps(guard, 51, 8.0, 0.0, -0.5)
    assert steps[49].state == PUSHING and steps[50].state == LOST and "max_unmet_time" in steps[50].event


def test_passes_through_when_not_tracking_disabled_or_not_engaged():
    guard = ContactGuard()
    assert all(s.applied_force == 10.0 and s.state == IDLE
               for s in (guard.step(10.0, 0.0, 5.0, DT, tracking=False) for _ in range(100)))
    off = ContactGuard(ContactGuardConfig(enabled=False))
    assert all(s.applied_force == 10.0 for s in _steps(off, 100, 10.0, 0.0, 5.0))
    small = ContactGuard()
    assert all(s.applied_force == 0.4 and s.state == IDLE for s in _steps(small, 100, 0.4, 0.0, 5.0))
    assert ContactGuard().step(math.nan, 0.0, 0.0, DT).applied_force == 0.0


@pytest.mark.parametrize("bad", [{"min_fraction": 0.0}, {"max_free_travel": 0.0}, {"fade_rate": -1.0},
                                 {"engage_force": math.inf}, {"max_unmet_time": math.nan}])
def test_config_is_validated(bad):
    with pytest.raises(ValueError):
        ContactGuardConfig(**bad)


# ---- closed loop: decentralized impedance (Table 4.5), exact local states, perfect link ------------------------------
def _controllers(guard: ContactGuardConfig) -> list[Controller]:
    return [Controller(PARAMS, ControllerConfig(
        uav_id=i + 1, info_plausibility=HARNESS_PLAUSIBILITY, mode="impedance", gains=gains_from_dict({}, 3),
        state_source="local", contact_guard=guard)) for i in range(3)]


def _fly(sim: Sim, duration: float, force: float) -> list[tuple[float, float, float, list]]:
    """(t, z [m], v_z [m/s], outputs) every control period."""
    rows = []
    cmd = command(3, leg=LEG, force=force)
    for _ in range(int(round(duration / DT))):
        outputs = sim.run(DT, cmd)
        rows.append((sim.t, sim.q[2], sim.nu[2], outputs))
    return rows


@pytest.mark.parametrize("enabled", [False, True])
def test_a_demand_in_free_air_stops_instead_of_climbing(enabled):
    """10 N asked with nothing above: without the guard the robot climbs at f^d_c / B^d_p = 1 m/s as long as it
    is held (4 m in 4 s); with it, it stops after max_free_travel, the fade and the impedance's own decay M^d/B^d
    = 0.5 s (0.9 m in all) and hovers, the
    operator's demand still reported, the applied one 0, each UAV's guard in LOST."""
    q, nu = hover_state(PARAMS, leg_angle=LEG, height=1.5)
    sim = Sim(PARAMS, _controllers(ContactGuardConfig(enabled=enabled)), q, nu, YAW_OFFSETS)
    rows = _fly(sim, 4.0, 10.0)
    climb = rows[-1][1] - 1.5
    if not enabled:
        assert rows[-1][2] == pytest.approx(1.0, abs=0.05) and climb > 3.0
        return
    assert climb < 1.0, f"climbed {climb:.2f} m"
    assert abs(rows[-1][2]) < 0.05, "still moving"
    final = rows[-1][3]
    assert [o.contact_guard_state for o in final] == [LOST] * 3
    assert all(o.applied_contact_force == 0.0 and o.desired.contact_force == 10.0 for o in final)
    events = [o.contact_guard_event for _, _, _, outs in rows for o in outs if o.contact_guard_event]
    assert len(events) == 3 and all("contact lost" in e for e in events), "once per UAV"
    roll, pitch, _ = quat_to_euler_zyx(sim.q[3:7])
    assert max(abs(roll), abs(pitch)) < math.radians(1.0)


def test_a_board_that_goes_away_under_the_push():
    """5 N on a stiff ceiling 5 cm above (tracked as before the guard: test_impedance_payload), then the ceiling is
    gone at 6 s: the robot stops within 1 m instead of flying on at 0.5 m/s."""
    q, nu = hover_state(PARAMS, leg_angle=LEG, height=1.5)
    ceiling = q[2] + 0.05

    def contact(q, nu):
        depth = q[2] - ceiling
        force = max(0.0, 5000.0 * depth + 100.0 * nu[2]) if depth > 0.0 and sim.t < 6.0 else 0.0
        return np.array([0.0, 0.0, -force, 0, 0, 0, 0, 0, 0])

    sim = Sim(PARAMS, _controllers(ContactGuardConfig()), q, nu, YAW_OFFSETS, external=contact)
    pushing = _fly(sim, 6.0, 5.0)
    assert all(o.contact_guard_state == PUSHING and o.applied_contact_force == 5.0 for o in pushing[-1][3])
    assert pushing[-1][3][0].contact_force == pytest.approx(5.0, rel=0.05)
    after = _fly(sim, 4.0, 5.0)
    assert after[-1][1] - ceiling < 1.0 and abs(after[-1][2]) < 0.05
    assert all(o.contact_guard_state == LOST for o in after[-1][3])
