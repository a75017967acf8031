"""Reference outputs of :meth:`fpr_control.controller.Controller.step` on random inputs, for every mode.

The scenarios (random local estimates, peers' ζ_j, teleoperation commands, ground truth; stale peers, bad inputs,
a singular leg angle, holds without a command) are generated here from fixed seeds, so the test
``test_controller_reference.py`` replays exactly the inputs that produced the fixture and compares the outputs.

The fixture ``data/controller_reference.npz`` was recorded with the controller of commit 00348cc (before the
hot-path optimisation of the "Speed and determinism" issue); its SOWO cases were re-recorded on 2026-12-07, when
the SOWO's reset started keeping its estimate (fpr_control.observers). Re-record it only on purpose, when the
controller's results are meant to change, and only the cases meant to change:

    .venv/bin/python src/fpr_control/test/controller_reference.py [--only _sowo_]  # data/controller_reference.npz
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
for _path in (os.path.dirname(_HERE), os.path.join(os.path.dirname(os.path.dirname(_HERE)), "fpr_model")):
    if _path not in sys.path:
        sys.path.insert(0, _path)

from fpr_control.controller import (  # noqa: E402
    MODE_CODES,
    Controller,
    ControllerConfig,
    ControlOutput,
    GroundTruth,
    gains_from_dict,
)
from fpr_control.information import InfoPlausibility, LocalEstimate, PeerInfo  # noqa: E402
from fpr_control.reference import TeleopReference  # noqa: E402
from fpr_model.parameters import default_parameters  # noqa: E402
from fpr_model.rotations import euler_zyx_to_quat  # noqa: E402

FIXTURE = os.path.join(_HERE, "data", "controller_reference.npz")
STEPS = 40
#: (mode, observer, state_source, impedance_force_input): every controller variant of the node
CASES = (
    ("communicating", "fowo", "local", "interaction"),
    ("non_communicating", "fowo", "local", "interaction"),
    ("impedance", "fowo", "local", "interaction"),
    ("impedance", "smwo", "local", "interaction"),
    ("impedance", "sowo", "local", "full"),
    ("pd", "fowo", "local", "interaction"),
    ("pd_compensated", "smwo", "local", "interaction"),
    ("centralized", "fowo", "ground_truth", "interaction"),
    ("impedance", "fowo", "ground_truth", "interaction"),
    ("impedance", "smwo", "ground_truth", "interaction"),
    ("pd", "sowo", "ground_truth", "interaction"),
    ("pd_compensated", "fowo", "ground_truth", "interaction"),
)
SIZES = (3, 6)


#: The scenarios draw every ζ_j at random each step (a numerical regression of the control step, not a flight):
#: the ζ plausibility checks (fpr_control.information, issue 12) are off, every bound out of reach.
UNCHECKED = InfoPlausibility(leg_angle_min=0.0, leg_angle_max=math.pi, max_speed=1e9, max_thrust=1e9,
                             max_leg_rate=1e9, max_angular_rate=1e9, max_acceleration=1e9)


#: the fixture was recorded when the PIDs' default anti-windup had an integral zone; the reference keeps it (the
#: default is now the thesis's saturation-only rule, integral_zone .inf: covered by test_laws_setpoints)
RECORDED_GAINS = {group: {"integral_zone": [0.1, 0.02, 0.02]} for group in ("pid_centralized", "pid_decentralized")}


def case_names() -> list[str]:
    return [f"n{n}_{mode}_{observer}_{source}_{force}" for n in SIZES for mode, observer, source, force in CASES]


def _unit_quat(rng, tilt: float) -> np.ndarray:
    return euler_zyx_to_quat(rng.normal(0.0, tilt), rng.normal(0.0, tilt), rng.uniform(-math.pi, math.pi))


def _command(rng, n: int) -> TeleopReference:
    ref = TeleopReference(
        platform_velocity=rng.normal(0.0, 0.2, 3), platform_acceleration=rng.normal(0.0, 0.2, 3),
        yaw_rate=float(rng.normal(0.0, 0.2)), yaw_acceleration=float(rng.normal(0.0, 0.2)),
        roll=float(rng.normal(0.0, 0.15)), roll_rate=float(rng.normal(0.0, 0.1)),
        pitch=float(rng.normal(0.0, 0.15)), pitch_rate=float(rng.normal(0.0, 0.1)),
        leg_angles=rng.uniform(0.4, 1.3, n), leg_rates=rng.normal(0.0, 0.1, n),
        contact_force=float(rng.uniform(0.0, 5.0)) if rng.random() < 0.5 else 0.0,
        mode=2 if rng.random() < 0.85 else 0)
    return ref


def run_case(index: int) -> list[ControlOutput]:
    """Replay scenario ``index`` (of :func:`case_names`) through a fresh controller; returns the outputs."""
    n = SIZES[index // len(CASES)]
    mode, observer, source, force = CASES[index % len(CASES)]
    rng = np.random.default_rng(1000 + index)
    params = default_parameters(n)
    own = 1 + index % n
    controller = Controller(params, ControllerConfig(uav_id=own, mode=mode, gains=gains_from_dict(RECORDED_GAINS, n),
                                                     info_plausibility=UNCHECKED,
                                                     observer=observer, state_source=source,
                                                     impedance_force_input=force))
    silent_peer = 1 + (own % n)  # a peer whose ζ stops for steps 18-32 (fallback to NC and back)
    outputs = []
    for k in range(STEPS):
        t = 0.02 * k
        for j in range(1, n + 1):
            if j == silent_peer and 18 <= k < 33:
                continue
            info = PeerInfo(j, float(rng.uniform(0.35, 1.35)), rng.normal(0.0, 0.3, 3), _unit_quat(rng, 0.2),
                            float(rng.uniform(4.0, 20.0)))
            controller.receive_info(info, t)
        local = LocalEstimate(
            leg_angle=float(rng.uniform(0.35, 1.35)), platform_roll=float(rng.normal(0.0, 0.15)),
            platform_pitch=float(rng.normal(0.0, 0.15)), attitude=_unit_quat(rng, 0.2),
            velocity=rng.normal(0.0, 0.3, 3), relative_yaw=float(rng.uniform(-math.pi, math.pi)),
            uav_yaw=float(rng.uniform(-math.pi, math.pi)), valid=bool(rng.random() < 0.95))
        quat = _unit_quat(rng, 0.15)
        truth = GroundTruth(rng.normal(0.0, 1.0, 3), quat * rng.uniform(0.9, 1.1), rng.normal(0.0, 0.3, 3),
                            rng.normal(0.0, 0.3, 3), rng.uniform(0.35, 1.35, n), rng.normal(0.0, 0.3, n),
                            np.array([_unit_quat(rng, 0.2) for _ in range(n)]))
        cmd = _command(rng, n) if rng.random() < 0.9 else None
        yaw_local = float(rng.uniform(-math.pi, math.pi)) if rng.random() < 0.5 else None
        if k == 7:
            local.velocity[1] = math.nan  # non-finite own state: the last valid one is used
        if k == 11 and cmd is not None:
            cmd.pitch = math.inf  # non-finite command: hold
        if k == 15:
            local.leg_angle = 0.0  # singular (decentralized): the step fails and holds
            truth.leg_angles[:] = 1e-7  # singular (ground truth): cond(J) > CONDITION_LIMIT
        if k == 35:
            truth.platform_quat[:] = math.nan
        outputs.append(controller.step(t, local, cmd, truth, yaw_local))
    return outputs


def _nan(shape) -> np.ndarray:
    return np.full(shape, math.nan)


def record(outputs: list[ControlOutput], n: int) -> dict[str, np.ndarray]:
    """The compared fields of the outputs as arrays with a leading step axis (NaN where a field is None)."""
    def stack(get, shape):
        return np.array([_nan(shape) if get(o) is None else np.asarray(get(o), dtype=float) for o in outputs])

    return {
        "attitude": stack(lambda o: o.attitude, (4,)),
        "thrust": stack(lambda o: o.thrust, ()),
        "thrust_vectors": stack(lambda o: o.thrust_vectors, (n, 3)),
        "wrench": stack(lambda o: o.wrench, (6 + n,)),
        "contact_force": stack(lambda o: o.contact_force, ()),
        "info_ages": stack(lambda o: o.info_ages, (n,)),
        "info": stack(lambda o: None if o.info is None else np.concatenate(
            [[o.info.leg_angle, o.info.thrust], o.info.velocity, o.info.attitude]), (9,)),
        "desired": stack(lambda o: None if o.desired is None else np.concatenate(
            [o.desired.position, [o.desired.roll, o.desired.pitch, o.desired.yaw, o.desired.contact_force],
             o.desired.leg_angles]), (7 + n,)),
        "flags": np.array([[MODE_CODES[o.active_mode], o.fallback_active, o.thrust_saturated, o.tilt_saturated,
                            o.local_state_valid, o.state_ok] for o in outputs], dtype=np.int8),
        "warning": np.array([o.warning or "" for o in outputs]),
    }


def warning_codes(warnings: np.ndarray, table: list[str]) -> np.ndarray:
    """Index of each warning in ``table`` (appended when new): the fixture stores each text once."""
    for text in warnings:
        if text not in table:
            table.append(str(text))
    return np.array([table.index(text) for text in warnings], dtype=np.int8)


def main() -> None:
    """Record every case, or with ``--only TEXT`` re-record the cases whose name contains TEXT and keep the
    others' recorded outputs as they are."""
    only = sys.argv[sys.argv.index("--only") + 1] if "--only" in sys.argv else None
    arrays, table = {}, [""]
    if only is not None:
        with np.load(FIXTURE) as data:
            kept = {key: data[key] for key in data.files}
        table = [str(text) for text in kept.pop("warnings")]
        arrays = {key: value for key, value in kept.items() if only not in key.split("/")[0]}
    for index, name in enumerate(case_names()):
        if only is not None and only not in name:
            continue
        n = SIZES[index // len(CASES)]
        fields = record(run_case(index), n)
        flags = fields["flags"]
        print(f"{name:48s} state_ok {flags[:, 5].sum():2d}/{STEPS}  fallback {flags[:, 1].sum():2d}  "
              f"thrust sat {flags[:, 2].sum():2d}  tilt sat {flags[:, 3].sum():2d}  "
              f"warnings {np.count_nonzero(fields['warning']):2d}")
        fields["warning"] = warning_codes(fields["warning"], table)
        arrays.update({f"{name}/{key}": value for key, value in fields.items()})
    arrays["warnings"] = np.array(table)
    os.makedirs(os.path.dirname(FIXTURE), exist_ok=True)
    np.savez_compressed(FIXTURE, **arrays)
    print(f"wrote {FIXTURE} ({os.path.getsize(FIXTURE)} bytes)")


if __name__ == "__main__":
    main()
