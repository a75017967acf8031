"""Constant parameters of a Flying Parallel Robot: the immutable model object of ``fpr_model``.

Pinocchio style (DESIGN.md §8): :class:`FprParameters` holds the constants; the algorithms are free
functions (``mass_matrix(params, q)``, ...). Defaults are thesis Table B.1 (spec §3.2).

Frames and reference points (spec §0.1, thesis §2.2):

- ``Fp``: platform frame at the platform point P (the centre of the revolute-joint circle).
- ``F_li``: leg frame at the revolute-joint centre A_i; z = joint axis, x along the leg from A_i to the tip
  B_i.

Inertia reference points (Table B.1 does not state them, spec §5 open question 4). Choice made here:

- ``leg_inertia`` I_l is about the joint origin A_i, in F_li (thesis (2.40)-(2.41) use ``li I_Oi`` "expressed
  at the origin of its frame"; I_l,yy = 0.035 > m_l·0.599² = 0.0237 is consistent with that). The quadrotor i
  is a point mass m_b,i at the tip: the composite leg has mass m_l + m_b,i, first moment
  m_l·s_l + m_b,i·l·e_x and inertia I_l + m_b,i·diag(0, l², l²) about A_i (thesis (2.36)-(2.37),
  (2.41)-(2.42)).
- ``platform_inertia`` I_p is taken about the platform frame origin P, in Fp. The thesis uses ``p I_Op`` "the
  moment of inertia expressed at the origin of the platform frame Fp" directly with the first moment
  m_p·s_p in (2.43) and (2.51), without any parallel-axis shift, so the Table B.1 value enters the model as an
  inertia about P. (Physically the Table B.1 value matches a triangle plate about its own centroid; the
  difference, m_p·|s_p|² = 2.5e-5 kg·m² on the x and y axes, is 5 % of I_p,xx and is ignored, as in the
  thesis.)

Units: SI (m, kg, kg·m², rad, m/s²).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "TABLE_B1_UAV_MASSES",
    "FprParameters",
    "LegMassProperties",
    "default_parameters",
    "leg_mass_properties",
    "load_parameters",
    "parameters_from_dict",
    "parameters_to_dict",
]

#: Quadrotor masses of the prototype, thesis Table B.1 [kg].
TABLE_B1_UAV_MASSES = (1.007, 1.028, 1.018)


def _field_error(name: str, message: str) -> ValueError:
    return ValueError(f"FprParameters.{name}: {message}")


def _finite_scalar(name: str, value: Any) -> float:
    if isinstance(value, bool):
        raise _field_error(name, f"expected a real number, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise _field_error(name, f"expected a real number, got {value!r}") from None
    if not math.isfinite(number):
        raise _field_error(name, f"must be finite, got {number}")
    return number


def _positive(name: str, value: Any) -> float:
    number = _finite_scalar(name, value)
    if number <= 0.0:
        raise _field_error(name, f"must be > 0, got {number}")
    return number


def _finite_array(name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise _field_error(name, f"expected numbers of shape {shape}, got {value!r}") from None
    if array.shape != shape:
        raise _field_error(name, f"expected shape {shape}, got {array.shape}")
    if not np.isfinite(array).all():
        raise _field_error(name, "contains NaN or inf")
    array.setflags(write=False)
    return array


def _inertia(name: str, value: Any) -> np.ndarray:
    """Accept 3 diagonal values, 9 row-major values or a 3×3 matrix; require symmetric positive definite."""
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise _field_error(name, f"expected 3 diagonal values or a 3x3 matrix, got {value!r}") from None
    if array.shape == (3,):
        array = np.diag(array)
    elif array.shape == (9,):
        array = array.reshape(3, 3)
    if array.shape != (3, 3):
        raise _field_error(name, f"expected 3 diagonal values, 9 values or a 3x3 matrix, got {array.shape}")
    if not np.isfinite(array).all():
        raise _field_error(name, "contains NaN or inf")
    scale = max(float(np.abs(array).max()), 1e-300)
    if np.abs(array - array.T).max() > 1e-12 * scale:
        raise _field_error(name, "inertia matrix must be symmetric")
    array = 0.5 * (array + array.T)
    if np.linalg.eigvalsh(array).min() <= 0.0:
        raise _field_error(name, "inertia matrix must be positive definite")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class FprParameters:
    """Immutable constants of an n-leg FPR (thesis Table B.1 names in brackets). SI units.

    Attributes:
        n: number of legs = number of quadrotors, n >= 3.
        platform_radius: r, distance P -> A_i (revolute-joint centre) [m].
        leg_length: l, distance A_i -> B_i (quadrotor CoM / spherical joint) [m].
        joint_offset: d, spherical-joint offset from the quadrotor CoM in its x-y plane [m] (neglected by the
            model, d = 0 in the dynamics, thesis §2.3.3; used by the simulator and the setpoint yaw rule).
        joint_offset_angle: β [rad]: x_bi lies at +β about z_bi from the direction B_iS_i of the joint, i.e.
            B_iS_i = d·Rz(−β)·e_x in Fbi; the desired-x rule (3.37) (spec §1.7) puts x_bi at +β from the
            horizontal −l_i, so the joint faces the leg.
        platform_mass: m_p [kg].
        leg_mass: m_l, one leg without its quadrotor [kg].
        platform_com: s_p, platform CoM in Fp [m], shape (3,).
        leg_com: s_l, leg CoM in F_li [m], shape (3,).
        platform_inertia: I_p about P, in Fp [kg·m²], (3, 3) (see module docstring).
        leg_inertia: I_l about A_i, in F_li [kg·m²], (3, 3), without the quadrotor.
        uav_masses: m_b,i, shape (n,) [kg].
        gravity: g >= 0 [m/s²]; gravity vector in the world (ENU) frame is [0, 0, −g].

    Arrays are stored read-only. Two parameter objects are equal when all fields are equal.
    """

    n: int
    platform_radius: float
    leg_length: float
    joint_offset: float
    joint_offset_angle: float
    platform_mass: float
    leg_mass: float
    platform_com: np.ndarray
    leg_com: np.ndarray
    platform_inertia: np.ndarray
    leg_inertia: np.ndarray
    uav_masses: np.ndarray
    gravity: float = 9.81
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if isinstance(self.n, bool) or not isinstance(self.n, (int, np.integer)):
            if not (isinstance(self.n, float) and self.n.is_integer()):
                raise _field_error("n", f"expected an integer, got {self.n!r}")
        n = int(self.n)
        if n < 3:
            raise _field_error("n", f"needs at least 3 legs (fewer cannot control the platform), got {n}")
        set_(self, "n", n)
        set_(self, "platform_radius", _positive("platform_radius", self.platform_radius))
        set_(self, "leg_length", _positive("leg_length", self.leg_length))
        joint_offset = _finite_scalar("joint_offset", self.joint_offset)
        if joint_offset < 0.0:
            raise _field_error("joint_offset", f"must be >= 0, got {joint_offset}")
        set_(self, "joint_offset", joint_offset)
        set_(self, "joint_offset_angle", _finite_scalar("joint_offset_angle", self.joint_offset_angle))
        set_(self, "platform_mass", _positive("platform_mass", self.platform_mass))
        set_(self, "leg_mass", _positive("leg_mass", self.leg_mass))
        set_(self, "platform_com", _finite_array("platform_com", self.platform_com, (3,)))
        set_(self, "leg_com", _finite_array("leg_com", self.leg_com, (3,)))
        set_(self, "platform_inertia", _inertia("platform_inertia", self.platform_inertia))
        set_(self, "leg_inertia", _inertia("leg_inertia", self.leg_inertia))
        masses = np.array(self.uav_masses, dtype=float) if np.ndim(self.uav_masses) else None
        if masses is None or masses.shape != (n,):
            raise _field_error("uav_masses", f"expected {n} values (one per leg), got {self.uav_masses!r}")
        if not np.isfinite(masses).all():
            raise _field_error("uav_masses", "contains NaN or inf")
        if (masses <= 0.0).any():
            raise _field_error("uav_masses", f"every mass must be > 0, got {masses.tolist()}")
        masses.setflags(write=False)
        set_(self, "uav_masses", masses)
        gravity = _finite_scalar("gravity", self.gravity)
        if gravity < 0.0:
            raise _field_error("gravity", f"must be >= 0, got {gravity}")
        set_(self, "gravity", gravity)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, FprParameters):
            return NotImplemented
        return all(
            np.array_equal(getattr(self, f.name), getattr(other, f.name))
            for f in dataclasses.fields(self)
            if f.compare
        )

    def __hash__(self) -> int:
        return hash((self.n, self.platform_radius, self.leg_length, self.platform_mass,
                     self.uav_masses.tobytes()))

    @property
    def total_mass(self) -> float:
        """m_tot = m_p + Σ (m_l + m_b,i) (thesis (2.89)) [kg]."""
        return self.platform_mass + self.n * self.leg_mass + float(np.sum(self.uav_masses))

    @property
    def gravity_vector(self) -> np.ndarray:
        """Gravity vector in the world frame, [0, 0, −g] [m/s²]."""
        return np.array([0.0, 0.0, -self.gravity])


class LegMassProperties(NamedTuple):
    """Composite mass properties of leg + quadrotor point mass, in F_li about A_i (thesis (2.36)-(2.42))."""

    masses: np.ndarray  #: (n,) m_i = m_l + m_b,i [kg]
    first_moments: np.ndarray  #: (n, 3) ms_i = m_l·s_l + m_b,i·l·e_x [kg·m]
    inertias: np.ndarray  #: (n, 3, 3) I_l + m_b,i·diag(0, l², l²) [kg·m²]


def leg_mass_properties(params: FprParameters) -> LegMassProperties:
    """Composite leg i (leg + quadrotor as a point mass at the tip B_i) in F_li about A_i, (2.36)-(2.42)."""
    mb = params.uav_masses
    l2 = params.leg_length**2
    masses = params.leg_mass + mb
    first = params.leg_mass * params.leg_com[None, :] + np.outer(mb, [params.leg_length, 0.0, 0.0])
    inertias = params.leg_inertia[None, :, :] + mb[:, None, None] * np.diag([0.0, l2, l2])[None, :, :]
    return LegMassProperties(masses, first, inertias)


def default_parameters(n: int = 3) -> FprParameters:
    """Thesis Table B.1 prototype. For n != 3 every quadrotor gets the mean Table B.1 mass (1.01767 kg)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise ValueError(f"n: expected an integer, got {n!r}")
    mean_mass = float(np.mean(TABLE_B1_UAV_MASSES))
    uav_masses = list(TABLE_B1_UAV_MASSES) if n == 3 else [mean_mass] * max(int(n), 0)
    return FprParameters(
        n=int(n),
        platform_radius=0.127,
        leg_length=1.043,
        joint_offset=0.069,
        joint_offset_angle=math.radians(45.0),
        platform_mass=0.250,
        leg_mass=0.066,
        platform_com=np.array([0.0, 0.0, 0.010]),
        leg_com=np.array([0.599, 0.0, 0.0]),
        platform_inertia=np.diag([5.4e-4, 5.4e-4, 1.0e-3]),
        leg_inertia=np.diag([1.6e-6, 0.035, 0.035]),
        uav_masses=np.array(uav_masses),
        gravity=9.81,
    )


_FIELD_NAMES = (
    "n",
    "platform_radius",
    "leg_length",
    "joint_offset",
    "joint_offset_angle",
    "platform_mass",
    "leg_mass",
    "platform_com",
    "leg_com",
    "platform_inertia",
    "leg_inertia",
    "uav_masses",
    "gravity",
)


def parameters_from_dict(d: dict, base: FprParameters | None = None) -> FprParameters:
    """Build parameters from a mapping of field names (see :class:`FprParameters`).

    Missing fields come from ``base`` (default: :func:`default_parameters` for the given ``n``; when ``n``
    changes and ``uav_masses`` is not given, the base's mean quadrotor mass is used for every leg).
    Unknown keys are refused with a ValueError listing the valid names. A ROS 2 parameter file layout
    ``{<node or /**>: {ros__parameters: {...}}}`` is unwrapped. Inertias may be 3 diagonal values, 9 row-major
    values or a 3×3 nested list.
    """
    if not isinstance(d, dict):
        raise ValueError(f"parameters: expected a mapping, got {type(d).__name__}")
    if len(d) == 1:
        (inner,) = d.values()
        if isinstance(inner, dict) and "ros__parameters" in inner:
            d = inner["ros__parameters"]
    if isinstance(d, dict) and set(d) == {"ros__parameters"}:
        d = d["ros__parameters"]
    unknown = sorted(set(d) - set(_FIELD_NAMES))
    if unknown:
        raise ValueError(f"parameters: unknown key(s) {unknown}; valid keys are {list(_FIELD_NAMES)}")
    n = d.get("n", base.n if base is not None else 3)
    if base is None:
        if isinstance(n, bool) or not isinstance(n, (int, float)) or not float(n).is_integer():
            raise _field_error("n", f"expected an integer, got {n!r}")
        base = default_parameters(max(int(n), 3))
    values = {name: getattr(base, name) for name in _FIELD_NAMES}
    if "n" in d and "uav_masses" not in d and int(n) != base.n:
        values["uav_masses"] = np.full(max(int(n), 0), float(np.mean(base.uav_masses)))
    values.update(d)
    return FprParameters(**values)


def parameters_to_dict(params: FprParameters) -> dict:
    """Plain-Python mapping of the fields (inertias as 9 row-major values: ROS-parameter friendly)."""
    out: dict[str, Any] = {}
    for name in _FIELD_NAMES:
        value = getattr(params, name)
        if isinstance(value, np.ndarray):
            value = value.reshape(-1).tolist()
        out[name] = value
    return out


def load_parameters(path: str) -> FprParameters:
    """Load parameters from a YAML file (see ``config/fpr_parameters.yaml``); see
    :func:`parameters_from_dict`."""
    import yaml

    with open(path, encoding="utf-8") as stream:
        data = yaml.safe_load(stream)
    if data is None:
        data = {}
    return parameters_from_dict(data)
