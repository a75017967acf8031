"""Oracle test of the plant: it must reproduce frozen reference trajectories (plant_oracle_cases.py) to ~1e-10.

History of data/plant_oracle.npz (regenerate ONLY after a deliberate change of the physics, with the generator):

1. recorded with the numpy-vectorized plant of commit 99797a6; the scalar (plain-float) rewrite of commit fbd8882
   reproduced it to 1e-10, which is what pinned the speed-up;
2. regenerated (``python src/fpr_sim/test/plant_oracle_cases.py``) with the scalar plant after the ground /
   take-off fix, because that fix deliberately changes the physics: PX4's airmode-off mixer (the collective is
   never raised to desaturate; the old reference delivered 17.3 N for a 12.6 N command in board_push and 18-25 N
   in payload_drop once the legs folded), the rate integrator frozen while landed, the landing gear's yaw
   friction and tipping-bounded levelling moment, and the hover start with the battery already under its hover
   load. Before regenerating, the changed plant was checked against the old reference: it reproduced
   hover_commands, wind_wrench and n4_ideal over their whole duration (≤ 1e-9) and the others up to the first
   step where a changed mechanism acts (mixer desaturation: payload_drop at 1.228 s, board_push at 0.168 s;
   armed on the ground: ground_takeoff and n4_controlled_ground from t = 0);
3. regenerated after correcting the direction of the spherical joint on the quadrotor (plant.py): B_iS_i =
   d·Rz(−β)·e_x, which with the yaw rule (3.37) faces the leg; the earlier Rz(+β) put the joint 90° sideways.
   This changes the joint-offset moment (2.93) and hence every flying case. Same change: the default rate-loop
   integral gains to PX4's I/P ratio (rate_i_gain 0.2 -> 1.2 on roll/pitch, 0.1 -> 0.6 on yaw).

NOT regenerated when the legs' mechanical joint stops were added (scenario ``joint_stops``, default [10°, 92°]):
inside the stops the physics is unchanged (the stop moment is added only outside them), and five cases stay
within 45°-88°. board_push (legs to −107°) and payload_drop (−221° to +132°) do leave that range, so they run
with the stops disabled (plant_oracle_cases._NO_STOPS) and keep pinning the unstopped dynamics; the data file is
the one of step 3, reproduced unchanged by both kernels.

4. ``external_wrench`` of the three wind cases (wind_wrench, ground_takeoff, n4_ideal) only, when the reported
   true τ_e (Plant.external_wrench) gained the legs' wind drag at their middles, which the dynamics always had
   but the report left out (the fan's force on the legs must be in the ground truth). Updated in place, not
   regenerated: the current plant was checked to reproduce every other array of the file (≤ 1e-10), and these
   three to 1e-12 with the legs' drag removed from the report again; the physics did not change. The air
   velocity became per body point (platform centre, quadrotors, leg middles, for the fan's jet): with a
   uniform wind the arithmetic is the same as before.

Both implementations of the plant replay the same frozen reference: the pure-Python one (the reference code)
and the optional compiled kernel (fpr_sim._kernels, C): ``kernel`` is parametrized. The compiled variant fails
(does not skip) when a C compiler exists but the kernel is missing, so a broken build cannot pass unseen.

What it pins now: every kernel of the 1 kHz loop (structure RK4, ground and board contact, wind, payload, the
PX4 loops and mixer, motors, battery) through closed-loop runs of 1.5-2 s; agreement to ~1e-10 (rounding only,
amplified by the loops; the specific forces are a finite difference over dt, hence the looser bound).
``test_oracle_detects_a_small_physics_change`` shows the comparison fails for a 0.1 % change of one parameter.
"""

import dataclasses
import importlib.util
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from fpr_sim._kernels import kernel_status

_SPEC = importlib.util.spec_from_file_location("plant_oracle_cases", Path(__file__).with_name("plant_oracle_cases.py"))
cases = importlib.util.module_from_spec(_SPEC)
sys.modules.setdefault("plant_oracle_cases", cases)  # dataclasses need the module registered
_SPEC.loader.exec_module(cases)

#: absolute tolerance per recorded quantity, in units of max(1, max |reference|) of that quantity
TOLERANCE = {"specific_forces": 1e-9}
DEFAULT_TOLERANCE = 1e-10


@pytest.fixture(scope="module")
def reference():
    return np.load(cases.DATA)


@pytest.fixture(params=["python", "compiled"])
def kernel(request) -> str:
    """The plant implementation under test; 'compiled' must be available wherever a C compiler is."""
    if request.param == "compiled" and not kernel_status().available:
        if shutil.which("cc") or shutil.which("gcc"):
            pytest.fail(f"a C compiler exists but the compiled kernel is unavailable: {kernel_status().reason}")
        pytest.skip("no C compiler on this machine: the compiled kernel cannot be built")
    return request.param


def _mismatches(name: str, result: dict, reference) -> list[str]:
    """The recorded quantities of case ``name`` that differ from the reference beyond their tolerance."""
    if len(result["time"]) != len(reference[f"{name}/time"]):
        return ["time: sample count differs"]
    out = []
    for key, value in result.items():
        expected = reference[f"{name}/{key}"]
        if value.shape != expected.shape:
            out.append(f"{name}/{key}: shape {value.shape} != {expected.shape}")
            continue
        if not np.array_equal(np.isnan(value), np.isnan(expected)):
            out.append(f"{name}/{key}: contact pattern differs")
            continue
        scale = max(1.0, float(np.nanmax(np.abs(expected))) if np.isfinite(expected).any() else 1.0)
        error = float(np.nanmax(np.abs(value - expected))) if np.isfinite(expected).any() else 0.0
        if not error <= TOLERANCE.get(key, DEFAULT_TOLERANCE) * scale:
            out.append(f"{name}/{key}: error {error:.2e}")
    return out


@pytest.mark.parametrize("case", cases.CASES, ids=lambda c: c.name)
def test_plant_matches_frozen_reference(case, reference, kernel):
    assert _mismatches(case.name, cases.run_case(case, kernel=kernel), reference) == []


def test_oracle_detects_a_small_physics_change(reference, kernel):
    """The comparison is sensitive: a 0.1 % longer motor time constant is caught (rotors, attitudes, state)."""
    case = next(c for c in cases.CASES if c.name == "ground_takeoff")
    quadrotor = dict(case.scenario.get("quadrotor", {}), motor_time_constant=0.008 * 1.001)
    perturbed = dataclasses.replace(case, scenario=dict(case.scenario, quadrotor=quadrotor))
    mismatches = _mismatches(case.name, cases.run_case(perturbed, kernel=kernel), reference)
    assert any("/rotors" in m for m in mismatches) and any("/x" in m for m in mismatches), mismatches


def test_reference_is_not_trivial(reference):
    """The cases exercise what they claim: contact with the ground and the board, flight, payload, wind."""
    assert reference["board_push/contact_force"].max() > 1.0
    takeoff = reference["ground_takeoff/anchors"]
    assert np.isfinite(takeoff[1, :3]).all() and np.isnan(takeoff[-1]).all()  # on the ground, then airborne
    assert np.abs(reference["wind_wrench/external_wrench"]).max() > 0.1
    x = reference["payload_drop/x"]
    assert np.ptp(x[:, 2]) > 0.05
