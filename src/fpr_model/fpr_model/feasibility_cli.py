"""``ros2 run fpr_model feasibility [--output-dir DIR] [--quick]``: the thesis Ch. 5 tables and plots.

Plain Python (no rclpy, no ROS graph needed). Prints Table 5.1 (ATS precision), Table 5.2 (decomposed AWS at
pose (5.25)), Table 5.4 (margins at 15/45/75° for the flat and the inclined (roll 10°, pitch 25°) platform),
the optimal equal leg angles (Figs. 5.10-5.11) and a roll/pitch grid summary (Figs. 5.13-5.14), each next to
the thesis value; writes ``margin_vs_leg_angle.png``, ``optimal_leg_angles_grid.png`` and ``summary.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from fpr_model import feasibility as fz
from fpr_model.kinematics import jacobian
from fpr_model.parameters import FprParameters, default_parameters, load_parameters

# Thesis reference values (documents, for display next to the computed ones).
THESIS_TABLE_5_1 = {17: (30, 0.903), 38: (69, 0.964)}  # vertices -> (half-spaces, precision)
THESIS_TABLE_5_2 = {"F_p": (17, 30), "M_p": (170, 150), "M_l": (8, 6)}  # (vertices, half-spaces)
THESIS_TABLE_5_4 = {15: (4.10, 2.42, 3.02, 1.78), 45: (8.22, 6.90, 7.07, 6.03), 75: (5.01, 4.99, 2.96, 3.04)}
THESIS_OPTIMA = {"flat": (32, 8.66, 48, 6.92), "inclined": (32, 8.23, 41, 6.13)}
ORIENTATIONS = {"flat": (0.0, 0.0), "inclined": (math.radians(10.0), math.radians(25.0))}


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="feasibility", description=__doc__.split("\n\n")[0])
    parser.add_argument("--output-dir", default="reports/feasibility", help="where the PNG/JSON files go")
    parser.add_argument("--quick", action="store_true", help="coarse 15° orientation grid (default 5°)")
    parser.add_argument("--grid-step", type=float, default=None, help="orientation grid step [deg]")
    parser.add_argument("--parameters", default=None, help="FPR parameter YAML (default: thesis Table B.1)")
    parser.add_argument("--no-plots", action="store_true", help="print the tables only")
    return parser


def _table_5_1() -> list[dict]:
    print("\nTable 5.1  ATS discretisation (f_max = 25 N, γ = 35°)")
    print(f"  {'vertices':>8} {'(n_c, N)':>10} {'facets tri/merged':>18} {'thesis':>7} {'precision':>10} {'thesis':>7}")
    rows = []
    for n_cone, n_sphere in ((12, 38), (24, 165)):
        ats = fz.available_thrust_set(fz.CASE_MAX_THRUST, fz.CASE_MAX_TILT, n_cone, n_sphere)
        nv = ats.vertices.shape[0]
        half, prec = THESIS_TABLE_5_1.get(nv, (float("nan"), float("nan")))
        tri, merged = ats.polytope.n_triangulated_facets, ats.polytope.n_facets
        print(f"  {nv:>8} {f'({n_cone}, {n_sphere})':>10} {f'{tri}/{merged}':>18} {half:>7} "
              f"{100 * ats.precision:>9.2f}% {100 * prec:>6.1f}%")
        rows.append({"vertices": nv, "facets_triangulated": tri, "facets_merged": merged, "precision": ats.precision})
    return rows


def _table_5_2(params: FprParameters, ats: fz.AvailableThrustSet) -> dict:
    q = fz.equal_leg_configuration(params, fz.platform_orientation_quat(0.0, 0.0), 0.785)  # pose (5.25)
    sets = fz.decomposed_wrench_sets(ats, jacobian(params, q).T)
    print("\nTable 5.2  decomposed AWS at pose (5.25) (flat, θ = 0.785 rad), 17-vertex ATS")
    print(f"  {'set':<4} {'vertices':>9} {'thesis':>7} {'facets':>7} {'thesis':>7}")
    out = {}
    for name, poly in (("F_p", sets.force), ("M_p", sets.platform_moment), ("M_l", sets.leg_moment)):
        tv, th = THESIS_TABLE_5_2[name]
        facets = poly.n_facets if name != "F_p" else f"{poly.n_triangulated_facets}/{poly.n_facets}"
        print(f"  {name:<4} {poly.n_vertices:>9} {tv:>7} {facets!s:>7} {th:>7}")
        out[name] = {"vertices": poly.n_vertices, "facets": poly.n_facets}
    lo, hi = sets.leg_moment_bounds.min(), sets.leg_moment_bounds.max()
    print(f"  (F_p facets: triangulated/merged; leg moments in [{lo:.2f}, {hi:.2f}] N·m, thesis '0 to about -25')")
    return out


def _table_5_4(params: FprParameters, ats: fz.AvailableThrustSet) -> dict:
    print("\nTable 5.4  static feasibility margins (force N / moment N·m), this code (thesis)")
    print(f"  {'θ':>4} {'flat F':>14} {'flat M':>14} {'incl. F':>14} {'incl. M':>14}")
    out = {}
    for theta, thesis in THESIS_TABLE_5_4.items():
        values = []
        for roll, pitch in ORIENTATIONS.values():
            m = fz.feasibility_margins(params, ats, fz.platform_orientation_quat(roll, pitch), math.radians(theta))
            values += [m.force, m.moment]
        cells = " ".join(f"{v:>6.2f} ({t:4.2f})" for v, t in zip(values, thesis, strict=True))
        print(f"  {theta:>3}° {cells}")
        out[theta] = values
    return out


def _optima(params: FprParameters, ats: fz.AvailableThrustSet) -> tuple[dict, dict]:
    print("\nOptimal equal leg angles (Figs. 5.10-5.11), sweep 1°..89°: this code (thesis)")
    curves, out = {}, {}
    for name, (roll, pitch) in ORIENTATIONS.items():
        best = fz.optimal_leg_angles(params, ats, fz.platform_orientation_quat(roll, pitch))
        tf, tfm, tm, tmm = THESIS_OPTIMA[name]
        print(f"  {name:<9} θ*_F = {math.degrees(best.force_angle):4.0f}° ({tf}°) margin {best.force_margin:5.2f} N "
              f"({tfm});  θ*_M = {math.degrees(best.moment_angle):4.0f}° ({tm}°) margin {best.moment_margin:5.2f} N·m "
              f"({tmm})")
        infeasible = np.degrees(best.curve.leg_angles[~best.curve.feasible])
        if infeasible.size:
            print(f"  {'':<9} statically infeasible for θ in [{infeasible.min():.0f}°, {infeasible.max():.0f}°] "
                  "(thesis: under 8°)")
        curves[f"{name} (roll {math.degrees(roll):.0f}°, pitch {math.degrees(pitch):.0f}°)"] = best.curve
        out[name] = {"force_angle_deg": math.degrees(best.force_angle), "force_margin": best.force_margin,
                     "moment_angle_deg": math.degrees(best.moment_angle), "moment_margin": best.moment_margin}
    return curves, out


def _grid(params: FprParameters, ats: fz.AvailableThrustSet, step_deg: float) -> fz.OrientationGrid:
    angles = np.radians(np.arange(0.0, 90.0 + 1e-9, step_deg))
    total = angles.size**2
    start = time.perf_counter()

    def progress(done: int, total_: int) -> None:
        if done % angles.size == 0 or done == total_:
            elapsed = time.perf_counter() - start
            print(f"\r  orientation grid: {done}/{total_} orientations, {elapsed:5.1f} s", end="", file=sys.stderr,
                  flush=True)

    print(f"\nOrientation grid: roll, pitch in 0..90° step {step_deg:g}° ({total} orientations × 89 leg angles)")
    grid = fz.orientation_grid(params, ats, angles, angles, progress=progress)
    print("", file=sys.stderr)
    fa, ma = np.degrees(grid.force_angle), np.degrees(grid.moment_angle)
    i_f = np.unravel_index(np.argmax(grid.force_margin), grid.force_margin.shape)
    i_m = np.unravel_index(np.argmax(grid.moment_margin), grid.moment_margin.shape)
    j_f = np.unravel_index(np.argmin(grid.force_margin), grid.force_margin.shape)
    j_m = np.unravel_index(np.argmin(grid.moment_margin), grid.moment_margin.shape)
    deg = np.degrees
    print(f"  θ*_F spans {fa.min():.0f}°-{fa.max():.0f}° (thesis 28°-45°); θ*_M spans {ma.min():.0f}°-{ma.max():.0f}° "
          "(thesis 35°-55°)")
    print(f"  best force margin {grid.force_margin[i_f]:.2f} N at (roll, pitch) = "
          f"({deg(angles[i_f[0]]):.0f}°, {deg(angles[i_f[1]]):.0f}°); best moment margin {grid.moment_margin[i_m]:.2f} "
          f"N·m at ({deg(angles[i_m[0]]):.0f}°, {deg(angles[i_m[1]]):.0f}°) (thesis: best at (0°, 0°))")
    print(f"  lowest optimal margins: {grid.force_margin[j_f]:.2f} N at ({deg(angles[j_f[0]]):.0f}°, "
          f"{deg(angles[j_f[1]]):.0f}°), {grid.moment_margin[j_m]:.2f} N·m at ({deg(angles[j_m[0]]):.0f}°, "
          f"{deg(angles[j_m[1]]):.0f}°) (thesis: 'always above about 8 N and 6 N·m')")
    return grid


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    step = args.grid_step if args.grid_step is not None else (15.0 if args.quick else 5.0)
    if not (0.0 < step <= 90.0):
        print(f"feasibility: --grid-step must be in (0, 90] deg, got {step}", file=sys.stderr)
        return 2
    try:
        params = load_parameters(args.parameters) if args.parameters else default_parameters()
    except (OSError, ValueError) as error:
        print(f"feasibility: cannot load parameters: {error}", file=sys.stderr)
        return 2
    if params.n != 3:
        print(f"feasibility: the margins need n = 3 (square Jacobian), got n = {params.n}", file=sys.stderr)
        return 2
    start = time.perf_counter()
    ats = fz.available_thrust_set()
    summary: dict = {"table_5_1": _table_5_1(), "table_5_2": _table_5_2(params, ats),
                     "table_5_4": _table_5_4(params, ats)}
    curves, summary["optima"] = _optima(params, ats)
    grid = _grid(params, ats, step)
    summary["grid"] = {
        "step_deg": step,
        "rolls_deg": np.degrees(grid.rolls).tolist(),
        "pitches_deg": np.degrees(grid.pitches).tolist(),
        "force_angle_deg": np.degrees(grid.force_angle).round(3).tolist(),
        "force_margin": grid.force_margin.round(4).tolist(),
        "moment_angle_deg": np.degrees(grid.moment_angle).round(3).tolist(),
        "moment_margin": grid.moment_margin.round(4).tolist(),
    }
    output = Path(args.output_dir)
    output.mkdir(parents=True, exist_ok=True)
    (output / "summary.json").write_text(json.dumps(summary, indent=1))
    written = [output / "summary.json"]
    if not args.no_plots:
        from fpr_model import feasibility_plots

        written.append(feasibility_plots.plot_margin_curves(curves, output / "margin_vs_leg_angle.png"))
        written.append(feasibility_plots.plot_orientation_grid(grid, output / "optimal_leg_angles_grid.png"))
    print(f"\nwrote {', '.join(str(p) for p in written)} in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
