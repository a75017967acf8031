"""``selfcheck``: reproduce the thesis's model validation (§2.6, Table 2.1) and a few physical checks.

Run ``selfcheck`` (console script) or ``python -m fpr_model.selfcheck``. Prints one table and exits with a
non-zero status if any check fails.

State: thesis (2.94), i.e. spec §4.1 M1/M3 (quaternion normalised). For n = 4 and 6 the platform part of
(2.94) is kept and the three leg angles / rates of (2.94) are repeated cyclically over the n legs.
"""

from __future__ import annotations

import sys

import numpy as np

from fpr_model.dynamics import (
    coriolis_matrix,
    forward_dynamics,
    gravity,
    inverse_dynamics,
    mass_matrix,
    mass_matrix_rnea,
    thrusts_from_wrench,
)
from fpr_model.geometry import difference_configuration, integrate_configuration, inverse_geometric_model
from fpr_model.kinematics import jacobian
from fpr_model.parameters import FprParameters, default_parameters

__all__ = ["main", "reference_state", "run_checks"]

#: Thesis (2.94): q = [p_p, q_p (to be normalised), θ], ν = [v_p, ω_p, θ̇].
Q_294 = (0.815, 0.906, 0.127, 0.795, 0.550, 0.085, 0.242, 0.547, 0.958, 0.965)
NU_294 = (0.158, 0.971, 0.957, 0.485, 0.800, 0.142, 0.422, 0.916, 0.792)

TABLE_TOLERANCE = 1e-12  # Table 2.1 comparisons (thesis: 4.4e-16, 8.9e-16, 0)
MDOT_TOLERANCE = 1e-6  # relative, Ṁ = C + Cᵀ by central differences
IKM_TOLERANCE = 1e-5  # thesis §2.6 IGM vs IKM
EQUILIBRIUM_TOLERANCE = 1e-9  # |ν̇| under f = J^{-T} g
WEIGHT_TOLERANCE = 1e-3  # N, vertical gravity force vs m_tot g


def reference_state(n: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(q, ν) of thesis (2.94), quaternion normalised; legs repeated cyclically for n != 3."""
    q = np.array(Q_294[:7] + tuple(Q_294[7 + i % 3] for i in range(n)))
    q[3:7] /= np.linalg.norm(q[3:7])
    nu = np.array(NU_294[:6] + tuple(NU_294[6 + i % 3] for i in range(n)))
    return q, nu


def run_checks(params: FprParameters, seed: int = 0) -> dict[str, float]:
    """The checks for one parameter set, at the (2.94) state; returns the measured errors."""
    n = params.n
    q, nu = reference_state(n)
    zero = np.zeros(6 + n)
    results: dict[str, float] = {}
    M = mass_matrix(params, q)
    results["|M_RNEA - M_CRBA|"] = float(np.abs(mass_matrix_rnea(params, q) - M).max())
    C = coriolis_matrix(params, q, nu)
    c_rnea = inverse_dynamics(params, q, nu, zero, gravity=False)
    results["|c_RNEA(g=0) - C nu|"] = float(np.abs(c_rnea - C @ nu).max())
    g_rnea = inverse_dynamics(params, q, zero, zero, gravity=True)
    results["|g_RNEA(nu=0) - g|"] = float(np.abs(g_rnea - gravity(params, q)).max())
    h = 1e-6
    M_dot = (mass_matrix(params, integrate_configuration(q, nu, h))
             - mass_matrix(params, integrate_configuration(q, nu, -h))) / (2 * h)
    results["Mdot = C + C^T (rel)"] = float(np.abs(M_dot - C - C.T).max() / np.abs(M_dot).max())
    # Thesis §2.6 IGM vs IKM: δq ~ N(0, 0.001) on every component of q (quaternion renormalised), ν′ the
    # constant velocity that takes q to q + δq in unit time. The one-sided residual
    # IGM(q + δq) − IGM(q) − J ν′ is second order in ν′ (about 1e-5 at this size: the thesis's "within 1e-5"
    # holds for the median, not for every draw), so it is reported as information; the pass/fail check is
    # the central (symmetric) residual, which isolates errors of J.
    rng = np.random.default_rng(seed)
    J = jacobian(params, q)
    p0 = inverse_geometric_model(params, q).reshape(-1)
    one_sided, central = [], []
    for _ in range(200):
        q_perturbed = q + rng.normal(0.0, 0.001, q.shape)
        q_perturbed[3:7] /= np.linalg.norm(q_perturbed[3:7])
        nu_prime = difference_configuration(q, q_perturbed)
        forward = inverse_geometric_model(params, q_perturbed).reshape(-1)
        backward = inverse_geometric_model(params, integrate_configuration(q, nu_prime, -1.0)).reshape(-1)
        one_sided.append(float(np.linalg.norm(forward - p0 - J @ nu_prime)))
        central.append(float(np.linalg.norm(0.5 * (forward - backward) - J @ nu_prime)))
    results["IGM vs IKM central (max)"] = max(central)
    results["IGM vs IKM one-sided (median)"] = float(np.median(one_sided))
    # Equilibrium: flat platform, legs at 60°, f = J^{-T} g(q) gives ν̇ = 0.
    q_eq = np.concatenate([[0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0], np.full(n, np.radians(60.0))])
    tau_g = gravity(params, q_eq)
    thrusts = thrusts_from_wrench(params, q_eq, tau_g)
    tau = jacobian(params, q_eq).T @ thrusts.reshape(-1)
    results["equilibrium |nu_dot|"] = float(np.abs(forward_dynamics(params, q_eq, zero, tau)).max())
    results["sum thrust_z - m_tot g"] = float(abs(thrusts[:, 2].sum() - params.total_mass * params.gravity))
    results["weight f_z"] = float(tau_g[2])
    return results


_LIMITS = {
    "|M_RNEA - M_CRBA|": TABLE_TOLERANCE,
    "|c_RNEA(g=0) - C nu|": TABLE_TOLERANCE,
    "|g_RNEA(nu=0) - g|": TABLE_TOLERANCE,
    "Mdot = C + C^T (rel)": MDOT_TOLERANCE,
    "IGM vs IKM central (max)": IKM_TOLERANCE,
    "equilibrium |nu_dot|": EQUILIBRIUM_TOLERANCE,
    "sum thrust_z - m_tot g": WEIGHT_TOLERANCE,
}


def main(argv: list[str] | None = None) -> int:
    """Print the validation table for n = 3, 4, 6 (Table B.1 parameters); return 0 if every check passes."""
    del argv
    ok = True
    rows = []
    for n in (3, 4, 6):
        params = default_parameters(n)
        results = run_checks(params)
        expected_weight = params.total_mass * params.gravity
        for name, value in results.items():
            if name == "IGM vs IKM one-sided (median)":
                passed = True
                limit = "(info, 2nd order)"
                shown = f"{value:.2e}"
            elif name == "weight f_z":
                passed = abs(value - expected_weight) <= WEIGHT_TOLERANCE
                limit = f"= {expected_weight:.3f}"
                shown = f"{value:.4f} N"
            else:
                passed = value <= _LIMITS[name]
                limit = f"<= {_LIMITS[name]:.0e}"
                shown = f"{value:.2e}"
            ok &= passed
            rows.append((str(n), name, shown, limit, "ok" if passed else "FAIL"))
    widths = [max(len(row[i]) for row in rows + [("n", "check", "value", "limit", "")]) for i in range(5)]
    print("fpr_model self-check: thesis Table 2.1 at the (2.94) state, Table B.1 parameters")
    header = ("n", "check", "value", "limit", "")
    print("  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    for row in rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)))
    print("ALL CHECKS PASSED" if ok else "SOME CHECKS FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
