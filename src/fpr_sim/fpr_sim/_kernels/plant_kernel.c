/*
 * fpr_sim compiled kernel: the 1 kHz plant step in plain C99 (loaded with ctypes, no Python C-API).
 *
 * This is a line-by-line port of the Python reference in fpr_sim/plant.py (Plant.step, Plant._derivative,
 * Plant._add_landing_gear_moments, joint_stop_moment), fpr_sim/structure.py (StructureDynamics.accelerate),
 * fpr_sim/environment.py (GroundContacts.point_force / update_anchors, Environment.board_force_scalar) and
 * fpr_sim/quadrotor.py (QuadrotorFleet.control / step, mix_one, Battery.update). The Python code stays the
 * reference (and the fallback); every function below names its Python original, which names the thesis
 * equations. The same floating-point operations are done in the same order where practical, and
 * Python's min/max semantics are kept (NaN comparisons), so both paths agree to rounding
 * (test/test_plant_oracle.py runs both against the same frozen trajectories).
 *
 * No model constant is defined here: every parameter (the fitted mass-matrix basis, geometry, masses, gains,
 * contact and drag constants) is passed in from Python (FprPlantModel / FprQuadModel, built from fpr_model
 * and the scenario in fpr_sim/_kernels/__init__.py).
 *
 * Units SI; world frame ENU; platform body frame Fp; quadrotor body frames FLU; quaternions [w, x, y, z].
 * Build: compiled by setup.py as an optional extension (plain shared library); never required.
 *
 * One more function, not of the plant: fpr_frame_finish, the last pass of a rendered camera frame
 * (fpr_sim/camera_renderer.py, MarkerRenderer.render: photometric table, lighting gradient, sensor noise, rounding
 * to uint8), the same float32 operations in the same order (test/test_frame_kernel.py: bit for bit).
 */

#include <math.h>
#include <stdint.h>
#include <stddef.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#if defined(__GNUC__)
#define FPR_EXPORT __attribute__((visibility("default")))
#else
#define FPR_EXPORT
#endif

/* Bumped whenever a struct, a buffer layout or a function signature changes (checked by the loader). */
#define FPR_KERNEL_ABI 6
#define FPR_MAX_N 16
#define FPR_MAX_N9 (6 + FPR_MAX_N)
/* math.pi (M_PI is not C99) */
#define FPR_PI 3.141592653589793

#ifndef FPR_KERNEL_SOURCE_HASH
#define FPR_KERNEL_SOURCE_HASH "unknown"
#endif

/* error codes (negative); the loader maps them to Python exceptions */
#define FPR_OK 0
#define FPR_ERR_SINGULAR (-1)      /* mass matrix singular (np.linalg.LinAlgError in Python) */
#define FPR_ERR_QUAT (-2)          /* zero or non-finite quaternion in the controller (ValueError in Python) */
#define FPR_ERR_SIZE (-3)          /* n out of range */

/* ------------------------------------------------------------------------------------------- models */

/* The n quadrotors' constants (QuadrotorFleet, Battery). */
typedef struct {
    int n;
    double inertia[3];          /* diagonal [kg m^2] */
    double arm;                 /* d [m] */
    double kappa;               /* c_Q / c_T [m] */
    double motor_tau;           /* motor time constant [s] */
    double attitude_p[3];       /* (3.39) [1/s] */
    double rate_p[3], rate_i[3], rate_d[3];  /* (3.40) */
    double max_rate[3];         /* [rad/s] */
    double integrator_limit;    /* |K_I * integral| bound [N m] */
    double controller_period;   /* [s] */
    double current_per_newton;  /* battery current per newton of thrust [A/N] */
} FprQuadModel;

/* The plant's constants (Plant, StructureDynamics, Environment); the mass-matrix basis is passed apart. */
typedef struct {
    int n;
    double leg_length;
    double anchors[FPR_MAX_N][3];     /* a_i in Fp [m] */
    double cos_alpha[FPR_MAX_N];
    double sin_alpha[FPR_MAX_N];
    double joint_axes[FPR_MAX_N][3];  /* k_i in Fp */
    double gravity[3];                /* gravity vector, world [m/s^2] */
    double gravity_magnitude;         /* g [m/s^2] */
    double uav_masses[FPR_MAX_N];     /* [kg] */
    double joint_offset[3];           /* B_iS_i in Fbi [m] */
    int ground_enabled;
    double ground_height, ground_stiffness, ground_damping;
    double ground_tangential_stiffness, ground_tangential_damping, ground_friction;
    double gear_height, gear_radius;  /* landing gear [m] */
    double uav_drag, leg_drag, platform_drag;  /* wind drag [N s/m] */
    int board_enabled;
    double board_normal[3], board_point[3];
    double board_stiffness, board_damping, board_friction;
    double board_u[3], board_v[3];    /* in-plane unit axes of the board's rectangle (world) */
    double board_half_size[2];        /* half side lengths along board_u, board_v [m] (inf: unbounded) */
    double board_contact_depth;       /* deepest penetration still in contact [m] (BoardConfig.contact_depth) */
    double end_effector[3];           /* in Fp [m] */
    int joint_stops_enabled;          /* legs' mechanical stops (JointStopConfig) */
    double joint_stop_lower, joint_stop_upper;  /* [rad] */
    double joint_stop_stiffness;      /* [N m/rad] */
    double joint_stop_damping;        /* [N m s/rad] */
    FprQuadModel quad;
} FprPlantModel;

/* ------------------------------------------------------------------------------------------- buffer layouts */

/* Layout kinds for fpr_layout(): offsets (in doubles) of the named slots of each call's buffer. */
enum { FPR_LAYOUT_PLANT = 0, FPR_LAYOUT_CONTROL = 1, FPR_LAYOUT_QUAD = 2, FPR_LAYOUT_ACCELERATE = 3 };

/* plant step buffer: inputs first (x .. platform moment), then outputs; x, quat, rate, rotors, charge,
   tip velocity and yaw anchors are updated in place. P_WIND: the air velocities (world) held over the step at
   the platform centre, the n quadrotors and the n leg middles, 3 (1 + 2n) doubles (Plant._air_velocities).
   P_FACTOR: the per-rotor produced-thrust factors (n, 4) of the realism effects (read with FPR_FLAG_FACTORS);
   P_UAV_FORCE: a world force on each quadrotor (n, 3), the rotor drag (read with FPR_FLAG_UAV_FORCE); both held
   over the step (fpr_sim.plant_realism). */
enum {
    P_X, P_QUAT, P_RATE, P_ROTORS, P_ROTOR_CMD, P_CHARGE, P_TIP_VEL, P_YAW_ANCHOR, P_WIND, P_PFORCE, P_PMOMENT,
    P_FACTOR, P_UAV_FORCE, P_CURRENT, P_TIP_POS, P_TIP_ACC, P_CONTACT, P_GROUND_ACTIVE, P_SIZE, P_COUNT
};
/* controller buffer: inputs, then outputs */
enum {
    C_QUAT, C_RATE, C_PREVIOUS, C_INTEGRAL, C_CMD_QUAT, C_THRUST, C_ARMED, C_LANDED, C_FEEDFORWARD, C_FMAX,
    C_SETPOINT, C_INTEGRAL_OUT, C_COMMANDS, C_SIZE, C_COUNT
};
/* quadrotor step buffer: quat, rate, rotors, charge updated in place; factors (n, 4) read when asked; current
   output */
enum { Q_QUAT, Q_RATE, Q_ROTORS, Q_ROTOR_CMD, Q_MOMENTS, Q_CHARGE, Q_FACTOR, Q_CURRENT, Q_SIZE, Q_COUNT };
/* structure acceleration buffer */
enum { A_COS, A_SIN, A_XI, A_GRAVITY, A_FORCE, A_OUT, A_SIZE, A_COUNT };

static int plant_layout(int n, int *o)
{
    int sizes[P_COUNT - 1] = {13 + 2 * n, 4 * n, 3 * n, 4 * n, 4 * n, n, 3 * n, n, 3 * (1 + 2 * n), 3, 3, 4 * n,
                              3 * n, n, 3 * n, 3 * n, 1, 1};
    int k, at = 0;
    for (k = 0; k < P_SIZE; ++k) {
        o[k] = at;
        at += sizes[k];
    }
    o[P_SIZE] = at;
    return P_COUNT;
}

static int control_layout(int n, int *o)
{
    int sizes[C_COUNT - 1] = {4 * n, 3 * n, 3 * n, 3 * n, 4 * n, n, n, n, 3 * n, n, 3 * n, 3 * n, 4 * n};
    int k, at = 0;
    for (k = 0; k < C_SIZE; ++k) {
        o[k] = at;
        at += sizes[k];
    }
    o[C_SIZE] = at;
    return C_COUNT;
}

static int quad_layout(int n, int *o)
{
    int sizes[Q_COUNT - 1] = {4 * n, 3 * n, 4 * n, 4 * n, 3 * n, n, 4 * n, n};
    int k, at = 0;
    for (k = 0; k < Q_SIZE; ++k) {
        o[k] = at;
        at += sizes[k];
    }
    o[Q_SIZE] = at;
    return Q_COUNT;
}

static int accelerate_layout(int n, int *o)
{
    int sizes[A_COUNT - 1] = {n, n, 6 + n, 3, 6 + n, 6 + n};
    int k, at = 0;
    for (k = 0; k < A_SIZE; ++k) {
        o[k] = at;
        at += sizes[k];
    }
    o[A_SIZE] = at;
    return A_COUNT;
}

/* ------------------------------------------------------------------------------------------- helpers */

/* Python's builtin max(a, b) / min(a, b): the second argument wins only on a strict comparison (NaN kept). */
static double py_max(double a, double b) { return (b > a) ? b : a; }
static double py_min(double a, double b) { return (b < a) ? b : a; }

/* fpr_sim.scalar_math.rotation_entries: row-major entries of fpr_model.rotations.quat_to_rotmat (A.60). */
static void rotation_entries(double w, double x, double y, double z, double r[9])
{
    r[0] = w * w + x * x - y * y - z * z;
    r[1] = 2.0 * (x * y - w * z);
    r[2] = 2.0 * (x * z + w * y);
    r[3] = 2.0 * (x * y + w * z);
    r[4] = w * w - x * x + y * y - z * z;
    r[5] = 2.0 * (y * z - w * x);
    r[6] = 2.0 * (x * z - w * y);
    r[7] = 2.0 * (y * z + w * x);
    r[8] = w * w - x * x - y * y + z * z;
}

/* ------------------------------------------------------------------------------------------- structure */

/* Solve M x = b (dim k, M symmetric): Cholesky (M positive definite, as LAPACK dposv), else Gaussian
   elimination with partial pivoting (np.linalg.solve). M and b are overwritten. */
static int solve_spd(int k, double *M, double *b, double *x)
{
    double L[FPR_MAX_N9 * FPR_MAX_N9];
    int i, j, p, cholesky_ok = 1;
    for (j = 0; j < k && cholesky_ok; ++j) {
        double d = M[j * k + j];
        for (p = 0; p < j; ++p)
            d -= L[j * k + p] * L[j * k + p];
        if (!(d > 0.0)) {
            cholesky_ok = 0;
            break;
        }
        d = sqrt(d);
        L[j * k + j] = d;
        for (i = j + 1; i < k; ++i) {
            double v = M[i * k + j];
            for (p = 0; p < j; ++p)
                v -= L[i * k + p] * L[j * k + p];
            L[i * k + j] = v / d;
        }
    }
    if (cholesky_ok) {
        double y[FPR_MAX_N9];
        for (i = 0; i < k; ++i) {
            double v = b[i];
            for (p = 0; p < i; ++p)
                v -= L[i * k + p] * y[p];
            y[i] = v / L[i * k + i];
        }
        for (i = k - 1; i >= 0; --i) {
            double v = y[i];
            for (p = i + 1; p < k; ++p)
                v -= L[p * k + i] * x[p];
            x[i] = v / L[i * k + i];
        }
        return FPR_OK;
    }
    /* not positive definite (never for a physical parameter set): LU with partial pivoting */
    for (j = 0; j < k; ++j) {
        int pivot = j;
        double best = fabs(M[j * k + j]);
        for (i = j + 1; i < k; ++i) {
            if (fabs(M[i * k + j]) > best) {
                best = fabs(M[i * k + j]);
                pivot = i;
            }
        }
        if (best == 0.0)
            return FPR_ERR_SINGULAR;
        if (pivot != j) {
            for (p = 0; p < k; ++p) {
                double t = M[j * k + p];
                M[j * k + p] = M[pivot * k + p];
                M[pivot * k + p] = t;
            }
            {
                double t = b[j];
                b[j] = b[pivot];
                b[pivot] = t;
            }
        }
        for (i = j + 1; i < k; ++i) {
            double f = M[i * k + j] / M[j * k + j];
            for (p = j; p < k; ++p)
                M[i * k + p] -= f * M[j * k + p];
            b[i] -= f * b[j];
        }
    }
    for (i = k - 1; i >= 0; --i) {
        double v = b[i];
        for (p = i + 1; p < k; ++p)
            v -= M[i * k + p] * x[p];
        x[i] = v / M[i * k + i];
    }
    return FPR_OK;
}

/* StructureDynamics.accelerate: ξ̇ from M̃ ξ̇ = b(ξ) + M̃[:, :3] g_b + Q̃ − Σ θ̇_i ∂_iM̃ ξ (thesis (2.86)-(2.88) in
   platform-body coordinates, Euler-Poincaré / Kirchhoff terms; see structure.py's module doc).
   basis: (1+4n, n9*n9) fitted M̃ basis (row 0 constant incl. payload, then per leg [c, s, c2, s2]). */
static int accelerate(int n, const double *basis, const double *c, const double *s, const double *xi,
                      const double *g_body, const double *q_force, double *out)
{
    const int n9 = 6 + n;
    const int nn = n9 * n9;
    double coef[1 + 4 * FPR_MAX_N], slopes[4 * FPR_MAX_N], weights[4 * FPR_MAX_N];
    double M[FPR_MAX_N9 * FPR_MAX_N9], rows[4 * FPR_MAX_N * FPR_MAX_N9];
    double mu[FPR_MAX_N9], rhs[FPR_MAX_N9], quadratic[4 * FPR_MAX_N];
    int i, k, a, b;
    coef[0] = 1.0;
    for (i = 0; i < n; ++i) {
        const double ci = c[i], si = s[i];
        const double c2 = ci * ci - si * si;
        const double s2 = 2.0 * si * ci;
        const double rate = xi[6 + i];
        coef[1 + 4 * i] = ci;
        coef[2 + 4 * i] = si;
        coef[3 + 4 * i] = c2;
        coef[4 + 4 * i] = s2;
        slopes[4 * i] = -si;
        slopes[4 * i + 1] = ci;
        slopes[4 * i + 2] = -2.0 * s2;
        slopes[4 * i + 3] = 2.0 * c2;
        weights[4 * i] = -si * rate;
        weights[4 * i + 1] = ci * rate;
        weights[4 * i + 2] = -2.0 * s2 * rate;
        weights[4 * i + 3] = 2.0 * c2 * rate;
    }
    /* M̃ = Σ_k coef_k basis_k */
    for (a = 0; a < nn; ++a)
        M[a] = basis[a];
    for (k = 1; k <= 4 * n; ++k) {
        const double w = coef[k];
        const double *B = basis + (size_t)k * nn;
        for (a = 0; a < nn; ++a)
            M[a] += w * B[a];
    }
    /* μ = M̃ ξ (symmetric), gravity rhs = M̃[:, :3] g_b */
    for (a = 0; a < n9; ++a) {
        double v = 0.0, g = 0.0;
        for (b = 0; b < n9; ++b)
            v += xi[b] * M[b * n9 + a];
        for (b = 0; b < 3; ++b)
            g += g_body[b] * M[b * n9 + a];
        mu[a] = v;
        rhs[a] = g;
    }
    /* rows B_ik ξ and ξᵀ B_ik ξ */
    for (k = 0; k < 4 * n; ++k) {
        const double *B = basis + (size_t)(k + 1) * nn;
        double quad = 0.0;
        for (a = 0; a < n9; ++a) {
            double v = 0.0;
            for (b = 0; b < n9; ++b)
                v += B[a * n9 + b] * xi[b];
            rows[k * n9 + a] = v;
            quad += v * xi[a];
        }
        quadratic[k] = quad;
    }
    for (a = 0; a < n9; ++a) {
        double m_dot_xi = 0.0;
        for (k = 0; k < 4 * n; ++k)
            m_dot_xi += weights[k] * rows[k * n9 + a];
        rhs[a] = rhs[a] + q_force[a] - m_dot_xi;
    }
    {
        const double u0 = xi[0], u1 = xi[1], u2 = xi[2], w0 = xi[3], w1 = xi[4], w2 = xi[5];
        const double p0 = mu[0], p1 = mu[1], p2 = mu[2], r0 = mu[3], r1 = mu[4], r2 = mu[5];
        rhs[0] += p1 * w2 - p2 * w1;
        rhs[1] += p2 * w0 - p0 * w2;
        rhs[2] += p0 * w1 - p1 * w0;
        rhs[3] += r1 * w2 - r2 * w1 + p1 * u2 - p2 * u1;
        rhs[4] += r2 * w0 - r0 * w2 + p2 * u0 - p0 * u2;
        rhs[5] += r0 * w1 - r1 * w0 + p0 * u1 - p1 * u0;
    }
    for (i = 0; i < n; ++i) {
        k = 4 * i;
        rhs[6 + i] += 0.5 * (slopes[k] * quadratic[k] + slopes[k + 1] * quadratic[k + 1]
                             + slopes[k + 2] * quadratic[k + 2] + slopes[k + 3] * quadratic[k + 3]);
    }
    return solve_spd(n9, M, rhs, out);
}

/* ------------------------------------------------------------------------------------------- environment */

/* GroundContacts.point_force: penalty normal force with a stick/slip friction anchor (anchor NaN: none). */
static void ground_point_force(const FprPlantModel *m, const double *anchor, double px, double py, double pz,
                               double vx, double vy, double vz, double *f)
{
    const double depth = m->ground_height - pz;
    double normal, ax, ay, tx, ty, size, limit;
    if (!(depth > 0.0) || !m->ground_enabled) {
        f[0] = f[1] = f[2] = 0.0;
        return;
    }
    normal = py_max(m->ground_stiffness * depth - m->ground_damping * vz, 0.0);
    ax = anchor[0];
    ay = anchor[1];
    if (ax != ax) {
        ax = px;
        ay = py;
    }
    tx = -m->ground_tangential_stiffness * (px - ax) - m->ground_tangential_damping * vx;
    ty = -m->ground_tangential_stiffness * (py - ay) - m->ground_tangential_damping * vy;
    size = hypot(tx, ty);
    limit = m->ground_friction * normal;
    if (size > limit) {
        const double scale = limit / py_max(size, 1e-12);
        tx *= scale;
        ty *= scale;
    }
    f[0] = tx;
    f[1] = ty;
    f[2] = normal;
}

/* GroundContacts.update_anchors for one point: create, slide (friction saturated) or drop the anchor. */
static void ground_update_anchor(const FprPlantModel *m, double *anchor, double px, double py, double pz)
{
    const double depth = m->ground_height - pz;
    double limit, sx, sy, size;
    if (!(depth > 0.0) || !m->ground_enabled) {
        anchor[0] = anchor[1] = NAN;
        return;
    }
    if (anchor[0] != anchor[0]) {
        anchor[0] = px;
        anchor[1] = py;
        return;
    }
    limit = m->ground_friction * m->ground_stiffness * depth / m->ground_tangential_stiffness;
    sx = px - anchor[0];
    sy = py - anchor[1];
    size = hypot(sx, sy);
    if (size > limit) {
        anchor[0] = px - sx * (limit / size);
        anchor[1] = py - sy * (limit / size);
    }
}

/* Environment.board_force_scalar: board contact force (world) on the end-effector; returns the normal force. */
static double board_force(const FprPlantModel *m, const double *point, const double *velocity, double *f)
{
    const double *nv = m->board_normal, *bp = m->board_point, *bu = m->board_u, *bv = m->board_v;
    double depth, normal_speed, normal, t0, t1, t2, scale, o0, o1, o2;
    f[0] = f[1] = f[2] = 0.0;
    if (!m->board_enabled)
        return 0.0;
    o0 = point[0] - bp[0];
    o1 = point[1] - bp[1];
    o2 = point[2] - bp[2];
    depth = -(o0 * nv[0] + o1 * nv[1] + o2 * nv[2]);
    if (depth <= 0.0 || depth > m->board_contact_depth)  /* in front of the face, or behind the board */
        return 0.0;
    /* over the board's rectangle only (beside it: no contact) */
    if (!(fabs(o0 * bu[0] + o1 * bu[1] + o2 * bu[2]) <= m->board_half_size[0]
          && fabs(o0 * bv[0] + o1 * bv[1] + o2 * bv[2]) <= m->board_half_size[1]))
        return 0.0;
    normal_speed = velocity[0] * nv[0] + velocity[1] * nv[1] + velocity[2] * nv[2];
    normal = py_max(0.0, m->board_stiffness * depth - m->board_damping * normal_speed);
    t0 = velocity[0] - normal_speed * nv[0];
    t1 = velocity[1] - normal_speed * nv[1];
    t2 = velocity[2] - normal_speed * nv[2];
    scale = -m->board_friction * normal / py_max(sqrt(t0 * t0 + t1 * t1 + t2 * t2), 0.01);
    f[0] = normal * nv[0] + scale * t0;
    f[1] = normal * nv[1] + scale * t1;
    f[2] = normal * nv[2] + scale * t2;
    return normal;
}

/* ------------------------------------------------------------------------------------------- plant */

/* plant.joint_stop_moment: unilateral penalty moment of a leg's mechanical stop [N m], positive towards larger
   θ (the θ_i row of the generalized forces of (2.86)). */
static double joint_stop_moment(const FprPlantModel *m, double theta, double rate)
{
    if (theta < m->joint_stop_lower)
        return py_max(0.0, m->joint_stop_stiffness * (m->joint_stop_lower - theta) - m->joint_stop_damping * rate);
    if (theta > m->joint_stop_upper)
        return py_min(0.0, m->joint_stop_stiffness * (m->joint_stop_upper - theta) - m->joint_stop_damping * rate);
    return 0.0;
}

/* Per-step inputs of the structure derivative, held over the RK4 stages. */
typedef struct {
    const double *thrust;   /* (n, 3) world thrust vectors [N] */
    int ground;             /* ground contact evaluated */
    const double *wind;     /* air velocities (3 (1 + 2n): P, quadrotors, leg middles) or NULL */
    const double *anchors;  /* ground anchors (n+1, 2) */
    const double *pforce;   /* platform force (world, at P) */
    const double *pmoment;  /* platform moment (Fp) */
    double stage_contact;   /* board normal force of the last evaluation [N] */
} StageInputs;

/* Plant._derivative: ẋ of x = [P, q_p, θ, u, ω, θ̇] with the held thrusts and the environment forces of this
   stage: point forces f (world) at body points ρ (Fp) enter Q̃ as [Rᵀf, ρ × Rᵀf, k_i · ((ρ − a_i) × Rᵀf)]
   ((2.28) generalised), thesis (2.86) solved by accelerate(). */
static int plant_derivative(const FprPlantModel *m, const double *basis, const double *x, StageInputs *in,
                            double *dx)
{
    const int n = m->n;
    const double length = m->leg_length;
    const double px = x[0], py = x[1], pz = x[2], qw = x[3], qx = x[4], qy = x[5], qz = x[6];
    const double *xi = x + 7 + n;
    const double u0 = xi[0], u1 = xi[1], u2 = xi[2], w0 = xi[3], w1 = xi[4], w2 = xi[5];
    const int ground = in->ground;
    const double *wind = in->wind;
    const int need_velocity = ground || wind != NULL;
    double r[9];
    double fp0 = in->pforce[0], fp1 = in->pforce[1], fp2 = in->pforce[2];
    double q0 = 0.0, q1 = 0.0, q2 = 0.0, mm0 = 0.0, mm1 = 0.0, mm2 = 0.0;
    double c_list[FPR_MAX_N], s_list[FPR_MAX_N], q_force[FPR_MAX_N9], g_body[3];
    int i, status;
    rotation_entries(qw, qx, qy, qz, r);
    for (i = 0; i < n; ++i) {
        const double theta = x[7 + i];
        const double c = cos(theta), s = sin(theta);
        const double a0 = m->anchors[i][0], a1 = m->anchors[i][1], a2 = m->anchors[i][2];
        const double ca = m->cos_alpha[i], sa = m->sin_alpha[i];
        const double e0 = ca * c, e1 = sa * c, e2 = -s;
        const double t0 = a0 + length * e0, t1 = a1 + length * e1, t2 = a2 + length * e2;
        double f0 = in->thrust[3 * i], f1 = in->thrust[3 * i + 1], f2 = in->thrust[3 * i + 2];
        double mid0 = 0.0, mid1 = 0.0, mid2 = 0.0;
        double g0, g1, g2, l0, l1, l2;
        const double k0 = m->joint_axes[i][0], k1 = m->joint_axes[i][1], k2 = m->joint_axes[i][2];
        c_list[i] = c;
        s_list[i] = s;
        if (need_velocity) {
            const double lr = length * xi[6 + i];
            const double n0 = -ca * s, n1 = -sa * s, n2 = -c;
            double b0 = u0 + w1 * t2 - w2 * t1 + lr * n0;
            double b1 = u1 + w2 * t0 - w0 * t2 + lr * n1;
            double b2 = u2 + w0 * t1 - w1 * t0 + lr * n2;
            const double v0 = r[0] * b0 + r[1] * b1 + r[2] * b2;
            const double v1 = r[3] * b0 + r[4] * b1 + r[5] * b2;
            const double v2 = r[6] * b0 + r[7] * b1 + r[8] * b2;
            if (ground) {
                double gf[3];
                ground_point_force(m, in->anchors + 2 * i, px + r[0] * t0 + r[1] * t1 + r[2] * t2,
                                   py + r[3] * t0 + r[4] * t1 + r[5] * t2,
                                   pz + r[6] * t0 + r[7] * t1 + r[8] * t2 - m->gear_height, v0, v1, v2, gf);
                f0 += gf[0];
                f1 += gf[1];
                f2 += gf[2];
            }
            if (wind != NULL) {
                const double *uav_air = wind + 3 + 3 * i, *mid_air = wind + 3 + 3 * n + 3 * i;
                const double air0 = uav_air[0], air1 = uav_air[1], air2 = uav_air[2];
                const double drag = m->uav_drag;
                const double h0 = 0.5 * (t0 + a0), h1 = 0.5 * (t1 + a1), h2 = 0.5 * (t2 + a2);
                const double hl = 0.5 * lr;
                double d0, d1, d2;
                f0 += drag * (air0 - v0);
                f1 += drag * (air1 - v1);
                f2 += drag * (air2 - v2);
                b0 = u0 + w1 * h2 - w2 * h1 + hl * n0;
                b1 = u1 + w2 * h0 - w0 * h2 + hl * n1;
                b2 = u2 + w0 * h1 - w1 * h0 + hl * n2;
                d0 = m->leg_drag * (mid_air[0] - (r[0] * b0 + r[1] * b1 + r[2] * b2));
                d1 = m->leg_drag * (mid_air[1] - (r[3] * b0 + r[4] * b1 + r[5] * b2));
                d2 = m->leg_drag * (mid_air[2] - (r[6] * b0 + r[7] * b1 + r[8] * b2));
                mid0 = r[0] * d0 + r[3] * d1 + r[6] * d2;
                mid1 = r[1] * d0 + r[4] * d1 + r[7] * d2;
                mid2 = r[2] * d0 + r[5] * d1 + r[8] * d2;
            }
        }
        /* tip force in Fp */
        g0 = r[0] * f0 + r[3] * f1 + r[6] * f2;
        g1 = r[1] * f0 + r[4] * f1 + r[7] * f2;
        g2 = r[2] * f0 + r[5] * f1 + r[8] * f2;
        q0 += g0 + mid0;
        q1 += g1 + mid1;
        q2 += g2 + mid2;
        mm0 += t1 * g2 - t2 * g1;
        mm1 += t2 * g0 - t0 * g2;
        mm2 += t0 * g1 - t1 * g0;
        /* lever of the joint moment: l e_i × (f_tip + f_mid / 2), and the mid force's moment about P */
        l0 = g0 + 0.5 * mid0;
        l1 = g1 + 0.5 * mid1;
        l2 = g2 + 0.5 * mid2;
        if (mid0 != 0.0 || mid1 != 0.0 || mid2 != 0.0) {
            const double h0 = a0 + 0.5 * length * e0, h1 = a1 + 0.5 * length * e1, h2 = a2 + 0.5 * length * e2;
            mm0 += h1 * mid2 - h2 * mid1;
            mm1 += h2 * mid0 - h0 * mid2;
            mm2 += h0 * mid1 - h1 * mid0;
        }
        q_force[6 + i] = length * (k0 * (e1 * l2 - e2 * l1) + k1 * (e2 * l0 - e0 * l2) + k2 * (e0 * l1 - e1 * l0));
        if (m->joint_stops_enabled && !(m->joint_stop_lower <= theta && theta <= m->joint_stop_upper))
            q_force[6 + i] += joint_stop_moment(m, theta, xi[6 + i]); /* the leg is in a mechanical stop */
    }
    if (ground) {
        const double vc0 = r[0] * u0 + r[1] * u1 + r[2] * u2;
        const double vc1 = r[3] * u0 + r[4] * u1 + r[5] * u2;
        const double vc2 = r[6] * u0 + r[7] * u1 + r[8] * u2;
        double gf[3];
        ground_point_force(m, in->anchors + 2 * n, px, py, pz, vc0, vc1, vc2, gf);
        fp0 += gf[0];
        fp1 += gf[1];
        fp2 += gf[2];
    }
    if (wind != NULL) {
        const double drag = m->platform_drag;
        fp0 += drag * (wind[0] - (r[0] * u0 + r[1] * u1 + r[2] * u2));
        fp1 += drag * (wind[1] - (r[3] * u0 + r[4] * u1 + r[5] * u2));
        fp2 += drag * (wind[2] - (r[6] * u0 + r[7] * u1 + r[8] * u2));
    }
    if (m->board_enabled) {
        const double e0 = m->end_effector[0], e1 = m->end_effector[1], e2 = m->end_effector[2];
        const double b0 = u0 + w1 * e2 - w2 * e1;
        const double b1 = u1 + w2 * e0 - w0 * e2;
        const double b2 = u2 + w0 * e1 - w1 * e0;
        double point[3], velocity[3], f[3], normal;
        point[0] = px + r[0] * e0 + r[1] * e1 + r[2] * e2;
        point[1] = py + r[3] * e0 + r[4] * e1 + r[5] * e2;
        point[2] = pz + r[6] * e0 + r[7] * e1 + r[8] * e2;
        velocity[0] = r[0] * b0 + r[1] * b1 + r[2] * b2;
        velocity[1] = r[3] * b0 + r[4] * b1 + r[5] * b2;
        velocity[2] = r[6] * b0 + r[7] * b1 + r[8] * b2;
        normal = board_force(m, point, velocity, f);
        in->stage_contact = normal;
        if (normal > 0.0) {
            const double g0 = r[0] * f[0] + r[3] * f[1] + r[6] * f[2];
            const double g1 = r[1] * f[0] + r[4] * f[1] + r[7] * f[2];
            const double g2 = r[2] * f[0] + r[5] * f[1] + r[8] * f[2];
            q0 += g0;
            q1 += g1;
            q2 += g2;
            mm0 += e1 * g2 - e2 * g1;
            mm1 += e2 * g0 - e0 * g2;
            mm2 += e0 * g1 - e1 * g0;
        }
    }
    q_force[0] = q0 + r[0] * fp0 + r[3] * fp1 + r[6] * fp2;
    q_force[1] = q1 + r[1] * fp0 + r[4] * fp1 + r[7] * fp2;
    q_force[2] = q2 + r[2] * fp0 + r[5] * fp1 + r[8] * fp2;
    q_force[3] = mm0 + in->pmoment[0];
    q_force[4] = mm1 + in->pmoment[1];
    q_force[5] = mm2 + in->pmoment[2];
    {
        const double gx = m->gravity[0], gy = m->gravity[1], gz = m->gravity[2];
        g_body[0] = r[0] * gx + r[3] * gy + r[6] * gz;
        g_body[1] = r[1] * gx + r[4] * gy + r[7] * gz;
        g_body[2] = r[2] * gx + r[5] * gy + r[8] * gz;
    }
    status = accelerate(n, basis, c_list, s_list, xi, g_body, q_force, dx + 7 + n);
    if (status != FPR_OK)
        return status;
    dx[0] = r[0] * u0 + r[1] * u1 + r[2] * u2;
    dx[1] = r[3] * u0 + r[4] * u1 + r[5] * u2;
    dx[2] = r[6] * u0 + r[7] * u1 + r[8] * u2;
    dx[3] = 0.5 * (-qx * w0 - qy * w1 - qz * w2);
    dx[4] = 0.5 * (qw * w0 + qy * w2 - qz * w1);
    dx[5] = 0.5 * (qw * w1 - qx * w2 + qz * w0);
    dx[6] = 0.5 * (qw * w2 + qx * w1 - qy * w0);
    for (i = 0; i < n; ++i)
        dx[7 + i] = xi[6 + i];
    return FPR_OK;
}

/* Plant._tip_kinematics_list: tip positions B_i and velocities (world), p_i = P + R ρ_i,
   v_i = R (u + ω × ρ_i + l θ̇_i ∂e_i/∂θ_i) with ρ_i = a_i + l e_i (thesis (2.5)). */
static void tip_kinematics(const FprPlantModel *m, const double *x, double *positions, double *velocities)
{
    const int n = m->n;
    const double length = m->leg_length;
    const double *xi = x + 7 + n;
    const double u0 = xi[0], u1 = xi[1], u2 = xi[2], w0 = xi[3], w1 = xi[4], w2 = xi[5];
    double r[9];
    int i;
    rotation_entries(x[3], x[4], x[5], x[6], r);
    for (i = 0; i < n; ++i) {
        const double theta = x[7 + i];
        const double c = cos(theta), s = sin(theta);
        const double ca = m->cos_alpha[i], sa = m->sin_alpha[i];
        const double t0 = m->anchors[i][0] + length * ca * c;
        const double t1 = m->anchors[i][1] + length * sa * c;
        const double t2 = m->anchors[i][2] - length * s;
        const double lr = length * xi[6 + i];
        const double v0 = u0 + w1 * t2 - w2 * t1 - lr * ca * s;
        const double v1 = u1 + w2 * t0 - w0 * t2 - lr * sa * s;
        const double v2 = u2 + w0 * t1 - w1 * t0 - lr * c;
        positions[3 * i] = x[0] + r[0] * t0 + r[1] * t1 + r[2] * t2;
        positions[3 * i + 1] = x[1] + r[3] * t0 + r[4] * t1 + r[5] * t2;
        positions[3 * i + 2] = x[2] + r[6] * t0 + r[7] * t1 + r[8] * t2;
        velocities[3 * i] = r[0] * v0 + r[1] * v1 + r[2] * v2;
        velocities[3 * i + 1] = r[3] * v0 + r[4] * v1 + r[5] * v2;
        velocities[3 * i + 2] = r[6] * v0 + r[7] * v1 + r[8] * v2;
    }
}

/* Plant._add_landing_gear_moments: levelling (bounded by the tipping moment N_i r) and yaw stick/slip friction
   moments (body FLU) on the quadrotors whose feet touch the ground, in place; updates the yaw anchors. */
static void landing_gear_moments(const FprPlantModel *m, const double *anchors, const double *quats,
                                 const double *rates, const double *normals, double *yaw_anchors, double *moments)
{
    const int n = m->n;
    const double radius = m->gear_radius;
    const double arm = m->quad.arm;
    const double yaw_stiffness = m->ground_tangential_stiffness * radius * radius;
    const double yaw_damping = m->ground_tangential_damping * radius * radius;
    int i;
    for (i = 0; i < n; ++i) {
        const double *q = quats + 4 * i;
        const double qw = q[0], qx = q[1], qy = q[2], qz = q[3];
        const double w0 = rates[3 * i], w1 = rates[3 * i + 1], w2 = rates[3 * i + 2];
        double r[9], up0, up1, up2, tipping, stiffness, m0, m1, size, yaw, yaw_anchor, stretch, limit, mz;
        if (anchors[2 * i] != anchors[2 * i]) { /* NaN: not touching */
            yaw_anchors[i] = NAN;
            continue;
        }
        rotation_entries(qw, qx, qy, qz, r);
        up0 = r[6];
        up1 = r[7];
        up2 = r[8]; /* world z in body coordinates */
        tipping = py_max(normals[i], 0.0) * radius;
        stiffness = m->uav_masses[i] * m->gravity_magnitude * 0.5 * arm * 4.0;
        /* tilt = up_body × e_z */
        m0 = -stiffness * up1 - 0.2 * w0;
        m1 = stiffness * up0 - 0.2 * w1;
        size = hypot(m0, m1);
        if (size > tipping) {
            const double scale = tipping / size;
            m0 *= scale;
            m1 *= scale;
        }
        /* yaw friction about the world vertical */
        yaw = atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz));
        yaw_anchor = yaw_anchors[i];
        if (yaw_anchor != yaw_anchor)
            yaw_anchor = yaw;
        stretch = remainder(yaw - yaw_anchor, 2.0 * FPR_PI);
        limit = m->ground_friction * py_max(normals[i], 0.0) * radius;
        if (yaw_stiffness * fabs(stretch) > limit) { /* slipping: the anchor follows */
            stretch = copysign(limit / yaw_stiffness, stretch);
            yaw_anchor = yaw - stretch;
        }
        yaw_anchors[i] = yaw_anchor;
        mz = -yaw_stiffness * stretch - yaw_damping * (up0 * w0 + up1 * w1 + up2 * w2);
        mz = py_min(py_max(mz, -limit), limit);
        moments[3 * i] += m0 + mz * up0;
        moments[3 * i + 1] += m1 + mz * up1;
        moments[3 * i + 2] += mz * up2;
    }
}

/* Battery.update: current k_I·max(f_t, 0) [A] drawn during dt; charge used [A h]. */
static void battery_update(const FprQuadModel *q, const double *rotors, double dt, double *charge, double *current)
{
    int i;
    for (i = 0; i < q->n; ++i) {
        const double *t = rotors + 4 * i;
        const double thrust = t[0] + t[1] + t[2] + t[3];
        const double amps = q->current_per_newton * py_max(thrust, 0.0);
        current[i] = amps;
        charge[i] = charge[i] + amps * dt / 3600.0;
    }
}

/* quadrotor._attitude_derivative: (2.92) q̇ = ½ q ∘ [0, ω], I ω̇ = m − ω × I ω with m = base + offset·slope. */
static void attitude_derivative(const double *y, const double *base, const double *slope, double offset,
                                const double *inertia, double *dy)
{
    const double qw = y[0], qx = y[1], qy = y[2], qz = y[3], w0 = y[4], w1 = y[5], w2 = y[6];
    const double i0 = inertia[0], i1 = inertia[1], i2 = inertia[2];
    const double h0 = w0 * i0, h1 = w1 * i1, h2 = w2 * i2;
    dy[0] = 0.5 * (-qx * w0 - qy * w1 - qz * w2);
    dy[1] = 0.5 * (qw * w0 + qy * w2 - qz * w1);
    dy[2] = 0.5 * (qw * w1 - qx * w2 + qz * w0);
    dy[3] = 0.5 * (qw * w2 + qx * w1 - qy * w0);
    dy[4] = (base[0] + offset * slope[0] - (w1 * h2 - w2 * h1)) / i0;
    dy[5] = (base[1] + offset * slope[1] - (w2 * h0 - w0 * h2)) / i1;
    dy[6] = (base[2] + offset * slope[2] - (w0 * h1 - w1 * h0)) / i2;
}

/* QuadrotorFleet.step: (2.92) and the motor lag Ṫ = (T_cmd − T)/τ_m by classical RK4 (motor stages in closed
   form), quaternion re-normalised, then Battery.update. quat (n,4), rate (n,3), rotors (n,4) in place. factors
   (n,4): produced thrust k_j T_j of the rotors (QuadrotorFleet.rotor_factors), NULL: k = 1. */
static void quad_step(const FprQuadModel *q, double *quat, double *rate, double *rotors, const double *commands,
                      const double *moments, double *charge, double *current, double dt, const double *factors)
{
    const double arm = q->arm, kappa = q->kappa, tau = q->motor_tau;
    const double a = dt / tau;
    const double beta2 = 1.0 - 0.5 * a;
    const double beta3 = 1.0 - 0.5 * a * beta2;
    const double beta4 = 1.0 - a * beta3;
    const double h = 0.5 * dt;
    const double sixth = dt / 6.0;
    int i, j;
    for (i = 0; i < q->n; ++i) {
        double *t = rotors + 4 * i;
        const double *cmd = commands + 4 * i;
        const double *mo = moments + 3 * i;
        const double t1 = t[0], t2 = t[1], t3 = t[2], t4 = t[3];
        const double e1 = cmd[0] - t1, e2 = cmd[1] - t2, e3 = cmd[2] - t3, e4 = cmd[3] - t4;
        double base[3], slope[3], y[7], ys[7], k1[7], k2[7], k3[7], k4[7], norm, gain;
        double p1 = t1, p2 = t2, p3 = t3, p4 = t4, d1 = e1, d2 = e2, d3 = e3, d4 = e4;
        if (factors != NULL) {
            const double *f = factors + 4 * i;
            p1 = f[0] * t1;
            p2 = f[1] * t2;
            p3 = f[2] * t3;
            p4 = f[3] * t4;
            d1 = f[0] * e1;
            d2 = f[1] * e2;
            d3 = f[2] * e3;
            d4 = f[3] * e4;
        }
        base[0] = arm * (p2 - p4) + mo[0];
        base[1] = arm * (p3 - p1) + mo[1];
        base[2] = kappa * (-p1 + p2 - p3 + p4) + mo[2];
        slope[0] = arm * (d2 - d4) / tau;
        slope[1] = arm * (d3 - d1) / tau;
        slope[2] = kappa * (-d1 + d2 - d3 + d4) / tau;
        for (j = 0; j < 4; ++j)
            y[j] = quat[4 * i + j];
        for (j = 0; j < 3; ++j)
            y[4 + j] = rate[3 * i + j];
        attitude_derivative(y, base, slope, 0.0, q->inertia, k1);
        for (j = 0; j < 7; ++j)
            ys[j] = y[j] + h * k1[j];
        attitude_derivative(ys, base, slope, h, q->inertia, k2);
        for (j = 0; j < 7; ++j)
            ys[j] = y[j] + h * k2[j];
        attitude_derivative(ys, base, slope, h * beta2, q->inertia, k3);
        for (j = 0; j < 7; ++j)
            ys[j] = y[j] + dt * k3[j];
        attitude_derivative(ys, base, slope, dt * beta3, q->inertia, k4);
        for (j = 0; j < 7; ++j)
            y[j] = y[j] + sixth * (k1[j] + 2 * k2[j] + 2 * k3[j] + k4[j]);
        norm = sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2] + y[3] * y[3]);
        for (j = 0; j < 4; ++j)
            quat[4 * i + j] = y[j] / norm;
        for (j = 0; j < 3; ++j)
            rate[3 * i + j] = y[4 + j];
        gain = sixth * (1.0 + 2.0 * beta2 + 2.0 * beta3 + beta4) / tau;
        t[0] = py_max(t1 + gain * e1, 0.0);
        t[1] = py_max(t2 + gain * e2, 0.0);
        t[2] = py_max(t3 + gain * e3, 0.0);
        t[3] = py_max(t4 + gain * e4, 0.0);
    }
    battery_update(q, rotors, dt, charge, current);
}

/* Plant.step after the controller update, payload, wind and wrench scheduling (done in Python): the ground
   activity test, RK4 of the structure with the held thrusts (quaternion re-normalised), the tip kinematics,
   ground anchors, the joint-offset moment (2.93) m = d_b × (R_biᵀ f_l,i) with f_l,i = m_b,i a_i − f_i − m_b,i g
   − f_env,i, the landing-gear moments, then the quadrotors (QuadrotorFleet.step) or, with ideal attitudes,
   the battery alone. */
#define FPR_FLAG_IDEAL 1
#define FPR_FLAG_WIND 2
#define FPR_FLAG_FACTORS 4
#define FPR_FLAG_UAV_FORCE 8

static int plant_step(const FprPlantModel *m, const double *basis, double *anchors, double *io, double dt, int flags)
{
    const int n = m->n;
    const int dim = 13 + 2 * n;
    int o[P_COUNT];
    double *x, *quat, *rate, *rotors, *tip_vel, *yaw_anchors, *tip_pos, *tip_acc;
    double thrust[3 * FPR_MAX_N], k1[13 + 2 * FPR_MAX_N], k2[13 + 2 * FPR_MAX_N], k3[13 + 2 * FPR_MAX_N];
    double k4[13 + 2 * FPR_MAX_N], stage[13 + 2 * FPR_MAX_N], new_pos[3 * FPR_MAX_N], new_vel[3 * FPR_MAX_N];
    double env_uav[3 * FPR_MAX_N], normals[FPR_MAX_N], moments[3 * FPR_MAX_N], start_quat[4 * FPR_MAX_N];
    double start_rate[3 * FPR_MAX_N];
    double h, sixth, norm, contact;
    const double *factors;
    int i, k, status, ground_active = 0, landed = 0;
    StageInputs in;
    plant_layout(n, o);
    x = io + o[P_X];
    quat = io + o[P_QUAT];
    rate = io + o[P_RATE];
    rotors = io + o[P_ROTORS];
    tip_vel = io + o[P_TIP_VEL];
    yaw_anchors = io + o[P_YAW_ANCHOR];
    tip_pos = io + o[P_TIP_POS];
    tip_acc = io + o[P_TIP_ACC];
    /* ground activity: a foot or P within a margin of the ground (tips of the current state) */
    tip_kinematics(m, x, new_pos, new_vel);
    if (m->ground_enabled) {
        double vmax = fabs(new_vel[2]), zmin = new_pos[2], margin;
        for (i = 1; i < n; ++i) {
            vmax = py_max(vmax, fabs(new_vel[3 * i + 2]));
            zmin = py_min(zmin, new_pos[3 * i + 2]);
        }
        margin = 0.05 + 2.0 * vmax * dt;
        ground_active = (zmin - m->gear_height < m->ground_height + margin) || (x[2] < m->ground_height + margin);
    }
    /* thrust vectors f_i = R_bi [0, 0, f_t] held over the step (QuadrotorFleet.thrust_vectors_list), f_t the
       produced thrust Σ k_j T_j with the realism factors; plus the held world force on each quadrotor (rotor
       drag, Plant._advance) */
    factors = (flags & FPR_FLAG_FACTORS) ? io + o[P_FACTOR] : NULL;
    for (i = 0; i < n; ++i) {
        const double *q = quat + 4 * i, *t = rotors + 4 * i;
        const double w = q[0], qx = q[1], qy = q[2], qz = q[3];
        double f;
        if (factors != NULL) {
            const double *k = factors + 4 * i;
            f = k[0] * t[0] + k[1] * t[1] + k[2] * t[2] + k[3] * t[3];
        } else {
            f = t[0] + t[1] + t[2] + t[3];
        }
        thrust[3 * i] = 2.0 * (qx * qz + w * qy) * f;
        thrust[3 * i + 1] = 2.0 * (qy * qz - w * qx) * f;
        thrust[3 * i + 2] = (w * w - qx * qx - qy * qy + qz * qz) * f;
        if (flags & FPR_FLAG_UAV_FORCE) {
            const double *extra = io + o[P_UAV_FORCE] + 3 * i;
            thrust[3 * i] += extra[0];
            thrust[3 * i + 1] += extra[1];
            thrust[3 * i + 2] += extra[2];
        }
    }
    in.thrust = thrust;
    in.ground = ground_active;
    in.wind = (flags & FPR_FLAG_WIND) ? io + o[P_WIND] : NULL;
    in.anchors = anchors;
    in.pforce = io + o[P_PFORCE];
    in.pmoment = io + o[P_PMOMENT];
    in.stage_contact = 0.0;
    /* classical RK4 on the structure state */
    h = 0.5 * dt;
    if ((status = plant_derivative(m, basis, x, &in, k1)) != FPR_OK)
        return status;
    contact = in.stage_contact;
    for (k = 0; k < dim; ++k)
        stage[k] = x[k] + h * k1[k];
    if ((status = plant_derivative(m, basis, stage, &in, k2)) != FPR_OK)
        return status;
    for (k = 0; k < dim; ++k)
        stage[k] = x[k] + h * k2[k];
    if ((status = plant_derivative(m, basis, stage, &in, k3)) != FPR_OK)
        return status;
    for (k = 0; k < dim; ++k)
        stage[k] = x[k] + dt * k3[k];
    if ((status = plant_derivative(m, basis, stage, &in, k4)) != FPR_OK)
        return status;
    sixth = dt / 6.0;
    for (k = 0; k < dim; ++k)
        x[k] = x[k] + sixth * (k1[k] + 2.0 * k2[k] + 2.0 * k3[k] + k4[k]);
    norm = sqrt(x[3] * x[3] + x[4] * x[4] + x[5] * x[5] + x[6] * x[6]);
    x[3] = x[3] / norm;
    x[4] = x[4] / norm;
    x[5] = x[5] / norm;
    x[6] = x[6] / norm;
    io[o[P_CONTACT]] = contact;
    io[o[P_GROUND_ACTIVE]] = ground_active ? 1.0 : 0.0;
    /* environment forces on the quadrotors at the new state */
    tip_kinematics(m, x, new_pos, new_vel);
    for (k = 0; k < 3 * n; ++k)
        env_uav[k] = 0.0;
    if (ground_active) {
        for (i = 0; i < n; ++i)
            ground_update_anchor(m, anchors + 2 * i, new_pos[3 * i], new_pos[3 * i + 1],
                                 new_pos[3 * i + 2] - m->gear_height);
        ground_update_anchor(m, anchors + 2 * n, x[0], x[1], x[2]);
        for (i = 0; i < n; ++i)
            ground_point_force(m, anchors + 2 * i, new_pos[3 * i], new_pos[3 * i + 1],
                               new_pos[3 * i + 2] - m->gear_height, new_vel[3 * i], new_vel[3 * i + 1],
                               new_vel[3 * i + 2], env_uav + 3 * i);
    }
    for (i = 0; i < n; ++i)
        normals[i] = env_uav[3 * i + 2];
    if (flags & FPR_FLAG_WIND) {
        const double *wind = io + o[P_WIND];
        for (i = 0; i < n; ++i)
            for (k = 0; k < 3; ++k)
                env_uav[3 * i + k] += m->uav_drag * (wind[3 + 3 * i + k] - new_vel[3 * i + k]);
    }
    /* spherical-joint offset moment (2.93), body frame */
    {
        const double gx = m->gravity[0], gy = m->gravity[1], gz = m->gravity[2];
        const double d0 = m->joint_offset[0], d1 = m->joint_offset[1], d2 = m->joint_offset[2];
        for (i = 0; i < n; ++i) {
            double acc[3], r[9], f0, f1, f2, b0, b1, b2;
            const double mass = m->uav_masses[i];
            for (k = 0; k < 3; ++k)
                acc[k] = (new_vel[3 * i + k] - tip_vel[3 * i + k]) / dt;
            for (k = 0; k < 3; ++k)
                tip_acc[3 * i + k] = acc[k];
            f0 = mass * (acc[0] - gx) - thrust[3 * i] - env_uav[3 * i];
            f1 = mass * (acc[1] - gy) - thrust[3 * i + 1] - env_uav[3 * i + 1];
            f2 = mass * (acc[2] - gz) - thrust[3 * i + 2] - env_uav[3 * i + 2];
            rotation_entries(quat[4 * i], quat[4 * i + 1], quat[4 * i + 2], quat[4 * i + 3], r);
            b0 = r[0] * f0 + r[3] * f1 + r[6] * f2;
            b1 = r[1] * f0 + r[4] * f1 + r[7] * f2;
            b2 = r[2] * f0 + r[5] * f1 + r[8] * f2;
            moments[3 * i] = d1 * b2 - d2 * b1;
            moments[3 * i + 1] = d2 * b0 - d0 * b2;
            moments[3 * i + 2] = d0 * b1 - d1 * b0;
        }
    }
    if (ground_active) {
        for (i = 0; i < n; ++i)
            if (anchors[2 * i] == anchors[2 * i])
                landed = 1;
    }
    if (landed) {
        for (k = 0; k < 4 * n; ++k)
            start_quat[k] = quat[k];
        for (k = 0; k < 3 * n; ++k)
            start_rate[k] = rate[k];
        landing_gear_moments(m, anchors, start_quat, start_rate, normals, yaw_anchors, moments);
    } else {
        for (i = 0; i < n; ++i)
            yaw_anchors[i] = NAN;
    }
    for (k = 0; k < 3 * n; ++k) {
        tip_pos[k] = new_pos[k];
        tip_vel[k] = new_vel[k];
    }
    if (flags & FPR_FLAG_IDEAL)
        battery_update(&m->quad, rotors, dt, io + o[P_CHARGE], io + o[P_CURRENT]);
    else
        quad_step(&m->quad, quat, rate, rotors, io + o[P_ROTOR_CMD], moments, io + o[P_CHARGE],
                  io + o[P_CURRENT], dt, factors);
    return FPR_OK;
}

/* ------------------------------------------------------------------------------------------- controller */

/* quadrotor._desaturation_gain (PX4 computeDesaturationGain). */
static double desaturation_gain(const double *rotors, const double *axis, double top)
{
    double k_min = 0.0, k_max = 0.0, k;
    int j;
    for (j = 0; j < 4; ++j) {
        const double t = rotors[j], a = axis[j];
        if (a == 0.0)
            continue;
        if (t < 0.0)
            k = -t / a;
        else if (t > top)
            k = (top - t) / a;
        else
            continue;
        k_min = py_min(k_min, k);
        k_max = py_max(k_max, k);
    }
    return k_min + k_max;
}

/* quadrotor._desaturate (PX4 desaturateActuators), in place. */
static void desaturate(double *rotors, const double *axis, double top, int reduce_only)
{
    double gain = desaturation_gain(rotors, axis, top);
    int j;
    if (reduce_only && gain > 0.0)
        return;
    for (j = 0; j < 4; ++j)
        rotors[j] += gain * axis[j];
    gain = 0.5 * desaturation_gain(rotors, axis, top);
    for (j = 0; j < 4; ++j)
        rotors[j] += gain * axis[j];
}

static int out_of_bounds(const double *rotors, double top)
{
    double lo = rotors[0], hi = rotors[0];
    int j;
    for (j = 1; j < 4; ++j) {
        lo = py_min(lo, rotors[j]);
        hi = py_max(hi, rotors[j]);
    }
    return lo < 0.0 || hi > top;
}

/* quadrotor.mix_one: inverse of the "+" allocation (3.41) with PX4's airmode-off sequential desaturation. */
static void mix_one(double collective, const double *moments, double arm, double kappa, double rotor_max,
                    double *rotors)
{
    const double mx = moments[0], my = moments[1], mz = moments[2];
    const double half_arm = 0.5 / arm;
    const double quarter_kappa = 0.25 / kappa;
    const double quarter = 0.25 * collective;
    const double roll_axis[4] = {0.0, half_arm, 0.0, -half_arm};
    const double pitch_axis[4] = {-half_arm, 0.0, half_arm, 0.0};
    const double yaw_axis[4] = {-quarter_kappa, quarter_kappa, -quarter_kappa, quarter_kappa};
    const double thrust_axis[4] = {0.25, 0.25, 0.25, 0.25};
    int j;
    for (j = 0; j < 4; ++j)
        rotors[j] = quarter + mx * roll_axis[j] + my * pitch_axis[j];
    if (out_of_bounds(rotors, rotor_max)) {
        desaturate(rotors, thrust_axis, rotor_max, 1);
        desaturate(rotors, roll_axis, rotor_max, 0);
        desaturate(rotors, pitch_axis, rotor_max, 0);
    }
    for (j = 0; j < 4; ++j)
        rotors[j] = rotors[j] + mz * yaw_axis[j];
    if (out_of_bounds(rotors, rotor_max)) {
        desaturate(rotors, yaw_axis, rotor_max * (1.0 + 0.15), 0);
        desaturate(rotors, thrust_axis, rotor_max, 1);
    }
    for (j = 0; j < 4; ++j)
        rotors[j] = py_min(py_max(rotors[j], 0.0), rotor_max);
}

/* QuadrotorFleet.control: PX4 attitude P (3.39) on q_err = q⁻¹ ∘ q_d (fpr_model.rotations.quat_error, (3.28)),
   rate PID (3.40) with the integrator reset while disarmed / frozen while landed / clamped, mixer (3.41). */
static int quad_control(const FprQuadModel *q, double *io, int has_feedforward)
{
    const int n = q->n;
    const double dt = q->controller_period;
    int o[C_COUNT];
    int i, k;
    double bounds[3];
    control_layout(n, o);
    for (k = 0; k < 3; ++k)
        bounds[k] = q->integrator_limit / py_max(q->rate_i[k], 1e-12);
    for (i = 0; i < n; ++i) {
        const double *qa = io + o[C_QUAT] + 4 * i, *qd = io + o[C_CMD_QUAT] + 4 * i;
        const double *rate = io + o[C_RATE] + 3 * i, *previous = io + o[C_PREVIOUS] + 3 * i;
        const double *integral = io + o[C_INTEGRAL] + 3 * i;
        const int armed = io[o[C_ARMED] + i] != 0.0;
        const int on_ground = io[o[C_LANDED] + i] != 0.0;
        double norm2, aw, ax, ay, az, err[4], sign, moments[3], u, f_max;
        double *setpoint = io + o[C_SETPOINT] + 3 * i, *integral_out = io + o[C_INTEGRAL_OUT] + 3 * i;
        double *commands = io + o[C_COMMANDS] + 4 * i;
        for (k = 0; k < 4; ++k)
            if (!isfinite(qa[k]) || !isfinite(qd[k]))
                return FPR_ERR_QUAT; /* fpr_model refuses NaN / inf quaternions */
        norm2 = 0.0;
        norm2 += qa[0] * qa[0];
        norm2 += qa[1] * qa[1];
        norm2 += qa[2] * qa[2];
        norm2 += qa[3] * qa[3];
        if (norm2 <= 0.0)
            return FPR_ERR_QUAT;
        aw = qa[0] * 1.0 / norm2;
        ax = qa[1] * -1.0 / norm2;
        ay = qa[2] * -1.0 / norm2;
        az = qa[3] * -1.0 / norm2;
        err[0] = aw * qd[0] - ax * qd[1] - ay * qd[2] - az * qd[3];
        err[1] = aw * qd[1] + ax * qd[0] + ay * qd[3] - az * qd[2];
        err[2] = aw * qd[2] - ax * qd[3] + ay * qd[0] + az * qd[1];
        err[3] = aw * qd[3] + ax * qd[2] - ay * qd[1] + az * qd[0];
        sign = err[0] >= 0.0 ? 1.0 : -1.0;
        for (k = 0; k < 3; ++k) {
            double sp = 2.0 * q->attitude_p[k] * sign * err[1 + k];
            double error, acc, derivative;
            if (has_feedforward)
                sp += io[o[C_FEEDFORWARD] + 3 * i + k];
            sp = py_min(py_max(sp, -q->max_rate[k]), q->max_rate[k]);
            error = sp - rate[k];
            if (!armed)
                acc = 0.0;
            else if (on_ground)
                acc = integral[k];
            else
                acc = integral[k] + error * dt;
            acc = py_min(py_max(acc, -bounds[k]), bounds[k]);
            derivative = (rate[k] - previous[k]) / dt; /* on the measurement (PX4) */
            setpoint[k] = sp;
            integral_out[k] = acc;
            moments[k] = q->rate_p[k] * error + q->rate_i[k] * acc - q->rate_d[k] * derivative;
        }
        u = io[o[C_THRUST] + i];
        u = (u != u) ? 0.0 : py_min(py_max(u, 0.0), 1.0);
        f_max = io[o[C_FMAX] + i];
        if (armed)
            mix_one(u * f_max, moments, q->arm, q->kappa, 0.25 * f_max, commands);
        else
            commands[0] = commands[1] = commands[2] = commands[3] = 0.0;
    }
    return FPR_OK;
}

/* ------------------------------------------------------------------------------------------- camera frames */

/* One pixel of frame_finish: float32 p -> uint8 as OpenCV's saturate_cast (round half to even, clip to 0-255).
 * Clipping p to [-1, 256] first changes no result and keeps the conversion in range. */
static uint8_t frame_pixel(float p)
{
    p = p < -1.0f ? -1.0f : (p > 256.0f ? 256.0f : p);
    p = rintf(p);  /* the current rounding mode: to nearest, ties to even (never changed by Python) */
    return (uint8_t)(p <= 0.0f ? 0 : (p >= 255.0f ? 255 : (int)p));
}

/* MarkerRenderer.render's last pass (fpr_sim/camera_renderer.py) over a (height, width) uint8 frame, in place:
 *   p = table[I] (float32; NULL: (float)I),  p = p + (row_terms[v] + column_terms[u])  (lighting gradient,
 *   NULL: none),  p = p + noise[v * noise_stride + u]  (sensor noise window, NULL: none),  I' = round(p) in 0-255.
 * The float32 operations of the Python path in its order (cv2.LUT, np.add.outer then +=, cv2.add to CV_8U), so
 * the same bits. SSE2 where the compiler has it (x86-64 always), 16 pixels at a time; the scalar loop otherwise
 * and for the row's tail: the same operations (no FMA contraction: -ffp-contract=off). */
static void frame_finish(int height, int width, uint8_t *image, const float *table, const float *row_terms,
                         const float *column_terms, const float *noise, int noise_stride)
{
    float identity[256];
    if (table == NULL) {
        for (int k = 0; k < 256; ++k)
            identity[k] = (float)k;
        table = identity;
    }
    for (int v = 0; v < height; ++v) {
        uint8_t *row = image + (size_t)v * (size_t)width;
        const float *row_noise = noise != NULL ? noise + (size_t)v * (size_t)noise_stride : NULL;
        const float r = row_terms != NULL ? row_terms[v] : 0.0f;
        int u = 0;
#if defined(__SSE2__)
        const __m128 low = _mm_set1_ps(-1.0f), high = _mm_set1_ps(256.0f), rv = _mm_set1_ps(r);
        for (; u + 16 <= width; u += 16) {
            __m128i quarter[4];
            for (int k = 0; k < 4; ++k) {
                const uint8_t *s = row + u + 4 * k;
                __m128 p = _mm_setr_ps(table[s[0]], table[s[1]], table[s[2]], table[s[3]]);
                if (column_terms != NULL)
                    p = _mm_add_ps(p, _mm_add_ps(rv, _mm_loadu_ps(column_terms + u + 4 * k)));
                if (row_noise != NULL)
                    p = _mm_add_ps(p, _mm_loadu_ps(row_noise + u + 4 * k));
                /* cvtps2dq rounds in the current mode (to nearest, ties to even) like rintf */
                quarter[k] = _mm_cvtps_epi32(_mm_min_ps(_mm_max_ps(p, low), high));
            }
            /* int32 -> int16 -> uint8 with saturation: the clip to 0-255 */
            _mm_storeu_si128((__m128i *)(row + u), _mm_packus_epi16(_mm_packs_epi32(quarter[0], quarter[1]),
                                                                    _mm_packs_epi32(quarter[2], quarter[3])));
        }
#endif
        for (; u < width; ++u) {
            float p = table[row[u]];
            if (column_terms != NULL)
                p = p + (r + column_terms[u]);
            if (row_noise != NULL)
                p = p + row_noise[u];
            row[u] = frame_pixel(p);
        }
    }
}

/* ------------------------------------------------------------------------------------------- exports */

FPR_EXPORT int fpr_kernel_abi(void) { return FPR_KERNEL_ABI; }

FPR_EXPORT int fpr_kernel_max_legs(void) { return FPR_MAX_N; }

FPR_EXPORT const char *fpr_kernel_source_hash(void) { return FPR_KERNEL_SOURCE_HASH; }

/* sizeof the model structs, for the loader's layout check against its ctypes mirrors */
FPR_EXPORT int fpr_kernel_struct_size(int which)
{
    return which == 0 ? (int)sizeof(FprQuadModel) : (int)sizeof(FprPlantModel);
}

/* Offsets of the buffer slots of a call kind for n legs; returns the slot count + 1 (last entry: size). */
FPR_EXPORT int fpr_layout(int kind, int n, int *offsets)
{
    switch (kind) {
    case FPR_LAYOUT_PLANT: return plant_layout(n, offsets);
    case FPR_LAYOUT_CONTROL: return control_layout(n, offsets);
    case FPR_LAYOUT_QUAD: return quad_layout(n, offsets);
    case FPR_LAYOUT_ACCELERATE: return accelerate_layout(n, offsets);
    default: return 0;
    }
}

FPR_EXPORT int fpr_structure_accelerate(int n, const double *basis, double *io)
{
    int o[A_COUNT];
    if (n < 1 || n > FPR_MAX_N)
        return FPR_ERR_SIZE;
    accelerate_layout(n, o);
    return accelerate(n, basis, io + o[A_COS], io + o[A_SIN], io + o[A_XI], io + o[A_GRAVITY], io + o[A_FORCE],
                      io + o[A_OUT]);
}

FPR_EXPORT int fpr_plant_step(const FprPlantModel *m, const double *basis, double *anchors, double *io, double dt,
                              int flags)
{
    if (m->n < 1 || m->n > FPR_MAX_N || m->quad.n != m->n)
        return FPR_ERR_SIZE;
    return plant_step(m, basis, anchors, io, dt, flags);
}

FPR_EXPORT int fpr_quad_control(const FprQuadModel *q, double *io, int has_feedforward)
{
    if (q->n < 1 || q->n > FPR_MAX_N)
        return FPR_ERR_SIZE;
    return quad_control(q, io, has_feedforward);
}

FPR_EXPORT int fpr_frame_finish(int height, int width, uint8_t *image, const float *table, const float *row_terms,
                                const float *column_terms, const float *noise, int noise_stride)
{
    if (height < 1 || width < 1 || (noise != NULL && noise_stride < width))
        return FPR_ERR_SIZE;
    frame_finish(height, width, image, table, row_terms, column_terms, noise, noise_stride);
    return FPR_OK;
}

FPR_EXPORT int fpr_quad_step(const FprQuadModel *q, double *io, double dt, int has_factors)
{
    int o[Q_COUNT];
    if (q->n < 1 || q->n > FPR_MAX_N)
        return FPR_ERR_SIZE;
    quad_layout(q->n, o);
    quad_step(q, io + o[Q_QUAT], io + o[Q_RATE], io + o[Q_ROTORS], io + o[Q_ROTOR_CMD], io + o[Q_MOMENTS],
              io + o[Q_CHARGE], io + o[Q_CURRENT], dt, has_factors ? io + o[Q_FACTOR] : NULL);
    return FPR_OK;
}
