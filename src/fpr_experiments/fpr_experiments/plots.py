"""PNG plots of one flight, like the thesis's figures (ROS-free: numpy + matplotlib, Agg backend).

Per variant: platform position desired vs actual (ground-truth modes), roll / pitch and leg angles desired vs
actual, thrusts, the modes timeline, the external-wrench estimate of every UAV vs the truth, the contact force
(desired / estimated / true) when one is asked, the estimated vs true relative pose (ArUco, EKF) and the
positioning error of the scripted operator's tasks. Per experiment: one comparison figure per reported quantity
across the variants (e.g. Fig. 3.9's z position of three controllers). Degrees only here.
"""

from __future__ import annotations

import math
import os

import numpy as np

from fpr_experiments.metrics import desired_at, interpolate, tracking_mask, true_relative_poses
from fpr_experiments.records import FlightRecord

_LEGEND = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "fontsize": 8, "frameon": False}
_COLORS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:gray"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _title(record: FlightRecord, what: str) -> str:
    return f"{what} — {record.experiment}/{record.variant} ({record.controller_mode})"


def _shade(ax, record: FlightRecord, label: bool) -> None:
    """Shade the tracking window and mark the teleop mode changes."""
    t, mask = record.truth.t, tracking_mask(record)
    if mask.any():
        edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
        for k, (a, b) in enumerate(zip(edges[::2], edges[1::2], strict=True)):
            ax.axvspan(t[a], t[b - 1], color="0.93", zorder=0, label="tracking window" if label and k == 0 else None)
    c = record.command
    for k in (np.flatnonzero(np.diff(c.mode)) + 1 if len(c.mode) else []):
        ax.axvline(c.t[k], color="0.5", lw=0.8, ls=":", zorder=1)
        if label:
            ax.annotate(record.names.teleop_mode.get(int(c.mode[k]), "?"), (c.t[k], 1.0),
                        xycoords=("data", "axes fraction"), xytext=(-1, -4), textcoords="offset points",
                        rotation=90, ha="right", va="top", fontsize=7, color="0.35")


def _finish(fig, axes, path: str, dpi: int) -> str:
    for ax in np.atleast_1d(axes):
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(**_LEGEND)
    np.atleast_1d(axes)[-1].set_xlabel("simulation time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    _plt().close(fig)
    return path


def plot_position(record: FlightRecord, path: str, dpi: int) -> str | None:
    truth = record.truth
    desired = desired_at(record, truth.t)
    fig, axes = _plt().subplots(3, 1, figsize=(12, 7.5), sharex=True)
    for k, axis in enumerate("xyz"):
        axes[k].plot(truth.t, truth.position[:, k], color=_COLORS[k], label=f"p_{axis} (truth)")
        if np.isfinite(desired["position"][:, k]).any():
            axes[k].plot(truth.t, desired["position"][:, k], "k--", lw=1.1, label=f"p_{axis} desired")
        axes[k].set_ylabel(f"{axis} [m]")
        _shade(axes[k], record, label=k == 0)
    axes[0].set_title(_title(record, "Platform position in F0"))
    return _finish(fig, axes, path, dpi)


def plot_attitude_legs(record: FlightRecord, path: str, dpi: int) -> str:
    truth = record.truth
    desired = desired_at(record, truth.t)
    fig, axes = _plt().subplots(3, 1, figsize=(12, 8), sharex=True)
    for ax, k, name in ((axes[0], 0, "roll"), (axes[1], 1, "pitch")):
        ax.plot(truth.t, np.degrees(truth.rpy[:, k]), color="tab:red" if k == 0 else "tab:green",
                label=f"platform {name} (truth)")
        ax.plot(truth.t, np.degrees(desired[name]), "k--", lw=1.1, label=f"{name} desired")
        ax.set_ylabel(f"{name} [deg]")
    for i in range(record.n):
        axes[2].plot(truth.t, np.degrees(truth.legs[:, i]), color=_COLORS[i % len(_COLORS)], lw=1.0,
                     label=f"leg {i + 1}")
    axes[2].plot(truth.t, np.degrees(desired["legs"][:, 0]), "k--", lw=1.1, label="desired (leg 1)")
    axes[2].set_ylabel("leg angle [deg]")
    for k, ax in enumerate(axes):
        _shade(ax, record, label=k == 0)
    axes[0].set_title(_title(record, "Platform roll / pitch (F_Fp) and leg angles"))
    return _finish(fig, axes, path, dpi)


def plot_height_velocity(record: FlightRecord, path: str, dpi: int) -> str:
    truth, c = record.truth, record.command
    fig, axes = _plt().subplots(2, 1, figsize=(12, 6.5), sharex=True)
    axes[0].plot(truth.t, truth.position[:, 2], color="tab:blue", label="platform height (truth)")
    axes[0].set_ylabel("height [m]")
    axes[1].plot(truth.t, truth.velocity[:, 2], color="tab:blue", lw=1.0, label="v_z (truth)")
    if len(c.t):
        axes[1].plot(c.t, c.velocity[:, 2], "k--", lw=1.1, label="v_z commanded")
    axes[1].set_ylabel("vertical speed [m/s]")
    for k, ax in enumerate(axes):
        _shade(ax, record, label=k == 0)
    axes[0].set_title(_title(record, "Platform height and vertical speed"))
    return _finish(fig, axes, path, dpi)


def plot_thrusts(record: FlightRecord, path: str, dpi: int) -> str:
    truth = record.truth
    fig, ax = _plt().subplots(figsize=(12, 4.5))
    for k, uav in enumerate(record.uavs):
        color = _COLORS[k % len(_COLORS)]
        ax.plot(truth.t, truth.thrusts[:, k], color=color, lw=1.0, label=f"uav{uav.uav_id} actual")
        ax.plot(uav.setpoint_t, uav.setpoint_thrust, color=color, ls="--", lw=0.9, alpha=0.8,
                label=f"uav{uav.uav_id} setpoint")
    ax.set_ylabel("thrust [N]")
    ax.set_title(_title(record, "Thrust per UAV (actual: plant; setpoint: controller)"))
    _shade(ax, record, label=True)
    return _finish(fig, ax, path, dpi)


def plot_wrench(record: FlightRecord, path: str, dpi: int) -> str | None:
    """Fig. 3.4 / 3.7 / 4.14 style: the observers' platform force estimate (every UAV) vs the true external force."""
    truth = record.truth
    if not any(len(u.wrench_t) for u in record.uavs):
        return None
    fig, axes = _plt().subplots(3, 1, figsize=(12, 7.5), sharex=True)
    for k, axis in enumerate("xyz"):
        axes[k].plot(truth.t, truth.external_wrench[:, k], "k-", lw=1.4, label=f"f_p{axis},e true")
        for j, uav in enumerate(record.uavs):
            axes[k].plot(uav.wrench_t, uav.wrench_force[:, k], color=_COLORS[j % len(_COLORS)], lw=0.9,
                         alpha=0.85, label=f"f̂_p{axis},e uav{uav.uav_id}")
        axes[k].set_ylabel(f"force {axis} [N]")
        _shade(axes[k], record, label=k == 0)
    axes[0].set_title(_title(record, "External force on the platform: estimates vs truth"))
    return _finish(fig, axes, path, dpi)


def plot_contact(record: FlightRecord, path: str, dpi: int) -> str | None:
    """Fig. 3.13 / 4.17 style: desired, estimated and true contact force."""
    truth = record.truth
    desired = desired_at(record, truth.t)["contact_force"]
    if not (np.nanmax(desired, initial=0.0) > 0.1 or truth.contact_force.max(initial=0.0) > 0.1):
        return None
    fig, ax = _plt().subplots(figsize=(12, 4.5))
    ax.plot(truth.t, desired, "k--", lw=1.2, label="f^d_c desired")
    for j, uav in enumerate(record.uavs):
        ax.plot(uav.wrench_t, uav.wrench_contact, color=_COLORS[j % len(_COLORS)], lw=0.9,
                label=f"estimated (uav{uav.uav_id})")
    ax.plot(truth.t, truth.contact_force, color="tab:red", lw=1.4, label="true normal force")
    ax.set_ylabel("contact force [N]")
    ax.set_title(_title(record, "Contact force"))
    _shade(ax, record, label=True)
    return _finish(fig, ax, path, dpi)


def plot_relative_pose(record: FlightRecord, path: str, dpi: int) -> str | None:
    """Fig. 4.12 style: relative pose of every UAV in Fp, ArUco (dots), EKF and truth."""
    from fpr_model.rotations import quat_to_euler_zyx

    truth = record.truth
    if not any(len(u.local_t) for u in record.uavs) or len(truth.t) == 0:
        return None
    true_p, true_q = true_relative_poses(record)
    n = record.n
    fig, axes = _plt().subplots(6, n, figsize=(4.2 * n, 11), sharex=True, squeeze=False)
    names = ["x [m]", "y [m]", "z [m]", "roll [deg]", "pitch [deg]", "yaw [deg]"]

    def euler(quats: np.ndarray) -> np.ndarray:
        return np.degrees(np.array([quat_to_euler_zyx(q / np.linalg.norm(q)) for q in quats]).reshape(-1, 3))

    for i, uav in enumerate(record.uavs):
        true_e = euler(true_q[:, i])
        for row in range(6):
            ax = axes[row, i]
            truth_values = true_p[:, i, row] if row < 3 else true_e[:, row - 3]
            ax.plot(truth.t, truth_values, "r--", lw=1.0, label="truth (MOCAP)" if row == 0 else None)
            if len(uav.marker_t):
                values = uav.marker_position[:, row] if row < 3 else euler(uav.marker_quat)[:, row - 3]
                ax.plot(uav.marker_t, values, ".", color="tab:blue", ms=2, label="ArUco" if row == 0 else None)
            if len(uav.local_t):
                values = uav.local_position[:, row] if row < 3 else euler(uav.local_quat)[:, row - 3]
                ax.plot(uav.local_t, values, color="tab:green", lw=0.9, label="EKF" if row == 0 else None)
            if i == 0:
                ax.set_ylabel(names[row])
            ax.grid(True, alpha=0.3)
        axes[0, i].set_title(f"uav{uav.uav_id}: p T_b{uav.uav_id}")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper right", fontsize=8, frameon=False)
    for ax in axes[-1]:
        ax.set_xlabel("simulation time [s]")
    fig.suptitle(_title(record, "Relative pose of each UAV in Fp"))
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    _plt().close(fig)
    return path


def plot_tasks(record: FlightRecord, path: str, dpi: int) -> str | None:
    """Fig. 4.9 / 4.13 / 4.16 style: the distance to the operator's current target, task boxes."""
    starts = [e for e in record.events if e.get("event") == "task_start"]
    if not starts:
        return None
    truth = record.truth
    ends = {e.get("task"): e for e in record.events if e.get("event") == "task_end"}
    fig, ax = _plt().subplots(figsize=(12, 4.5))
    for start in starts:
        task = start.get("task")
        end = ends.get(task, {"t": truth.t[-1] if len(truth.t) else start["t"], "success": False})
        window = (truth.t >= start["t"]) & (truth.t <= end["t"])
        target = np.asarray(start.get("target", [math.nan] * 3), dtype=float)
        error = np.linalg.norm(truth.position[window] - target, axis=1)
        color = "tab:red" if end.get("success") else "black"
        ax.plot(truth.t[window], error, color="tab:blue", lw=1.0)
        ax.axvspan(start["t"], end["t"], facecolor="none", edgecolor=color, lw=1.2)
        ax.annotate(f"task {task} {'ok' if end.get('success') else 'failed'}", (start["t"], 1.0),
                    xycoords=("data", "axes fraction"), xytext=(2, -10), textcoords="offset points", fontsize=7,
                    color=color)
        for key, style in (("criterion", "k--"), ("success_radius", "r--")):
            if key in start:
                ax.plot([start["t"], end["t"]], [start[key]] * 2, style, lw=0.9)
    ax.set_ylabel("positioning error [m]")
    ax.set_title(_title(record, "Positioning error to the target (red box: success, black: failure)"))
    return _finish(fig, ax, path, dpi)


def plot_modes(record: FlightRecord, path: str, dpi: int) -> str:
    from matplotlib.patches import Patch

    names, t_end = record.names, record.sim_time
    plt = _plt()
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
            t, values = np.asarray(t), np.asarray(values)
            if len(t) == 0:
                continue
            starts = np.concatenate([[0], np.flatnonzero(np.diff(values)) + 1])
            ends = np.concatenate([starts[1:], [len(t)]])
            for a, b in zip(starts, ends, strict=True):
                stop = t[b] if b < len(t) else max(t_end, t[-1])
                ax.broken_barh([(t[a], stop - t[a])], (row - 0.4, 0.8), color=colors.get(int(values[a]), "k"))
                seen.add(int(values[a]))
        if title == "controller mode":
            for row, uav in enumerate(record.uavs):
                on = uav.fallback.astype(bool)
                if on.any():
                    ax.plot(uav.diagnostics_t[on], np.full(on.sum(), row), "k|", ms=6)
        ax.set_yticks(range(len(rows)), [r[0] for r in rows])
        ax.set_ylim(-0.6, len(rows) - 0.4)
        ax.invert_yaxis()
        ax.set_ylabel(title, fontsize=9)
        handles = [Patch(color=colors[v], label=labels[v]) for v in sorted(seen) if v in labels]
        ax.legend(handles=handles, loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8, frameon=False)
    axes[0].set_title(_title(record, "Modes timeline (| = NC fallback)"))
    axes[2].set_xlim(0.0, max(t_end, 1e-3))
    axes[2].set_xlabel("simulation time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


PLOTS = {
    "position": plot_position,
    "attitude_legs": plot_attitude_legs,
    "height_velocity": plot_height_velocity,
    "thrusts": plot_thrusts,
    "wrench": plot_wrench,
    "contact_force": plot_contact,
    "relative_pose": plot_relative_pose,
    "tasks": plot_tasks,
    "modes": plot_modes,
}


def write_plots(record: FlightRecord, output_dir: str, dpi: int = 110) -> list[str]:
    """Every plot that applies to ``record`` as ``<name>.png`` in ``output_dir``; returns their paths."""
    os.makedirs(output_dir, exist_ok=True)
    paths = []
    for name, plot in PLOTS.items():
        if name == "position" and not np.isfinite(desired_at(record, record.truth.t)["position"]).any():
            continue  # decentralized: no position reference
        path = plot(record, os.path.join(output_dir, f"{name}.png"), dpi)
        if path:
            paths.append(path)
    return paths


def plot_comparison(records: dict[str, FlightRecord], labels: dict[str, str], quantity: str, path: str,
                    title: str, dpi: int = 110) -> str | None:
    """One quantity of several variants on one axis: ``z`` (platform height), ``force_z`` (UAV 1's estimate),
    ``pitch`` / ``roll`` (error vs desired, deg), ``position_error`` (3-D, m)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(12, 4.5))
    for k, (variant, record) in enumerate(records.items()):
        truth = record.truth
        color = _COLORS[k % len(_COLORS)]
        label = labels.get(variant, variant)
        if quantity == "z":
            ax.plot(truth.t, truth.position[:, 2], color=color, label=label)
            ax.set_ylabel("platform z [m]")
        elif quantity == "force_z":
            uav = record.uavs[0]
            ax.plot(uav.wrench_t, uav.wrench_force[:, 2], color=color, lw=0.9, label=f"{label}: f̂_pz,e")
            if k == 0:
                ax.plot(truth.t, truth.external_wrench[:, 2], "k-", lw=1.3, label="true f_pz,e")
            ax.set_ylabel("z external force [N]")
        elif quantity in ("roll", "pitch"):
            index = 0 if quantity == "roll" else 1
            desired = desired_at(record, truth.t)[quantity]
            ax.plot(truth.t, np.degrees(truth.rpy[:, index] - desired), color=color, lw=0.9, label=label)
            ax.set_ylabel(f"{quantity} error [deg]")
        elif quantity == "position_error":
            desired = desired_at(record, truth.t)["position"]
            ax.plot(truth.t, np.linalg.norm(truth.position - desired, axis=1), color=color, lw=0.9, label=label)
            ax.set_ylabel("|p_p - p^d_p| [m]")
        elif quantity == "legs":
            desired = desired_at(record, truth.t)["legs"]
            ax.plot(truth.t, np.degrees(np.mean(np.abs(truth.legs - desired), axis=1)), color=color, lw=0.9,
                    label=label)
            ax.set_ylabel("mean |leg angle error| [deg]")
        else:
            raise ValueError(f"unknown comparison quantity '{quantity}'")
    ax.set_title(title)
    return _finish(fig, ax, path, dpi)


__all__ = ["PLOTS", "interpolate", "plot_comparison", "write_plots"]
