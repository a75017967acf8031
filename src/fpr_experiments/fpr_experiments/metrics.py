"""Flight metrics of one recorded flight (ROS-free: numpy), named as the thesis's table columns.

Every metric is computed from the ground truth (the simulator's motion capture) against what the controllers were
asked to do — their own desired state on ``diagnostics`` (:class:`~fpr_experiments.records.UavSeries`
``desired_*``, UAV 1's; every UAV tracks the same χ_d) — over the **tracking window**: every UAV airborne (its feet
above the ground), every bridge in OFFBOARD and the teleop in FLY. The thesis does not state its RMSE windows
(spec/thesis_experiments.md §2); Table 3.4's text suggests take-off and landing are included, and so they are
here as long as the robot is airborne under its controllers.

Definitions (the thesis's symbols, ASCII names):

- ``position_rmse_cm`` p_p: RMSE of the 3-D distance |p_p − p^d_p| (ground-truth / centralized modes only;
  the decentralized controllers have no position);
- ``position_xy_rmse_cm`` p_p,xy: RMSE of the horizontal distance (the RMS of the planar error norm; see spec N1);
- ``roll_rmse_deg``, ``pitch_rmse_deg`` ϕ_p, ϑ_p: ZYX roll / pitch of the platform vs the desired ones;
- ``legs_rmse_deg`` θ_l: the mean over the legs of each leg's RMSE (the thesis's "mean θ_l");
- ``force_z_rmse_n`` f̂_pz,e: RMSE of UAV 1's observer z force vs the true external z force (the payload weight,
  wind, contact: everything the plant applies that is not thrust, gravity of the structure or inertia);
- ``contact_force_rmse_n`` f^d_c: RMSE of desired minus estimated contact force −(R_pᵀ f̂_p,e)_z (3.45), over the
  samples where a contact force is asked (f^d_c > 0.1 N); ``contact_force_true_rmse_n`` the same against the
  board's true normal force (no force sensor on the robot: only a simulation can tell);
- per UAV i (``uav<i>.…``): ``aruco_<axis>`` / ``ekf_<axis>`` RMSE of the raw ArUco relative pose (4.2) and the
  EKF output against the true p T_bi (x, y, z [m]; roll, pitch, yaw [deg] of p q_i, Table 4.6); and
  ``detection_rate_pct``: successful detections (error < 10 cm and < 10°, Table 4.8) per camera frame;
  ``mocap_detection_pct``: with the thesis's motion-capture fallback, the share of the detections the estimator got
  that were emulated from the motion capture (§4.4.2);
- safety figures: ``max_abs_roll_deg`` / ``max_abs_pitch_deg`` (whole airborne flight), ``max_height_m``,
  ``max_excursion_m`` (horizontal, from the start), ``ground_contacts`` (UAVs touching the ground while the
  controllers fly, once the robot has taken off, unless the operator just commanded a descent: that is landing;
  touches before the take-off clearance are a take-off hop: ``takeoff_touchdowns``, not a check), ``nonfinite_samples``,
  ``swarm_emergencies`` (entries of the swarm into the bridges' emergency response: Hold, then land; why in
  metrics.json ``emergencies``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fpr_experiments.records import FlightRecord

#: a UAV whose feet are this far above the ground is airborne [m]
AIRBORNE_CLEARANCE = 0.03
#: a contact force is asked when the desired one is above this [N]
CONTACT_DEMAND = 0.1
#: Table 4.8's successful detection: errors below 10 cm and 10° (l.7114-7121)
DETECTION_POSITION_LIMIT = 0.10
DETECTION_ANGLE_LIMIT = math.radians(10.0)
#: [m] the robot has taken off once every UAV's feet have been this high together: a touch-down before it is the
#: take-off's (the structure lifting off and settling back, a hop, before the operator's climb), reported as
#: ``takeoff_touchdowns`` and not as a ground contact; a hop peaks at a few cm (table_3_7 Task 1 Case 2: 4.7 cm)
TAKEOFF_CLEARANCE = 0.15
#: [s] a touch-down this soon after a commanded descent is a landing, not a ground contact
GROUND_DESCENT_GRACE = 2.0
#: [s] after a payload attaches, the observers' estimate counts as converged (FOWO K_O = 2/s: e^-6 by 3 s)
LOADED_SETTLE = 3.0
#: a commanded vertical speed above this [m/s] starts a climb/descent segment
RATE_THRESHOLD = 0.05
#: the first seconds of a climb/descent segment are left out of the rate fit (lift-off, teleop low-pass)
RATE_SETTLE = 1.0


@dataclass(frozen=True)
class MetricInfo:
    unit: str
    description: str
    digits: int = 2


METRIC_INFO: dict[str, MetricInfo] = {
    "position_rmse_cm": MetricInfo("cm", "RMSE p_p (3-D platform position vs desired)", 1),
    "position_xy_rmse_cm": MetricInfo("cm", "RMSE p_p,xy (horizontal platform position vs desired)", 1),
    "roll_rmse_deg": MetricInfo("deg", "RMSE platform roll vs desired"),
    "pitch_rmse_deg": MetricInfo("deg", "RMSE platform pitch vs desired"),
    "legs_rmse_deg": MetricInfo("deg", "mean over the legs of the leg-angle RMSE"),
    "force_z_rmse_n": MetricInfo("N", "RMSE of the z external-force estimate vs the true one"),
    "force_z_final_n": MetricInfo("N", "z external-force estimate, mean of the last 2 s of the window"),
    "force_z_true_final_n": MetricInfo("N", "true z external force, mean of the last 2 s of the window"),
    "force_z_loaded_n": MetricInfo("N", "z force estimate while a payload is carried (3 s after it attached)"),
    "force_z_loaded_true_n": MetricInfo("N", "true z external force while a payload is carried"),
    "target_error_contact_cm": MetricInfo("cm", "RMS horizontal distance P - target while in contact", 1),
    "contact_force_rmse_n": MetricInfo("N", "RMSE desired - estimated contact force (while asked)"),
    "contact_force_true_rmse_n": MetricInfo("N", "RMSE desired - true contact force (while asked)"),
    "contact_force_max_n": MetricInfo("N", "largest true contact force"),
    "contact_time_s": MetricInfo("s", "time in contact with the board (true normal force > 0.1 N)", 1),
    "vertical_speed_rmse": MetricInfo("m/s", "RMSE vertical platform speed vs commanded", 3),
    "max_abs_roll_deg": MetricInfo("deg", "largest |platform roll| while airborne", 1),
    "max_abs_pitch_deg": MetricInfo("deg", "largest |platform pitch| while airborne", 1),
    "max_height_m": MetricInfo("m", "highest platform position", 2),
    "max_excursion_m": MetricInfo("m", "largest horizontal distance from the start", 2),
    "ground_contacts": MetricInfo("", "UAV ground touches while the controllers fly (no LAND), after take-off", 0),
    "takeoff_touchdowns": MetricInfo("", "UAV ground touches while the controllers fly, airborne but not yet "
                                         "15 cm up (a take-off hop; not a check)", 0),
    "nonfinite_samples": MetricInfo("", "ground-truth samples with NaN/inf", 0),
    "swarm_emergencies": MetricInfo("", "entries of the swarm into its emergency response (any UAV's bridge)", 0),
    "tracking_time_s": MetricInfo("s", "time inside the tracking window", 1),
    "fallback_fraction": MetricInfo("", "fraction of control periods in the NC fallback (all UAVs)", 3),
    "recovery_time_s": MetricInfo("s", "after the link is back: until no controller is in fallback", 2),
    "success_rate": MetricInfo("", "scripted-operator tasks accomplished / tasks (goto and push tasks)", 2),
    "tasks": MetricInfo("", "scripted-operator tasks ended (goto and push)", 0),
    "tasks_succeeded": MetricInfo("", "scripted-operator tasks accomplished", 0),
    "force_z_noise_n": MetricInfo("N", "std of the z force estimate around its 2-s moving mean", 3),
    "force_z_slope_n_per_s": MetricInfo("N/s", "slope of a line fit of the z force estimate", 4),
}
for _kind in ("aruco", "ekf"):
    for _axis, _unit in (("x", "m"), ("y", "m"), ("z", "m"), ("roll", "deg"), ("pitch", "deg"), ("yaw", "deg")):
        METRIC_INFO[f"{_kind}_{_axis}_{_unit}"] = MetricInfo(
            _unit, f"RMSE of the {'raw ArUco' if _kind == 'aruco' else 'EKF'} relative pose, {_axis}",
            3 if _unit == "m" else 2)
METRIC_INFO["detection_rate_pct"] = MetricInfo("%", "successful detections (< 10 cm, < 10 deg) per frame", 1)
METRIC_INFO["mocap_detection_pct"] = MetricInfo(
    "%", "detections the estimator got from the motion-capture fallback (thesis §4.4.2), not the camera", 1)


def metric_info(name: str) -> MetricInfo:
    """Info of ``name`` (``uav<i>.<metric>`` names share their metric's info)."""
    return METRIC_INFO.get(name.split(".")[-1], MetricInfo("", name))


# ------------------------------------------------------------------------------------------------ helpers
def hold(t_query: np.ndarray, t_source: np.ndarray, values: np.ndarray, before=-1) -> np.ndarray:
    """Zero-order hold of ``values`` (sampled at increasing ``t_source``) at ``t_query``; ``before`` ahead of
    the first sample."""
    values = np.asarray(values)
    if len(t_source) == 0:
        return np.full(len(t_query), before)
    index = np.searchsorted(t_source, t_query, side="right") - 1
    out = values[np.clip(index, 0, None)].copy()
    out[index < 0] = before
    return out


def interpolate(t_query: np.ndarray, t_source: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Linear interpolation of (K,) or (K, m) ``values``; NaN where there is no sample."""
    values = np.asarray(values, dtype=float)
    if len(t_source) == 0:
        return np.full((len(t_query),) + values.shape[1:], np.nan)
    if values.ndim == 1:
        return np.interp(t_query, t_source, values)
    return np.column_stack([np.interp(t_query, t_source, values[:, k]) for k in range(values.shape[1])])


def wrap(angle: np.ndarray) -> np.ndarray:
    return (np.asarray(angle) + math.pi) % (2.0 * math.pi) - math.pi


def rmse(error: np.ndarray) -> float:
    error = np.asarray(error, dtype=float)
    error = error[np.isfinite(error)] if error.ndim == 1 else error[np.all(np.isfinite(error), axis=1)]
    return float(np.sqrt(np.mean(error ** 2))) if error.size else math.nan


def airborne_mask(record: FlightRecord) -> np.ndarray:
    """Ground-truth samples where every UAV's feet are more than :data:`AIRBORNE_CLEARANCE` above z = 0."""
    truth = record.truth
    if len(truth.t) == 0:
        return np.zeros(0, dtype=bool)
    feet = truth.uav_positions[:, :, 2] - record.landing_gear_height
    return np.all(feet > AIRBORNE_CLEARANCE, axis=1)


def tracking_mask(record: FlightRecord) -> np.ndarray:
    """Airborne, teleop FLY and every bridge OFFBOARD (the controllers fly the robot)."""
    truth = record.truth
    mask = airborne_mask(record)
    if not len(mask):
        return mask
    mask &= hold(truth.t, record.command.t, record.command.mode) == record.names.fly_mode
    for uav in record.uavs:
        mask &= hold(truth.t, uav.status_t, uav.bridge_state) == record.names.offboard_state
    return mask


def desired_at(record: FlightRecord, t: np.ndarray) -> dict[str, np.ndarray]:
    """The controllers' desired state at ``t``: UAV 1's diagnostics (zero-order hold: a control period's value
    holds until the next), falling back to the teleop command for fields a controller did not report."""
    n = record.n
    c = record.command
    out = {"position": np.full((len(t), 3), np.nan),
           "roll": interpolate(t, c.t, c.roll) if len(c.t) else np.full(len(t), np.nan),
           "pitch": interpolate(t, c.t, c.pitch) if len(c.t) else np.full(len(t), np.nan),
           "yaw": np.full(len(t), np.nan),
           "legs": interpolate(t, c.t, c.legs) if len(c.t) else np.full((len(t), n), np.nan),
           "contact_force": interpolate(t, c.t, c.contact_force) if len(c.t) else np.zeros(len(t))}
    uav = record.uavs[0] if record.uavs else None
    if uav is None or len(uav.diagnostics_t) == 0:
        return out
    index = np.searchsorted(uav.diagnostics_t, t, side="right") - 1
    valid = index >= 0
    k = np.clip(index, 0, None)

    def held(values: np.ndarray) -> np.ndarray:
        result = values[k].astype(float)
        result[~valid] = np.nan
        return result

    position = held(uav.desired_position)
    ground_truth_mode = bool(np.any(np.abs(uav.desired_position[np.isfinite(uav.desired_position)]) > 0.0))
    if ground_truth_mode:  # zeros: a decentralized controller (no position, no yaw)
        out["position"] = position
        out["yaw"] = held(uav.desired_rpy[:, 2])

    def merge(reported: np.ndarray, fallback: np.ndarray) -> np.ndarray:
        """The controller's value where it reported one, the teleop command before (NaN rows)."""
        return np.where(np.isfinite(reported), reported, fallback)

    rpy = held(uav.desired_rpy)
    out["roll"], out["pitch"] = merge(rpy[:, 0], out["roll"]), merge(rpy[:, 1], out["pitch"])
    if uav.desired_legs.shape[1] == n:
        out["legs"] = merge(held(uav.desired_legs), out["legs"])
    out["contact_force"] = merge(held(uav.desired_contact_force), out["contact_force"])
    return out


def true_relative_poses(record: FlightRecord) -> tuple[np.ndarray, np.ndarray]:
    """True p T_bi of every UAV at the ground-truth samples: positions (N,n,3) [m] in Fp, quaternions (N,n,4)."""
    from fpr_model.rotations import quat_multiply, quat_to_rotmat

    truth = record.truth
    N, n = len(truth.t), record.n
    positions = np.zeros((N, n, 3))
    quats = np.zeros((N, n, 4))
    for k in range(N):
        q_p = truth.quat[k] / np.linalg.norm(truth.quat[k])
        R = quat_to_rotmat(q_p)
        conj = q_p * np.array([1.0, -1.0, -1.0, -1.0])
        for i in range(n):
            positions[k, i] = R.T @ (truth.uav_positions[k, i] - truth.position[k])
            quats[k, i] = quat_multiply(conj, truth.uav_quats[k, i])
    return positions, quats


def _euler(quats: np.ndarray) -> np.ndarray:
    from fpr_model.rotations import quat_to_euler_zyx

    return np.array([quat_to_euler_zyx(q / np.linalg.norm(q)) for q in quats]).reshape(-1, 3)


def _inside(t: np.ndarray, truth_t: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Samples at times ``t`` that fall in the window ``mask`` (defined on ``truth_t``)."""
    if len(truth_t) == 0:
        return np.zeros(len(t), dtype=bool)
    return hold(t, truth_t, mask.astype(int), before=0).astype(bool)


def _pose_errors(t: np.ndarray, positions: np.ndarray, quats: np.ndarray, truth_t: np.ndarray,
                 true_positions: np.ndarray, true_quats: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (K,3) [m] and ZYX angle (K,3) [rad] errors of estimates against the interpolated truth."""
    reference_p = interpolate(t, truth_t, true_positions)
    index = np.clip(np.searchsorted(truth_t, t), 0, len(truth_t) - 1)
    return positions - reference_p, wrap(_euler(quats) - _euler(true_quats[index]))


def _detection_ok(position_error: np.ndarray, quats: np.ndarray, true_quats: np.ndarray) -> np.ndarray:
    from fpr_model.rotations import quat_multiply

    angles = np.array([2.0 * math.acos(min(1.0, abs(float(quat_multiply(
        q * np.array([1.0, -1.0, -1.0, -1.0]) / np.linalg.norm(q), p)[0])))) for q, p in zip(quats, true_quats,
                                                                                           strict=True)])
    return (np.linalg.norm(position_error, axis=1) < DETECTION_POSITION_LIMIT) & (angles < DETECTION_ANGLE_LIMIT)


# ------------------------------------------------------------------------------------------------ metrics
def compute_metrics(record: FlightRecord, window: np.ndarray | None = None) -> dict[str, float]:
    """Every applicable metric of ``record`` (see the module doc); NaN where one does not apply. ``window`` (a
    mask over the ground-truth samples) defaults to :func:`tracking_mask`."""
    truth = record.truth
    mask = tracking_mask(record) if window is None else window
    metrics: dict[str, float] = {}
    dt = np.diff(truth.t, append=truth.t[-1]) if len(truth.t) else np.zeros(0)
    metrics["tracking_time_s"] = float(dt[mask].sum()) if len(mask) else 0.0
    t = truth.t[mask]
    desired = desired_at(record, t)
    deg = math.degrees(1.0)
    position_error = truth.position[mask] - desired["position"]
    metrics["position_rmse_cm"] = 100.0 * rmse(np.linalg.norm(position_error, axis=1))
    metrics["position_xy_rmse_cm"] = 100.0 * rmse(np.linalg.norm(position_error[:, :2], axis=1))
    metrics["roll_rmse_deg"] = deg * rmse(wrap(truth.rpy[mask, 0] - desired["roll"]))
    metrics["pitch_rmse_deg"] = deg * rmse(wrap(truth.rpy[mask, 1] - desired["pitch"]))
    legs_error = truth.legs[mask] - desired["legs"]
    per_leg = [rmse(legs_error[:, k]) for k in range(record.n)] if len(t) else []
    metrics["legs_rmse_deg"] = deg * float(np.mean(per_leg)) if per_leg else math.nan
    for k, value in enumerate(per_leg):
        metrics[f"leg{k + 1}_rmse_deg"] = deg * value

    # ---- wrench estimates against the truth: UAV 1's as the table value, every UAV's as uav<i>.*
    for k, u in enumerate(record.uavs):
        if not (len(u.wrench_t) and len(t)):
            continue
        prefix = "" if k == 0 else f"uav{u.uav_id}."
        for name, value in _force_metrics(record, u, t, mask, desired).items():
            metrics[prefix + name] = value
            if k == 0:
                metrics[f"uav{u.uav_id}.{name}"] = value
    if record.target_position is not None and len(truth.t):
        touching = mask & (truth.contact_force > CONTACT_DEMAND)
        if touching.any():
            offset = truth.position[touching, :2] - np.asarray(record.target_position[:2])
            metrics["target_error_contact_cm"] = 100.0 * rmse(np.linalg.norm(offset, axis=1))
    if len(truth.t):
        metrics["contact_force_max_n"] = float(truth.contact_force.max())
        metrics["contact_time_s"] = float(dt[truth.contact_force > CONTACT_DEMAND].sum())

    # ---- vertical speed vs command (velocities in F_Fp: z is the world z)
    c = record.command
    if len(c.t) and len(t):
        metrics["vertical_speed_rmse"] = rmse(truth.velocity[mask, 2] - interpolate(t, c.t, c.velocity[:, 2]))

    # ---- relative pose: raw ArUco and EKF vs truth (Table 4.6) and detection rate (Table 4.8)
    if len(t) and any(len(u.marker_t) or len(u.local_t) for u in record.uavs):
        true_p, true_q = true_relative_poses(record)
        for k, u in enumerate(record.uavs):
            prefix = f"uav{u.uav_id}."
            for kind, ts, ps, qs in (("aruco", u.marker_t, u.marker_position, u.marker_quat),
                                     ("ekf", u.local_t, u.local_position, u.local_quat)):
                inside = _inside(ts, truth.t, mask)
                if not inside.any():
                    continue
                p_err, a_err = _pose_errors(ts[inside], ps[inside], qs[inside], truth.t, true_p[:, k],
                                            true_q[:, k])
                for j, axis in enumerate("xyz"):
                    metrics[f"{prefix}{kind}_{axis}_m"] = rmse(p_err[:, j])
                for j, axis in enumerate(("roll", "pitch", "yaw")):
                    metrics[f"{prefix}{kind}_{axis}_deg"] = deg * rmse(a_err[:, j])
                if kind == "aruco":
                    index = np.clip(np.searchsorted(truth.t, ts[inside]), 0, len(truth.t) - 1)
                    ok = _detection_ok(p_err, qs[inside], true_q[index, k])
                    frames = metrics["tracking_time_s"] * record.camera_rate
                    metrics[f"{prefix}detection_rate_pct"] = 100.0 * min(1.0, ok.sum() / frames) if frames else \
                        math.nan

    # ---- the thesis's motion-capture fallback (§4.4.2): the share of emulated detections the estimators got
    for u in record.uavs:
        if len(u.checked_t):
            inside = _inside(u.checked_t, truth.t, mask)
            if inside.any():
                metrics[f"uav{u.uav_id}.mocap_detection_pct"] = 100.0 * float(u.checked_emulated[inside].mean())

    # ---- fallback and recovery
    periods = [len(u.fallback) for u in record.uavs]
    if sum(periods):
        metrics["fallback_fraction"] = float(sum(int(u.fallback.sum()) for u in record.uavs) / sum(periods))

    # ---- scripted operator's tasks
    tasks = [e for e in record.events if e.get("event") == "task_end" and e.get("kind") in ("goto", "push")]
    if tasks:
        metrics["tasks"] = float(len(tasks))
        metrics["tasks_succeeded"] = float(sum(bool(e.get("success")) for e in tasks))
        metrics["success_rate"] = metrics["tasks_succeeded"] / metrics["tasks"]

    metrics.update(safety_metrics(record))
    return metrics


def _force_metrics(record: FlightRecord, u, t: np.ndarray, mask: np.ndarray, desired: dict) -> dict[str, float]:
    """z-force estimate of one UAV's observer vs the truth; contact force while asked (see the module doc)."""
    truth = record.truth
    out: dict[str, float] = {}
    estimate = interpolate(t, u.wrench_t, u.wrench_force[:, 2])
    true_force = truth.external_wrench[mask, 2]
    out["force_z_rmse_n"] = rmse(estimate - true_force)
    last = t >= t[-1] - 2.0
    out["force_z_final_n"] = float(np.mean(estimate[last]))
    out["force_z_true_final_n"] = float(np.mean(true_force[last]))
    # carrying a payload (after LOADED_SETTLE s of convergence): Fig. 4.14's "converged to about -4 N"
    payload = truth.payload_mass[mask]
    attached = payload > 0.0
    if attached.any():
        since = np.zeros(len(t))
        start = -np.inf
        for k in range(len(t)):
            if attached[k] and (k == 0 or not attached[k - 1]):
                start = t[k]
            since[k] = t[k] - start if attached[k] else -1.0
        settled = since >= LOADED_SETTLE
        if settled.any():
            out["force_z_loaded_n"] = float(np.mean(estimate[settled]))
            out["force_z_loaded_true_n"] = float(np.mean(true_force[settled]))
    inside = _inside(u.wrench_t, truth.t, mask)
    series_t, series = u.wrench_t[inside], u.wrench_force[inside, 2]
    if len(series_t) > 20 and series_t[-1] - series_t[0] > 4.0:
        width = max(1, int(round(2.0 / np.median(np.diff(series_t)))))
        if len(series) > 2 * width:
            mean = np.convolve(series, np.ones(width) / width, mode="same")
            core = slice(width, len(series) - width)
            out["force_z_noise_n"] = float(np.std((series - mean)[core]))
        out["force_z_slope_n_per_s"] = float(np.polyfit(series_t, series, 1)[0])
    asked = desired["contact_force"] > CONTACT_DEMAND
    if asked.any():
        estimated_contact = interpolate(t, u.wrench_t, u.wrench_contact)
        out["contact_force_rmse_n"] = rmse((desired["contact_force"] - estimated_contact)[asked])
        out["contact_force_true_rmse_n"] = rmse((desired["contact_force"] - truth.contact_force[mask])[asked])
    return out


def recovery_time(record: FlightRecord, link_restored: float, hold_for: float = 1.0) -> float:
    """[s] from ``link_restored`` until every UAV is out of the NC fallback and stays out for ``hold_for`` s (a
    later fallback, e.g. once the robot has landed and the estimates go stale, is not this recovery); NaN if one
    never recovered."""
    latest = link_restored
    for u in record.uavs:
        t, fallback = u.diagnostics_t, u.fallback.astype(bool)
        recovered = math.nan
        for k in np.flatnonzero((t >= link_restored) & ~fallback):
            stays = (t >= t[k]) & (t <= t[k] + hold_for)
            if not fallback[stays].any():  # out for hold_for s (or until the record ends)
                recovered = float(t[k])
                break
        if math.isnan(recovered):
            return math.nan
        latest = max(latest, recovered)
    return latest - link_restored


def safety_metrics(record: FlightRecord) -> dict[str, float]:
    """Flip / fly-away / ground-touch figures of the whole flight (see the module doc)."""
    truth = record.truth
    out: dict[str, float] = {"nonfinite_samples": 0.0, "ground_contacts": 0.0, "takeoff_touchdowns": 0.0}
    if len(truth.t) == 0:
        return out
    finite = np.all(np.isfinite(truth.position), axis=1) & np.all(np.isfinite(truth.rpy), axis=1)
    out["nonfinite_samples"] = float(np.count_nonzero(~finite))
    airborne = airborne_mask(record)
    deg = math.degrees(1.0)
    if airborne.any():
        out["max_abs_roll_deg"] = deg * float(np.max(np.abs(truth.rpy[airborne, 0])))
        out["max_abs_pitch_deg"] = deg * float(np.max(np.abs(truth.rpy[airborne, 1])))
    out["max_height_m"] = float(np.nanmax(truth.position[:, 2]))
    out["max_excursion_m"] = float(np.nanmax(np.linalg.norm(truth.position[:, :2] - truth.position[0, :2],
                                                            axis=1)))
    # a UAV's feet on the ground while the controllers fly (OFFBOARD + FLY), after the robot has taken off
    # (TAKEOFF_CLEARANCE), unless the operator was bringing it down (a descent commanded in the last
    # GROUND_DESCENT_GRACE s): landing. Airborne before it (feet above AIRBORNE_CLEARANCE) and back on the
    # ground: a take-off hop, counted apart (takeoff_touchdowns)
    flying = hold(truth.t, record.command.t, record.command.mode) == record.names.fly_mode
    for u in record.uavs:
        flying &= hold(truth.t, u.status_t, u.bridge_state) == record.names.offboard_state
    feet = truth.uav_positions[:, :, 2] - record.landing_gear_height
    was_airborne = np.cumsum(airborne) > 0
    taken_off = np.cumsum(np.all(feet > TAKEOFF_CLEARANCE, axis=1)) > 0
    touching = np.any(feet < 0.005, axis=1)
    hops = np.diff(np.concatenate([[0], (touching & flying & was_airborne & ~taken_off).astype(int)])) == 1
    out["takeoff_touchdowns"] = float(np.count_nonzero(hops))
    c = record.command
    descending = np.zeros(len(truth.t), dtype=bool)
    if len(c.t):
        down = c.t[c.velocity[:, 2] < -RATE_THRESHOLD]
        if len(down):
            k = np.searchsorted(down, truth.t, side="right") - 1
            descending = (k >= 0) & (truth.t - down[np.clip(k, 0, None)] <= GROUND_DESCENT_GRACE)
    events = np.diff(np.concatenate([[0], (touching & flying & taken_off & ~descending).astype(int)])) == 1
    out["ground_contacts"] = float(np.count_nonzero(events))
    out["swarm_emergencies"] = float(swarm_emergencies(record))
    return out


def swarm_emergencies(record: FlightRecord) -> int:
    """How many times the swarm entered its emergency response: rising edges of "some UAV's bridge is in
    EMERGENCY" over the union of the status instants (every UAV following one root cause counts once)."""
    emergency = record.names.emergency_state
    times = np.unique(np.concatenate([u.status_t for u in record.uavs] + [np.zeros(0)]))
    if len(times) == 0:
        return 0
    some = np.zeros(len(times), dtype=bool)
    for u in record.uavs:
        if len(u.status_t):
            some |= hold(times, u.status_t, u.bridge_state) == emergency
    return int(np.count_nonzero(np.diff(np.concatenate([[0], some.astype(int)])) == 1))


@dataclass
class RateSegment:
    """A climb or descent: commanded vs achieved vertical speed (linear fit of the height), [m/s]."""

    start: float
    end: float
    commanded: float
    achieved: float


def rate_segments(record: FlightRecord) -> list[RateSegment]:
    """Climbs and descents: runs of FLY commands with |v_z,d| > :data:`RATE_THRESHOLD`, compared from
    :data:`RATE_SETTLE` s after the run starts (teleop low-pass) over the samples where the command is at least
    90 % of its peak; achieved = slope of a line fit of the true height, commanded = mean command there."""
    c, truth = record.command, record.truth
    if len(c.t) < 2 or len(truth.t) < 2:
        return []
    vz = c.velocity[:, 2]
    active = (np.abs(vz) > RATE_THRESHOLD) & (c.mode == record.names.fly_mode)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], active.astype(int), [0]])))
    segments = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        for sign in (1.0, -1.0):
            run = np.arange(a, b)[np.sign(vz[a:b]) == sign]
            if len(run) == 0:
                continue
            peak = np.abs(vz[run]).max()
            plateau = run[(np.abs(vz[run]) >= 0.9 * peak) & (c.t[run] >= c.t[run[0]] + RATE_SETTLE)]
            if len(plateau) == 0:
                continue
            t0, t1 = float(c.t[plateau[0]]), float(c.t[plateau[-1]])
            window = (truth.t >= t0) & (truth.t <= t1)
            if window.sum() < 10:
                continue
            achieved = float(np.polyfit(truth.t[window], truth.position[window, 2], 1)[0])
            commanded = float(np.mean(np.interp(truth.t[window], c.t, vz)))
            segments.append(RateSegment(start=t0, end=t1, commanded=commanded, achieved=achieved))
    return sorted(segments, key=lambda s: s.start)
