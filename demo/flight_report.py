"""Flight metrics, summary table and PNG plots of a simulated FPR swarm flight (ROS-free: numpy + matplotlib).

The demo (``demo/run_demo.py``) turns what its recorder kept into a :class:`FlightRecord` of numpy arrays
(simulation time [s], SI units, angles in rad) and calls :func:`compute_metrics`, :func:`format_summary`,
:func:`write_metrics_json` and :func:`write_plots`. Degrees appear only here, in the report (DESIGN.md §2).

Commanded values are the teleop command χ_d (thesis (4.25)) the controllers received on ``/fpr/teleop``:
platform velocity in the flat frame F_Fp (z up, platform yaw), platform roll/pitch in F_Fp, leg angles θ_l. The
ground truth's ZYX roll/pitch of the platform are angles in F_Fp as well, so they compare directly; the velocity
command is rotated into the world frame by the true platform yaw.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field

import numpy as np

#: a platform this much above its lowest recorded height [m] counts as airborne (tracking window)
AIRBORNE_CLEARANCE = 0.05
#: a commanded vertical speed above this [m/s] starts a climb/descent segment
RATE_THRESHOLD = 0.05
#: the first seconds of a climb/descent segment are left out of the rate fit (lift-off, teleop low-pass)
RATE_SETTLE = 1.0
#: ... and so are the samples where the filtered command is below this fraction of its peak (ramp down)
RATE_PLATEAU = 0.9


# ------------------------------------------------------------------------------------------------ record
@dataclass
class TruthSeries:
    """Ground truth (``/fpr/ground_truth``), N samples."""

    t: np.ndarray          #: (N,) [s]
    position: np.ndarray   #: (N,3) platform position in F0 (ENU) [m]
    velocity: np.ndarray   #: (N,3) platform linear velocity in F0 [m/s]
    rpy: np.ndarray        #: (N,3) platform ZYX roll, pitch, yaw [rad]
    legs: np.ndarray       #: (N,n) leg angles θ_l [rad]
    thrusts: np.ndarray    #: (N,n) actual thrust of each UAV [N]


@dataclass
class CommandSeries:
    """Teleop command χ_d (``/fpr/teleop``), M samples."""

    t: np.ndarray          #: (M,) [s]
    mode: np.ndarray       #: (M,) TeleopCommand.MODE_*
    velocity: np.ndarray   #: (M,3) platform velocity in F_Fp [m/s]
    roll: np.ndarray       #: (M,) [rad]
    pitch: np.ndarray      #: (M,) [rad]
    legs: np.ndarray       #: (M,n) [rad]


@dataclass
class UavSeries:
    """What one UAV's bridge and controller reported."""

    uav_id: int
    status_t: np.ndarray           #: bridge status times [s]
    bridge_state: np.ndarray       #: UavStatus.STATE_*
    diagnostics_t: np.ndarray      #: controller diagnostics times [s]
    active_mode: np.ndarray        #: ControllerStatus.MODE_* actually running
    fallback: np.ndarray           #: bool, the C/impedance -> NC fallback was active
    setpoint_t: np.ndarray         #: setpoint times [s]
    setpoint_thrust: np.ndarray    #: commanded thrust [N]


@dataclass
class StateNames:
    """Names of the enumerations (taken from the message constants by the caller)."""

    teleop_mode: dict[int, str]
    bridge_state: dict[int, str]
    controller_mode: dict[int, str]
    fly_mode: int          #: TeleopCommand.MODE_FLY
    offboard_state: int    #: UavStatus.STATE_OFFBOARD


@dataclass
class FlightRecord:
    """One flight: recorded series plus how it ran."""

    n: int
    truth: TruthSeries
    command: CommandSeries
    uavs: list[UavSeries]
    names: StateNames
    scenario: str = ""
    script: str = ""
    controller_mode: str = ""
    cameras: str = ""
    sim_time: float = 0.0          #: [s] simulated at the end
    wall_time: float = 0.0         #: [s] wall time of the flight (stepping the simulation)
    lockstep_timeouts: int = 0     #: control periods the simulator stopped waiting for setpoints
    callback_errors: list[str] = field(default_factory=list)
    completed: bool = True         #: the requested duration was simulated (no wall timeout / Ctrl-C)


# ------------------------------------------------------------------------------------------------ metrics
@dataclass
class TrackingError:
    """Error of a tracked quantity vs its command over the tracking window."""

    rmse: float
    max_abs: float
    unit: str


@dataclass
class RateSegment:
    """A climb or descent: commanded vs achieved vertical speed (linear fit of the height), [m/s]."""

    start: float
    end: float
    commanded: float
    achieved: float


@dataclass
class FlightMetrics:
    scenario: str
    script: str
    controller_mode: str
    cameras: str
    completed: bool
    sim_time: float                      #: [s]
    wall_time: float                     #: [s]
    real_time_factor: float              #: simulated / wall
    lockstep_timeouts: int
    callback_errors: int
    offboard_time: float | None          #: [s] all bridges OFFBOARD (None: never)
    tracking_window: tuple[float, float] | None  #: [s] airborne, OFFBOARD, teleop FLY
    tracking_duration: float             #: [s] time inside the window
    roll: TrackingError | None           #: [deg]
    pitch: TrackingError | None          #: [deg]
    legs: TrackingError | None           #: [deg], all legs together
    legs_each: list[TrackingError]       #: [deg], per leg
    vertical_velocity: TrackingError | None  #: [m/s]
    rate_segments: list[RateSegment]
    max_height_gain: float               #: [m] above the first recorded height
    fallback_periods: list[int]          #: per UAV, diagnostics periods with the fallback active (whole run)
    fallback_periods_tracking: list[int]  #: per UAV, the same inside the tracking window
    final_bridge_states: list[str]


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


def command_at(record: FlightRecord, t: np.ndarray) -> dict[str, np.ndarray]:
    """Command interpolated at times ``t``: roll, pitch [rad], legs (N,n) [rad], velocity in F0 (N,3) [m/s]
    (the F_Fp command rotated about z by the true platform yaw), mode (held)."""
    from fpr_model.rotations import rot_z

    c, truth = record.command, record.truth
    if len(c.t) == 0:
        nan = np.full(len(t), np.nan)
        return {"roll": nan, "pitch": nan, "legs": np.full((len(t), record.n), np.nan),
                "velocity": np.full((len(t), 3), np.nan), "mode": np.full(len(t), -1)}
    velocity_flat = np.column_stack([np.interp(t, c.t, c.velocity[:, k]) for k in range(3)])
    yaw = np.interp(t, truth.t, np.unwrap(truth.rpy[:, 2])) if len(truth.t) else np.zeros(len(t))
    velocity = np.einsum("nij,nj->ni", np.array([rot_z(a) for a in yaw]).reshape(-1, 3, 3), velocity_flat)
    return {"roll": np.interp(t, c.t, c.roll), "pitch": np.interp(t, c.t, c.pitch),
            "legs": np.column_stack([np.interp(t, c.t, c.legs[:, k]) for k in range(record.n)]),
            "velocity": velocity, "mode": hold(t, c.t, c.mode)}


def offboard_time(record: FlightRecord) -> float | None:
    """First time every bridge has reported OFFBOARD at least once, or None."""
    firsts = []
    for uav in record.uavs:
        reached = uav.status_t[uav.bridge_state == record.names.offboard_state]
        if len(reached) == 0:
            return None
        firsts.append(float(reached[0]))
    return max(firsts) if firsts else None


def tracking_mask(record: FlightRecord) -> np.ndarray:
    """Ground-truth samples where the controllers fly the robot: every bridge OFFBOARD, teleop FLY, and the
    platform more than :data:`AIRBORNE_CLEARANCE` above its lowest recorded height (off the ground)."""
    truth = record.truth
    if len(truth.t) == 0:
        return np.zeros(0, dtype=bool)
    mask = truth.position[:, 2] > truth.position[:, 2].min() + AIRBORNE_CLEARANCE
    mask &= hold(truth.t, record.command.t, record.command.mode) == record.names.fly_mode
    for uav in record.uavs:
        mask &= hold(truth.t, uav.status_t, uav.bridge_state) == record.names.offboard_state
    return mask


def _error(error: np.ndarray, unit: str, scale: float = 1.0) -> TrackingError | None:
    if error.size == 0:
        return None
    return TrackingError(rmse=float(np.sqrt(np.mean(error ** 2))) * scale,
                         max_abs=float(np.abs(error).max()) * scale, unit=unit)


def _inside(t: np.ndarray, window: tuple[float, float] | None) -> np.ndarray:
    if window is None:
        return np.zeros(len(t), dtype=bool)
    return (t >= window[0]) & (t <= window[1])


def rate_segments(record: FlightRecord) -> list[RateSegment]:
    """Climbs and descents: runs of FLY commands with |v_z,d| > :data:`RATE_THRESHOLD`. The rates are compared
    where the (low-pass filtered) command is steady: from :data:`RATE_SETTLE` s after the run starts, over the
    samples where |v_z,d| is at least :data:`RATE_PLATEAU` of the run's peak; the achieved rate is the slope of
    a linear fit of the true height there, the commanded one the mean command there."""
    c, truth = record.command, record.truth
    if len(c.t) < 2 or len(truth.t) < 2:
        return []
    vz = c.velocity[:, 2]
    active = (np.abs(vz) > RATE_THRESHOLD) & (c.mode == record.names.fly_mode)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], active.astype(int), [0]])))
    segments = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        for sign in (1.0, -1.0):  # a run may reverse (climb straight into descent)
            run = np.arange(a, b)[np.sign(vz[a:b]) == sign]
            if len(run) == 0:
                continue
            peak = np.abs(vz[run]).max()
            plateau = run[(np.abs(vz[run]) >= RATE_PLATEAU * peak) & (c.t[run] >= c.t[run[0]] + RATE_SETTLE)]
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


def compute_metrics(record: FlightRecord) -> FlightMetrics:
    """Every figure of the summary (see :class:`FlightMetrics`)."""
    truth, names = record.truth, record.names
    mask = tracking_mask(record)
    t = truth.t[mask]
    command = command_at(record, t)
    deg = math.degrees(1.0)
    legs_error = truth.legs[mask] - command["legs"]
    window = (float(t[0]), float(t[-1])) if len(t) else None
    dt = np.diff(truth.t, append=truth.t[-1]) if len(truth.t) else np.zeros(0)
    final_states = []
    for uav in record.uavs:
        state = int(uav.bridge_state[-1]) if len(uav.bridge_state) else -1
        final_states.append(names.bridge_state.get(state, "none"))
    return FlightMetrics(
        scenario=record.scenario, script=record.script, controller_mode=record.controller_mode,
        cameras=record.cameras, completed=record.completed, sim_time=record.sim_time, wall_time=record.wall_time,
        real_time_factor=record.sim_time / record.wall_time if record.wall_time > 0 else math.nan,
        lockstep_timeouts=record.lockstep_timeouts, callback_errors=len(record.callback_errors),
        offboard_time=offboard_time(record), tracking_window=window,
        tracking_duration=float(dt[mask].sum()),
        roll=_error(truth.rpy[mask, 0] - command["roll"], "deg", deg),
        pitch=_error(truth.rpy[mask, 1] - command["pitch"], "deg", deg),
        legs=_error(legs_error, "deg", deg),
        legs_each=[e for e in (_error(legs_error[:, k], "deg", deg) for k in range(record.n)) if e is not None],
        vertical_velocity=_error(truth.velocity[mask, 2] - command["velocity"][:, 2], "m/s"),
        rate_segments=rate_segments(record),
        max_height_gain=float(truth.position[:, 2].max() - truth.position[0, 2]) if len(truth.t) else 0.0,
        fallback_periods=[int(np.count_nonzero(uav.fallback)) for uav in record.uavs],
        fallback_periods_tracking=[int(np.count_nonzero(uav.fallback & _inside(uav.diagnostics_t, window)))
                                   for uav in record.uavs],
        final_bridge_states=final_states)


# ------------------------------------------------------------------------------------------------ outputs
def write_metrics_json(metrics: FlightMetrics, path: str) -> None:
    def clean(value):
        if isinstance(value, float) and not math.isfinite(value):
            return None
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, list | tuple):
            return [clean(v) for v in value]
        return value

    with open(path, "w", encoding="utf-8") as stream:
        json.dump(clean(asdict(metrics)), stream, indent=2)
        stream.write("\n")


def format_summary(metrics: FlightMetrics) -> str:
    """The summary table printed at the end of the demo."""
    m = metrics

    def error(e: TrackingError | None, digits: int = 2) -> str:
        return "n/a (never flew)" if e is None else f"{e.rmse:.{digits}f} / {e.max_abs:.{digits}f} {e.unit}"

    rows = [("simulated time", f"{m.sim_time:.1f} s" + ("" if m.completed else "  (INCOMPLETE)")),
            ("wall time of the flight", f"{m.wall_time:.1f} s"),
            ("real-time factor", f"{m.real_time_factor:.2f}"),
            ("lockstep timeouts", f"{m.lockstep_timeouts}"),
            ("callback errors", f"{m.callback_errors}"),
            ("all bridges OFFBOARD at", "never" if m.offboard_time is None else f"{m.offboard_time:.2f} s")]
    if m.tracking_window is not None:
        rows.append(("tracking window (airborne, FLY)", f"{m.tracking_window[0]:.1f} - {m.tracking_window[1]:.1f} s"
                     f" ({m.tracking_duration:.1f} s)"))
    rows += [("roll error RMSE / max", error(m.roll)),
             ("pitch error RMSE / max", error(m.pitch)),
             ("leg angle error RMSE / max", error(m.legs)),
             ("vertical speed error RMSE / max", error(m.vertical_velocity, 3))]
    for k, e in enumerate(m.legs_each):
        rows.append((f"  leg {k + 1} RMSE / max", error(e)))
    for s in m.rate_segments:
        kind = "climb" if s.commanded > 0 else "descent"
        rows.append((f"{kind} {s.start:.1f}-{s.end:.1f} s", f"{s.achieved:+.3f} m/s (commanded {s.commanded:+.3f})"))
    rows += [("max height gain", f"{m.max_height_gain:.3f} m"),
             ("NC fallback periods per UAV", ", ".join(str(f) for f in m.fallback_periods)
              + "  (in the tracking window: " + ", ".join(str(f) for f in m.fallback_periods_tracking) + ")"),
             ("final bridge states", ", ".join(m.final_bridge_states))]
    width = max(len(r[0]) for r in rows) + 2
    title = (f"FPR swarm demo: scenario {m.scenario}, script {m.script}, controller {m.controller_mode}, "
             f"{m.cameras} cameras")
    lines = [title, "-" * len(title)] + [f"{name:<{width}}{value}" for name, value in rows]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------ plots
#: legends outside the axes, on the right: they never hide data
_LEGEND = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "fontsize": 8, "frameon": False}
_COLORS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:gray"]


def _shade(ax, record: FlightRecord, mask: np.ndarray, label: bool) -> None:
    """Shade the tracking window and mark the teleop mode changes."""
    t = record.truth.t
    if mask.any():
        edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
        for k, (a, b) in enumerate(zip(edges[::2], edges[1::2], strict=True)):
            ax.axvspan(t[a], t[b - 1], color="0.92", zorder=0,
                       label="tracking window" if label and k == 0 else None)
    c = record.command
    changes = np.flatnonzero(np.diff(c.mode)) + 1 if len(c.mode) else []
    labels: list[tuple[float, str]] = []  # changes closer than 3 % of the plot merge into one label
    span = max(record.sim_time, float(t[-1]) if len(t) else 0.0, 1e-3)
    for k in changes:
        ax.axvline(c.t[k], color="0.5", lw=0.8, ls=":", zorder=1)
        name = record.names.teleop_mode.get(int(c.mode[k]), "?").upper()
        if labels and c.t[k] - labels[-1][0] < 0.03 * span:
            labels[-1] = (labels[-1][0], f"{labels[-1][1]}, {name}")
        else:
            labels.append((float(c.t[k]), name))
    if label:
        for x, text in labels:
            ax.annotate(text, (x, 1.0), xycoords=("data", "axes fraction"), xytext=(-1, -4),
                        textcoords="offset points", rotation=90, ha="right", va="top", fontsize=7, color="0.35")


def _finish(fig, ax_bottom, path: str, dpi: int) -> str:
    ax_bottom.set_xlabel("simulation time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


def _title(record: FlightRecord, what: str) -> str:
    return f"{what} — {record.scenario}, {record.script}, {record.controller_mode}"


def plot_height_velocity(record: FlightRecord, path: str, dpi: int = 110) -> str:
    import matplotlib.pyplot as plt

    truth, c = record.truth, record.command
    mask = tracking_mask(record)
    command = command_at(record, truth.t)
    fig, (ax_z, ax_v) = plt.subplots(2, 1, figsize=(12, 7), sharex=True)
    ax_z.plot(truth.t, truth.position[:, 2], color="tab:blue", label="platform height z (truth)")
    fly = command["mode"] == record.names.fly_mode
    if fly.any():
        # height reference: the true height when FLY starts plus the integral of the commanded v_z while in FLY
        start = int(np.flatnonzero(fly)[0])
        vz = np.where(fly, command["velocity"][:, 2], 0.0)
        integral = np.concatenate([[0.0], np.cumsum(0.5 * (vz[1:] + vz[:-1]) * np.diff(truth.t))])
        reference = truth.position[start, 2] + integral - integral[start]
        reference[~fly] = np.nan
        ax_z.plot(truth.t, reference, "k--", lw=1.2, label="reference: ∫ commanded v_z dt (in FLY)")
    ax_z.set_ylabel("height [m]")
    ax_z.set_title(_title(record, "Platform height and vertical speed"))
    for k, axis in enumerate("xyz"):
        ax_v.plot(truth.t, truth.velocity[:, k], color=_COLORS[k], lw=1.0, label=f"v_{axis} (truth)")
        if len(c.t):
            ax_v.plot(truth.t, command["velocity"][:, k], color=_COLORS[k], ls="--", lw=1.2,
                      label=f"v_{axis} commanded")
    ax_v.set_ylabel("platform velocity in F0 [m/s]")
    for ax in (ax_z, ax_v):
        _shade(ax, record, mask, label=ax is ax_z)
        ax.grid(True, alpha=0.3)
        ax.legend(**_LEGEND)
    return _finish(fig, ax_v, path, dpi)


def plot_attitude(record: FlightRecord, path: str, dpi: int = 110) -> str:
    import matplotlib.pyplot as plt

    truth = record.truth
    mask = tracking_mask(record)
    command = command_at(record, truth.t)
    fig, axes = plt.subplots(2, 1, figsize=(12, 6.5), sharex=True)
    for ax, k, name in ((axes[0], 0, "roll"), (axes[1], 1, "pitch")):
        ax.plot(truth.t, np.degrees(truth.rpy[:, k]), color="tab:blue", label=f"platform {name} (truth)")
        ax.plot(truth.t, np.degrees(command[name]), "k--", lw=1.2, label=f"{name} commanded")
        ax.set_ylabel(f"{name} [deg]")
        _shade(ax, record, mask, label=k == 0)
        ax.grid(True, alpha=0.3)
        ax.legend(**_LEGEND)
    axes[0].set_title(_title(record, "Platform roll and pitch (flat frame F_Fp)"))
    return _finish(fig, axes[1], path, dpi)


def plot_legs(record: FlightRecord, path: str, dpi: int = 110) -> str:
    import matplotlib.pyplot as plt

    truth = record.truth
    mask = tracking_mask(record)
    command = command_at(record, truth.t)
    fig, ax = plt.subplots(figsize=(12, 4.5))
    same = len(truth.t) > 0 and np.allclose(command["legs"], command["legs"][:, :1], equal_nan=True)
    for k in range(record.n):
        color = _COLORS[k % len(_COLORS)]
        ax.plot(truth.t, np.degrees(truth.legs[:, k]), color=color, label=f"leg {k + 1} (truth)")
        if not same:
            ax.plot(truth.t, np.degrees(command["legs"][:, k]), color=color, ls="--", lw=1.2,
                    label=f"leg {k + 1} commanded")
    if same:
        ax.plot(truth.t, np.degrees(command["legs"][:, 0]), "k--", lw=1.2, label="commanded (all legs)")
    ax.set_ylabel("leg angle θ [deg]")
    ax.set_title(_title(record, "Leg angles"))
    _shade(ax, record, mask, label=True)
    ax.grid(True, alpha=0.3)
    ax.legend(**_LEGEND)
    return _finish(fig, ax, path, dpi)


def plot_thrusts(record: FlightRecord, path: str, dpi: int = 110) -> str:
    import matplotlib.pyplot as plt

    truth = record.truth
    fig, ax = plt.subplots(figsize=(12, 4.5))
    for k, uav in enumerate(record.uavs):
        color = _COLORS[k % len(_COLORS)]
        ax.plot(truth.t, truth.thrusts[:, k], color=color, lw=1.0, label=f"uav{uav.uav_id} actual")
        ax.plot(uav.setpoint_t, uav.setpoint_thrust, color=color, ls="--", lw=1.0, alpha=0.8,
                label=f"uav{uav.uav_id} setpoint")
    ax.set_ylabel("thrust [N]")
    ax.set_title(_title(record, "Thrust per UAV (actual: plant; setpoint: controller)"))
    _shade(ax, record, tracking_mask(record), label=True)
    ax.grid(True, alpha=0.3)
    ax.legend(**_LEGEND)
    return _finish(fig, ax, path, dpi)


def _segments(t: np.ndarray, values: np.ndarray, t_end: float) -> list[tuple[float, float, int]]:
    """(start, width, value) runs of a piecewise-constant signal, the last one lasting until ``t_end``."""
    if len(t) == 0:
        return []
    starts = np.concatenate([[0], np.flatnonzero(np.diff(values)) + 1])
    ends = np.concatenate([starts[1:], [len(t)]])
    runs = []
    for a, b in zip(starts, ends, strict=True):
        stop = t[b] if b < len(t) else max(t_end, t[-1])
        runs.append((float(t[a]), float(stop - t[a]), int(values[a])))
    return runs


def plot_modes(record: FlightRecord, path: str, dpi: int = 110) -> str:
    """Timeline of the teleop mode, each bridge's state machine and each controller's active mode."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    names, t_end = record.names, record.sim_time
    fig, axes = plt.subplots(3, 1, figsize=(12, 2.2 + 0.55 * (1 + 2 * record.n)), sharex=True,
                             gridspec_kw={"height_ratios": [1, record.n, record.n]})
    panels = [(axes[0], "teleop mode", names.teleop_mode, [("teleop", record.command.t, record.command.mode)]),
              (axes[1], "bridge state", names.bridge_state,
               [(f"uav{u.uav_id}", u.status_t, u.bridge_state) for u in record.uavs]),
              (axes[2], "controller mode", names.controller_mode,
               [(f"uav{u.uav_id}", u.diagnostics_t, u.active_mode) for u in record.uavs])]
    for ax, title, labels, rows in panels:
        colors = {value: _COLORS[k % len(_COLORS)] for k, value in enumerate(sorted(labels))}
        seen: set[int] = set()
        for row, (_, t, values) in enumerate(rows):
            for start, width, value in _segments(np.asarray(t), np.asarray(values), t_end):
                ax.broken_barh([(start, width)], (row - 0.4, 0.8), color=colors.get(value, "black"))
                seen.add(value)
        if title == "controller mode":
            for row, uav in enumerate(record.uavs):
                runs = _segments(uav.diagnostics_t, uav.fallback.astype(int), t_end)
                spans = [(s, w) for s, w, v in runs if v]
                if spans:
                    ax.broken_barh(spans, (row - 0.4, 0.8), facecolor="none", edgecolor="black", hatch="//")
            if any(u.fallback.any() for u in record.uavs):
                seen.add(-100)
        ax.set_yticks(range(len(rows)), [r[0] for r in rows])
        ax.set_ylim(-0.6, len(rows) - 0.4)
        ax.invert_yaxis()
        ax.set_ylabel(title, fontsize=9)
        handles = [Patch(color=colors[v], label=labels[v]) for v in sorted(seen) if v in labels]
        if -100 in seen:
            handles.append(Patch(facecolor="none", edgecolor="black", hatch="//", label="NC fallback"))
        ax.legend(handles=handles, loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8, frameon=False)
        ax.grid(True, axis="x", alpha=0.3)
    axes[0].set_title(_title(record, "Modes timeline"))
    axes[2].set_xlim(0.0, max(t_end, 1e-3))
    return _finish(fig, axes[2], path, dpi)


def write_plots(record: FlightRecord, output_dir: str, dpi: int = 110) -> list[str]:
    """All PNG plots of the flight into ``output_dir``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    os.makedirs(output_dir, exist_ok=True)
    plots = [(plot_height_velocity, "height_velocity.png"), (plot_attitude, "roll_pitch.png"),
             (plot_legs, "leg_angles.png"), (plot_thrusts, "thrusts.png"), (plot_modes, "modes.png")]
    return [plot(record, os.path.join(output_dir, name), dpi) for plot, name in plots]
