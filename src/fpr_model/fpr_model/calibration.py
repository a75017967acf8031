"""Fixed calibrations of the on-board vision (thesis App. D, Table D.1; §4.2.1 (4.1)-(4.3)) and a pinhole camera.

Homogeneous transforms (4.1): ``A_T_B = [[A_R_B, A_p_B], [0, 0, 0, 1]]`` (4×4 numpy arrays) is the pose of frame
F_B in frame F_A: it maps F_B coordinates to F_A coordinates, ``a = A_T_B @ [b, 1]``. Lengths in metres.

Table D.1 (thesis App. D, spec §3.4) gives, for every UAV, the camera pose in the body frame ``b_T_C`` and the
marker pose in the platform frame ``p_T_M`` as a translation in **cm** and ZXZ Euler angles (ψ1, ϕ, ψ2) in rad.

Frames
------
- Body frame F_b: FLU (x forward, y left, z up), origin at the UAV CoM (DESIGN.md §2).
- Platform frame F_p: z up; leg i anchored at ``r·[cos α_i, sin α_i, 0]`` with α_i = 2π(i−1)/n (erratum E1).
- Camera frame F_C: **OpenCV optical convention**, x right, y down, z forward along the optical axis, origin at
  the optical centre. This is the frame of ``cv2.solvePnP`` and of fpr_msgs/MarkerDetection. Table D.1's camera
  frame *is* this frame: it comes from OpenCV's ChArUco pose ``C_T_Mc`` (D.3).
- Marker frame F_M: OpenCV ArUco convention, origin at the marker centre, x to the right and y up in the marker
  image, z out of the printed face (towards a camera that sees it). Corners TL, TR, BR, BL at
  ``(−L/2, L/2, 0), (L/2, L/2, 0), (L/2, −L/2, 0), (−L/2, −L/2, 0)``.

The Euler-angle convention of Table D.1 (decision, checked numerically)
-----------------------------------------------------------------------
Read as the thesis's intrinsic ZXZ ``R = Rz(ψ1)·Rx(ϕ)·Rz(ψ2)`` (A.44), the camera's optical axis in F_b is
``(0.650, −0.006, 0.760)``: straight ahead, 49° up. But the desired-yaw rule (3.37) with β = 45° puts the
platform at azimuth **−45°** in F_b (front right; the camera is mounted at (8.45, −9.35) cm, i.e. at −48°, on
that side). With that reading the marker under a flat platform falls at or below the bottom edge of a
640×480 / 62°×49° image for leg angles 45°-75° (only 4 of 20 tested poses in view). Read instead as the
**static-axes (extrinsic) ZXZ** ``R = Rz(ψ2)·Rx(ϕ)·Rz(ψ1)`` — the same three numbers composed in the opposite
order, a common ambiguity of Euler-angle tools (e.g. "szxz" vs "rzxz") — the optical axis is
``(0.479, −0.439, 0.760)``: azimuth −42.5°, elevation 49.5°, pointing at the platform. The marker then sits near
the image centre (320, 252) px at θ = 45° and moves right to u ≈ 575 px at θ = 75° (f = 500 px): all three
cameras see it over the whole 45°-75° range with a flat platform (checked in
``fpr_estimation/test/test_calibration.py``). We therefore use the extrinsic reading by default
(``euler_order="extrinsic"``); ``"intrinsic"`` keeps the literal (A.44) reading for comparison.
Erratum E16 (ZXZ from a matrix) is in :func:`fpr_model.rotations.rotmat_to_euler_zxz`.
Note that the marker's ϕ = 3.136 rad is 5.6 mrad from the ZXZ singularity ϕ = π, where only one combination
of ψ1 and ψ2 is well defined: ``Rz(a)·Rx(π)·Rz(b) = Rz(a − b)·Rx(π)``.
So the two readings give the same marker normal (pointing down: the face looks at the UAVs below the platform)
but in-plane angles ψ1 − ψ2 = −1.553 rad and ψ2 − ψ1 = +1.553 rad, i.e. marker yaws that differ by ≈ 178°. This
changes neither visibility nor accuracy; the simulator and the estimator use the same :class:`VisionCalibration`,
so they agree. On a real robot, re-run the calibration of App. D (D.1)-(D.4) rather than trusting either reading.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fpr_model._validation import as_array, as_scalar
from fpr_model.rotations import euler_zxz_to_rotmat, rotmat_to_euler_zxz

__all__ = [
    "TABLE_D1_CAMERA",
    "TABLE_D1_MARKER",
    "aruco_dictionary",
    "CameraModel",
    "EulerZxzPose",
    "VisionCalibration",
    "camera_T_marker_of",
    "compose_transforms",
    "invert_transform",
    "load_vision_calibration",
    "make_transform",
    "transform_points",
]

EULER_ORDERS = ("extrinsic", "intrinsic")


# --------------------------------------------------------------------------------------------------------
# Homogeneous transforms (4.1)-(4.3)
# --------------------------------------------------------------------------------------------------------
def make_transform(rotation, translation) -> np.ndarray:
    """``A_T_B`` of (4.1) from ``A_R_B`` (3×3) and ``A_p_B`` (3,) [m]."""
    R = as_array("rotation", rotation, (3, 3))
    p = as_array("translation", translation, (3,))
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T


def invert_transform(T) -> np.ndarray:
    """``B_T_A = A_T_B^{-1} = [[R^T, −R^T p], [0, 1]]`` (4.3) (exact for a rigid transform)."""
    T = as_array("T", T, (4, 4))
    R = T[:3, :3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def compose_transforms(*transforms) -> np.ndarray:
    """Product ``T1 @ T2 @ ...`` of homogeneous transforms, e.g. ``p_T_b = p_T_M · M_T_C · C_T_b`` (4.2)."""
    out = np.eye(4)
    for index, T in enumerate(transforms):
        out = out @ as_array(f"transforms[{index}]", T, (4, 4))
    return out


def camera_T_marker_of(platform_T_body, body_T_camera, platform_T_marker) -> np.ndarray:
    """``C_T_M = (b_T_C)⁻¹ (p_T_b)⁻¹ p_T_M``: the marker pose a camera mounted at ``b_T_C`` on a UAV at ``p_T_b``
    sees; the inverse of (4.2) (the estimator's ``p_T_b = p_T_M · M_T_C · C_T_b``). 4×4, m."""
    return invert_transform(body_T_camera) @ invert_transform(platform_T_body) @ platform_T_marker


def transform_points(T, points) -> np.ndarray:
    """Apply ``A_T_B`` to points (..., 3) given in F_B; returns them in F_A."""
    T = as_array("T", T, (4, 4))
    points = np.asarray(points, dtype=float)
    return points @ T[:3, :3].T + T[:3, 3]


# --------------------------------------------------------------------------------------------------------
# Table D.1
# --------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EulerZxzPose:
    """A fixed pose as in Table D.1: translation [cm] and ZXZ Euler angles (ψ1, ϕ, ψ2) [rad].

    ``euler_order``: "extrinsic" (default, R = Rz(ψ2)·Rx(ϕ)·Rz(ψ1), see the module docstring) or "intrinsic"
    (R = Rz(ψ1)·Rx(ϕ)·Rz(ψ2), (A.44)).
    """

    translation_cm: tuple[float, float, float]
    euler_zxz: tuple[float, float, float]
    euler_order: str = "extrinsic"

    def __post_init__(self) -> None:
        as_array("translation_cm", self.translation_cm, (3,))
        as_array("euler_zxz", self.euler_zxz, (3,))
        if self.euler_order not in EULER_ORDERS:
            raise ValueError(f"euler_order: expected one of {EULER_ORDERS}, got {self.euler_order!r}")

    @property
    def rotation(self) -> np.ndarray:
        psi1, phi, psi2 = (float(a) for a in self.euler_zxz)
        if self.euler_order == "extrinsic":
            return euler_zxz_to_rotmat(psi2, phi, psi1)
        return euler_zxz_to_rotmat(psi1, phi, psi2)

    @property
    def translation(self) -> np.ndarray:
        """Translation in metres."""
        return np.asarray(self.translation_cm, dtype=float) / 100.0

    @property
    def transform(self) -> np.ndarray:
        """The 4×4 homogeneous transform (4.1), translation in metres."""
        return make_transform(self.rotation, self.translation)

    @staticmethod
    def from_transform(T, euler_order: str = "extrinsic") -> EulerZxzPose:
        """Inverse of :attr:`transform` (erratum E16 formulas; exact away from ϕ ∈ {0, π})."""
        T = as_array("T", T, (4, 4))
        psi1, phi, psi2 = rotmat_to_euler_zxz(T[:3, :3])
        if euler_order == "extrinsic":
            psi1, psi2 = psi2, psi1
        translation = tuple(float(x) * 100.0 for x in T[:3, 3])
        return EulerZxzPose(translation, (psi1, phi, psi2), euler_order)  # type: ignore[arg-type]


#: Table D.1, camera pose b_T_C (same for every UAV).
TABLE_D1_CAMERA = EulerZxzPose((8.45, -9.35, 0.79), (1.561, 0.708, 0.829))
#: Table D.1, marker pose p_T_M.
TABLE_D1_MARKER = EulerZxzPose((-0.83, 0.26, -2.47), (-0.716, 3.136, 0.837))


# --------------------------------------------------------------------------------------------------------
# Pinhole camera
# --------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CameraModel:
    """Pinhole camera with OpenCV's distortion model (k1, k2, p1, p2, k3), pixel units.

    Defaults: a Raspberry Pi Camera V2-like sensor in a 640×480 mode, as on the thesis prototype (§4.4):
    f = 500 px, principal point at the image centre, no distortion (set ``distortion`` to use OpenCV's model,
    e.g. from a calibration). The V2's nominal field of view is 62.2° × 48.8° (IMX219, 3.04 mm lens), i.e.
    f ≈ 530 px at 640×480; 500 px (65° × 51°) is within calibration spread of such modules and keeps the
    marker's corners inside the image up to θ = 75° with a flat platform (with 530 px one corner leaves the
    image by ~1 px at θ = 75°; the marker centre stays at u ≈ 590 px).
    """

    width: int = 640
    height: int = 480
    fx: float = 500.0
    fy: float = 500.0
    cx: float = 320.0
    cy: float = 240.0
    distortion: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ValueError(f"camera size must be positive, got {self.width}×{self.height}")
        for name in ("fx", "fy"):
            if as_scalar(name, getattr(self, name)) <= 0.0:
                raise ValueError(f"{name}: must be positive")
        as_scalar("cx", self.cx)
        as_scalar("cy", self.cy)
        d = np.asarray(self.distortion, dtype=float)
        if d.ndim != 1 or d.size not in (4, 5, 8, 12, 14) or not np.isfinite(d).all():
            raise ValueError(f"distortion: expected 4, 5, 8, 12 or 14 finite coefficients, got {self.distortion}")

    @property
    def camera_matrix(self) -> np.ndarray:
        """The 3×3 intrinsic matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        return np.asarray(self.distortion, dtype=float)

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist_coeffs != 0.0))

    @staticmethod
    def from_camera_info(width: int, height: int, k, d) -> CameraModel:
        """From sensor_msgs/CameraInfo fields (``k`` row-major 3×3, ``d`` the plumb_bob coefficients)."""
        K = np.asarray(k, dtype=float).reshape(3, 3)
        dist = tuple(float(x) for x in d) if len(d) else (0.0,) * 5
        return CameraModel(int(width), int(height), K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist)

    def project(self, points_camera) -> np.ndarray:
        """Pixel coordinates (N, 2) of points (N, 3) in the camera frame (with distortion). z must be > 0."""
        import cv2  # local: fpr_model does not otherwise need OpenCV

        pts = np.asarray(points_camera, dtype=float).reshape(-1, 3)
        uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), self.camera_matrix, self.dist_coeffs)
        return uv.reshape(-1, 2)


@dataclass(frozen=True)
class VisionCalibration:
    """Everything fixed about one UAV's vision: camera pose b_T_C, marker pose p_T_M, intrinsics, marker size."""

    camera_pose: EulerZxzPose = TABLE_D1_CAMERA
    marker_pose: EulerZxzPose = TABLE_D1_MARKER
    camera: CameraModel = field(default_factory=CameraModel)
    marker_size: float = 0.109

    @property
    def body_T_camera(self) -> np.ndarray:
        """b_T_C (4.2)."""
        return self.camera_pose.transform

    @property
    def platform_T_marker(self) -> np.ndarray:
        """p_T_M (4.2)."""
        return self.marker_pose.transform


def _pose_from_dict(data: dict, default: EulerZxzPose, euler_order: str) -> EulerZxzPose:
    translation = data.get("translation_cm", default.translation_cm)
    euler = data.get("euler_zxz", default.euler_zxz)
    return EulerZxzPose(tuple(float(x) for x in translation), tuple(float(x) for x in euler),  # type: ignore
                        str(data.get("euler_order", euler_order)))


def load_vision_calibration(source: str | Path | dict | None = None) -> VisionCalibration:
    """Build a :class:`VisionCalibration` from a YAML file path or an already-parsed dict.

    Keys (all optional; missing ones take the Table D.1 / Pi Camera V2 defaults)::

        euler_order: extrinsic            # or intrinsic, applies to both poses unless given per pose
        camera_pose: {translation_cm: [8.45, -9.35, 0.79], euler_zxz: [1.561, 0.708, 0.829]}
        marker_pose: {translation_cm: [-0.83, 0.26, -2.47], euler_zxz: [-0.716, 3.136, 0.837]}
        camera: {width: 640, height: 480, fx: 500, fy: 500, cx: 320, cy: 240, distortion: [0, 0, 0, 0, 0]}
        marker_size: 0.109

    A ROS-parameter style file (``node: {ros__parameters: {...}}``) is accepted too: the first mapping that
    has a ``ros__parameters`` key is used.
    """
    if source is None:
        data: dict = {}
    elif isinstance(source, dict):
        data = source
    else:
        import yaml

        with open(source, encoding="utf-8") as stream:
            data = yaml.safe_load(stream) or {}
    for value in list(data.values()):
        if isinstance(value, dict) and "ros__parameters" in value:
            data = value["ros__parameters"]
            break
    euler_order = str(data.get("euler_order", "extrinsic"))
    camera_data = data.get("camera", {}) or {}
    default_camera = CameraModel()
    camera = CameraModel(
        int(camera_data.get("width", default_camera.width)),
        int(camera_data.get("height", default_camera.height)),
        float(camera_data.get("fx", default_camera.fx)),
        float(camera_data.get("fy", default_camera.fy)),
        float(camera_data.get("cx", default_camera.cx)),
        float(camera_data.get("cy", default_camera.cy)),
        tuple(float(x) for x in camera_data.get("distortion", default_camera.distortion)),
    )
    return VisionCalibration(
        _pose_from_dict(data.get("camera_pose", {}) or {}, TABLE_D1_CAMERA, euler_order),
        _pose_from_dict(data.get("marker_pose", {}) or {}, TABLE_D1_MARKER, euler_order),
        camera,
        float(data.get("marker_size", 0.109)),
    )


def aruco_dictionary(name: str):
    """OpenCV predefined ArUco dictionary by its cv2.aruco constant name, e.g. "DICT_ARUCO_MIP_36H12".

    Shared by the marker detector (fpr_estimation) and the simulator's marker renderer (fpr_sim) so that both
    always agree on the dictionary. Raises ValueError naming the dictionary when OpenCV does not know it.
    """
    import cv2  # local: fpr_model does not otherwise need OpenCV

    for key in (name, name.upper()):
        if key.startswith("DICT_") and isinstance(getattr(cv2.aruco, key, None), int):
            return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, key))
    raise ValueError(f"unknown ArUco dictionary {name!r}")
