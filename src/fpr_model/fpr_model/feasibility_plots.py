"""PNG plots of the wrench feasibility analysis (thesis Figs. 5.10-5.14). matplotlib is imported lazily
(Agg backend), so importing this module costs nothing; only the report command calls it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fpr_model.feasibility import MarginCurve, OrientationGrid


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_margin_curves(curves: dict[str, MarginCurve], path: Path) -> Path:
    """Force [N] and moment [N·m] margins vs equal leg angle [deg], one panel per orientation (Figs. 5.10-5.11)."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(curves), figsize=(6.0 * len(curves), 4.2), squeeze=False)
    for ax, (title, curve) in zip(axes[0], curves.items(), strict=True):
        degrees = np.degrees(curve.leg_angles)
        ax.plot(degrees, curve.force, label="force margin F$^s_p$ [N]", color="tab:blue")
        ax.plot(degrees, curve.moment, label="moment margin M$^s_p$ [N·m]", color="tab:red")
        for values, color in ((curve.force, "tab:blue"), (curve.moment, "tab:red")):
            k = int(np.argmax(values))
            ax.plot(degrees[k], values[k], "o", color=color)
            ax.annotate(f"{degrees[k]:.0f}°: {values[k]:.2f}", (degrees[k], values[k]),
                        textcoords="offset points", xytext=(4, 6), color=color)
        infeasible = ~curve.feasible
        if infeasible.any():
            ax.axvspan(degrees[infeasible].min() - 0.5, degrees[infeasible].max() + 0.5, color="0.85",
                       label="statically infeasible")
        ax.set_title(title)
        ax.set_xlabel("leg angle θ1 = θ2 = θ3 [deg]")
        ax.set_ylabel("feasibility margin")
        ax.set_xlim(0, 90)
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="lower center", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_orientation_grid(grid: OrientationGrid, path: Path) -> Path:
    """Optimal leg angles [deg] and their margins over roll × pitch [deg] (Figs. 5.13-5.14)."""
    plt = _pyplot()
    rolls = np.degrees(grid.rolls)
    pitches = np.degrees(grid.pitches)
    panels = (
        (np.degrees(grid.force_angle), "force-optimal leg angle θ*_F [deg]", "viridis"),
        (np.degrees(grid.moment_angle), "moment-optimal leg angle θ*_M [deg]", "viridis"),
        (grid.force_margin, "force margin at θ*_F [N]", "magma"),
        (grid.moment_margin, "moment margin at θ*_M [N·m]", "magma"),
    )
    fig, axes = plt.subplots(2, 2, figsize=(11, 9))
    step_r = rolls[1] - rolls[0] if rolls.size > 1 else 5.0
    step_p = pitches[1] - pitches[0] if pitches.size > 1 else 5.0
    extent = (pitches[0] - step_p / 2, pitches[-1] + step_p / 2, rolls[0] - step_r / 2, rolls[-1] + step_r / 2)
    for ax, (values, title, cmap) in zip(axes.ravel(), panels, strict=True):
        image = ax.imshow(values, origin="lower", extent=extent, aspect="auto", cmap=cmap)
        fig.colorbar(image, ax=ax)
        ax.set_title(title)
        ax.set_xlabel("platform pitch ϑ_p [deg]")
        ax.set_ylabel("platform roll ϕ_p [deg]")
    fig.suptitle("Optimal equal leg angles over platform orientation (ZYX, yaw 0)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path

