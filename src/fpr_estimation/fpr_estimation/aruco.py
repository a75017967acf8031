"""ArUco marker detection and planar pose (thesis §4.2.1): the marker pose ``C_T_M`` in the camera frame. ROS-free.

Camera frame: OpenCV optical (x right, y down, z forward); marker frame: OpenCV ArUco (origin at the centre, z out
of the face). Units: metres, radians, pixels.

Pose: ``cv2.solvePnPGeneric(..., SOLVEPNP_IPPE_SQUARE)`` returns both solutions of the planar (IPPE) problem with
their reprojection errors. The two differ by a reflection of the marker's tilt; at long range or small tilt they
are nearly equally good (the planar ambiguity that makes ArUco poses "flip"). We keep the solution closest in
rotation to the previous accepted pose when there is one and the ambiguity ratio is below
``ambiguity_threshold`` (the image cannot tell them apart), otherwise the one with the lower reprojection
error. ``ambiguity_ratio`` = error of the rejected solution / error of the chosen one (≫ 1: unambiguous).

Region of interest (``roi_margin`` > 0, the default): after a detection, the next frame is searched first in the
last marker's bounding box grown by ``roi_margin`` of its size plus ``roi_border`` px on every side (clipped to the
image), and the whole frame only when the marker is not found there. The marker moves little between two frames
at 20 Hz, so most frames cost the crop's search: 0.3-0.6 ms against 1.9-3.9 ms for a 640×480 frame, with the
same corners (the quad search and AprilTag refinement are local: within 3e-5 px on the simulator's noisy frames;
benchmarks/bench_estimation.py). Onboard, that is CPU the camera's rate could use.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from fpr_model.calibration import CameraModel, aruco_dictionary, make_transform

__all__ = [
    "ArucoConfig", "ArucoPoseDetector", "MarkerObservation", "aruco_dictionary", "decode_image", "validate_mono_image",
]

CORNER_REFINEMENT = {
    "none": cv2.aruco.CORNER_REFINE_NONE,
    "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
    "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
    "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG,
}


#: Pixel-centre convention offset of the AprilTag corner refinement (see ArucoPoseDetector.detect) [px].
APRILTAG_CORNER_OFFSET_PX = 0.5


@dataclass(frozen=True)
class ArucoConfig:
    """Detector configuration (YAML: config/aruco_detector.yaml)."""

    dictionary: str = "DICT_ARUCO_MIP_36H12"
    marker_id: int = 0
    marker_size: float = 0.109  #: black-square side [m]
    corner_refinement: str = "apriltag"  #: none | subpix | contour | apriltag (most accurate on 40-80 px markers)
    corner_refinement_win_size: int = 5
    corner_refinement_max_iterations: int = 30
    corner_refinement_min_accuracy: float = 0.01
    adaptive_thresh_win_size_min: int = 3
    adaptive_thresh_win_size_max: int = 23
    adaptive_thresh_win_size_step: int = 10
    min_marker_perimeter_rate: float = 0.03
    #: AprilTag quad detector (corner_refinement apriltag): minimum white-black intensity difference [grey levels].
    #: OpenCV's default 5 makes the quad search chase sensor noise (85-90 ms per noisy 640x480 frame at pixel noise
    #: sigma 2, vs 1.7 ms at 30, same corner accuracy; measured in the speed issue): 30 keeps real edges only.
    april_tag_min_white_black_diff: int = 30
    ambiguity_threshold: float = 2.0  #: below this ratio, prefer the solution consistent with the previous pose
    #: region of interest (module doc): the last marker's bounding box grown by this fraction of its larger side on
    #: every side; 0: every frame is searched whole
    roi_margin: float = 0.5
    roi_border: int = 16  #: [px] added to the region of interest's margin on every side
    #: frames without the marker the last region of interest is still searched first (then the whole frame);
    #: 0: forgotten at the first frame without the marker
    roi_hold: int = 10

    def __post_init__(self) -> None:
        if self.corner_refinement not in CORNER_REFINEMENT:
            raise ValueError(f"corner_refinement: expected one of {sorted(CORNER_REFINEMENT)}")
        if not self.marker_size > 0.0:
            raise ValueError("marker_size must be positive")
        if not 0.0 <= self.roi_margin <= 10.0 or not 0 <= self.roi_border <= 10000:
            raise ValueError(f"roi_margin must be in [0, 10] and roi_border in [0, 10000] px, got {self.roi_margin}, "
                             f"{self.roi_border}")
        if not 0 <= self.roi_hold <= 1000:
            raise ValueError(f"roi_hold must be in [0, 1000] frames, got {self.roi_hold}")


@dataclass
class MarkerObservation:
    """One detection: ``C_T_M`` and its quality.

    camera_T_marker: 4×4 pose of the marker in the camera frame [m].
    corners: (4, 2) detected corners TL, TR, BR, BL [px].
    reprojection_error: RMS over the 4 corners of the chosen solution [px].
    ambiguity_ratio: reprojection error of the other IPPE solution / chosen one (inf if only one solution).
    """

    marker_id: int
    camera_T_marker: np.ndarray
    corners: np.ndarray
    reprojection_error: float
    ambiguity_ratio: float
    rvec: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(3))
    tvec: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(3))


def validate_mono_image(image) -> np.ndarray:
    """Return ``image`` as a 2-D uint8 array or raise ValueError with a reason (empty, wrong dtype/shape)."""
    if image is None:
        raise ValueError("no image")
    image = np.asarray(image)
    if image.size == 0:
        raise ValueError("empty image")
    if image.dtype != np.uint8:
        raise ValueError(f"expected uint8 pixels, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim != 2:
        raise ValueError(f"expected a single-channel image, got shape {image.shape}")
    if min(image.shape) < 8:
        raise ValueError(f"image too small: {image.shape}")
    return image


def _rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    cos = 0.5 * (np.trace(Ra.T @ Rb) - 1.0)
    return float(np.arccos(np.clip(cos, -1.0, 1.0)))


class ArucoPoseDetector:
    """Detects one marker id and estimates its pose; remembers the last pose for the ambiguity choice."""

    def __init__(self, config: ArucoConfig | None = None) -> None:
        self.config = config if config is not None else ArucoConfig()
        c = self.config
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = CORNER_REFINEMENT[c.corner_refinement]
        params.cornerRefinementWinSize = int(c.corner_refinement_win_size)
        params.cornerRefinementMaxIterations = int(c.corner_refinement_max_iterations)
        params.cornerRefinementMinAccuracy = float(c.corner_refinement_min_accuracy)
        params.adaptiveThreshWinSizeMin = int(c.adaptive_thresh_win_size_min)
        params.adaptiveThreshWinSizeMax = int(c.adaptive_thresh_win_size_max)
        params.adaptiveThreshWinSizeStep = int(c.adaptive_thresh_win_size_step)
        params.minMarkerPerimeterRate = float(c.min_marker_perimeter_rate)
        params.aprilTagMinWhiteBlackDiff = int(c.april_tag_min_white_black_diff)
        self._detector = cv2.aruco.ArucoDetector(aruco_dictionary(c.dictionary), params)
        half = 0.5 * c.marker_size
        #: Object points in ArUco corner order TL, TR, BR, BL (what SOLVEPNP_IPPE_SQUARE expects).
        self.object_points = np.array([[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0],
                                       [-half, -half, 0.0]])
        self.previous_rotation: np.ndarray | None = None
        #: (x0, y0, x1, y1) [px] where the next frame is searched first (module doc); None: the whole frame
        self.roi: tuple[int, int, int, int] | None = None
        self.roi_hits = 0    #: frames whose marker was found in the region of interest
        self.roi_misses = 0  #: frames searched whole after the region of interest came up empty
        self.frames_without_marker = 0  #: consecutive frames in which the marker was not found (roi_hold)

    def reset(self) -> None:
        """Forget the previous pose and region of interest (e.g. after a long loss of the marker)."""
        self.previous_rotation = None
        self.roi = None
        self.frames_without_marker = 0

    def _find(self, image: np.ndarray) -> np.ndarray | None:
        """The configured marker's raw corners in ``image`` (4, 2) [px, OpenCV's convention], or None."""
        corners_list, ids, _ = self._detector.detectMarkers(image)
        if ids is None or len(ids) == 0:
            return None
        matches = [k for k, marker_id in enumerate(ids.ravel()) if int(marker_id) == self.config.marker_id]
        if not matches:
            return None
        # Several candidates with the same id: take the largest (closest / most accurate).
        return max((corners_list[k].reshape(4, 2) for k in matches),
                   key=lambda c: cv2.contourArea(c.astype(np.float32))).astype(np.float64)

    def _region_around(self, corners: np.ndarray, shape: tuple[int, int]) -> tuple[int, int, int, int] | None:
        """The region of interest of the module doc around raw ``corners``, clipped to an image of ``shape``."""
        low, high = corners.min(axis=0), corners.max(axis=0)
        grow = self.config.roi_margin * float(np.max(high - low)) + self.config.roi_border
        x0, y0 = (max(0, int(np.floor(v - grow))) for v in low)
        x1, y1 = min(shape[1], int(np.ceil(high[0] + grow))), min(shape[0], int(np.ceil(high[1] + grow)))
        return (x0, y0, x1, y1) if x1 - x0 >= 8 and y1 - y0 >= 8 else None

    def detect(self, image, camera: CameraModel) -> MarkerObservation | None:
        """Detect the configured marker in a mono8 image; None if it is not found. With ``roi_margin`` > 0 the
        last detection's region of interest is searched first, also for ``roi_hold`` frames after it was last
        found (module doc).

        Raises ValueError for an unusable image (see :func:`validate_mono_image`).
        """
        image = validate_mono_image(image)
        corners = None
        if self.roi is not None:
            x0, y0, x1, y1 = self.roi
            crop = image[y0:y1, x0:x1]  # a smaller next frame clips it
            corners = self._find(crop) if min(crop.shape) >= 8 else None
            if corners is not None:
                corners += (x0, y0)  # crop -> frame pixels
                self.roi_hits += 1
            else:
                self.roi_misses += 1
        if corners is None:
            corners = self._find(image)
        if corners is None:
            self.frames_without_marker += 1
            if self.frames_without_marker > self.config.roi_hold:
                self.roi = None
            return None
        self.frames_without_marker = 0
        self.roi = self._region_around(corners, image.shape) if self.config.roi_margin > 0.0 else None
        if self.config.corner_refinement == "apriltag":
            # OpenCV's AprilTag refinement reports corners with pixel centres at (0.5, 0.5) instead of (0, 0)
            # (AprilRobotics/apriltag#121): measured +0.43 px on both axes against projectPoints of the true
            # corners on rendered images; shifting back halves the median position error (1.35 -> 0.6 mm).
            corners -= APRILTAG_CORNER_OFFSET_PX
        return self.estimate_pose(corners, camera)

    def estimate_pose(self, corners: np.ndarray, camera: CameraModel) -> MarkerObservation | None:
        """IPPE_SQUARE pose from 4 corners (TL, TR, BR, BL) with the ambiguity resolution of the module doc."""
        image_points = np.ascontiguousarray(corners, dtype=np.float64).reshape(4, 1, 2)
        count, rvecs, tvecs, errors = cv2.solvePnPGeneric(
            self.object_points, image_points, camera.camera_matrix, camera.dist_coeffs,
            flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if count == 0:
            return None
        errors = np.asarray(errors, dtype=float).ravel() if errors is not None else np.zeros(count)
        candidates = []
        for k in range(count):
            R, _ = cv2.Rodrigues(rvecs[k])
            t = np.asarray(tvecs[k], dtype=float).ravel()
            if t[2] <= 0.0 or not np.isfinite(R).all() or not np.isfinite(t).all():
                continue
            candidates.append((float(errors[k]), R, t, np.asarray(rvecs[k], dtype=float).ravel()))
        if not candidates:
            return None
        candidates.sort(key=lambda c: c[0])
        chosen = candidates[0]
        ratio = float("inf")
        if len(candidates) > 1:
            other = candidates[1]
            ratio = other[0] / max(chosen[0], 1e-9)
            if self.previous_rotation is not None and ratio < self.config.ambiguity_threshold:
                if (_rotation_angle(self.previous_rotation, other[1])
                        < _rotation_angle(self.previous_rotation, chosen[1])):
                    chosen, other = other, chosen
                    ratio = other[0] / max(chosen[0], 1e-9)
        error, R, t, rvec = chosen
        self.previous_rotation = R
        return MarkerObservation(self.config.marker_id, make_transform(R, t), corners.reshape(4, 2).copy(),
                                 float(error), float(ratio), rvec, t.copy())


#: sensor_msgs/Image encodings the detector accepts (colour is converted to grey).
SUPPORTED_ENCODINGS = ("mono8", "8UC1", "bgr8", "rgb8", "bgra8", "rgba8")


def decode_image(encoding: str, width: int, height: int, step: int, data) -> np.ndarray:
    """Turn sensor_msgs/Image fields into a mono8 array; raise ValueError with a reason for bad input."""
    if encoding not in SUPPORTED_ENCODINGS:
        raise ValueError(f"unsupported encoding {encoding!r} (supported: {', '.join(SUPPORTED_ENCODINGS)})")
    channels = {"mono8": 1, "8UC1": 1, "bgr8": 3, "rgb8": 3, "bgra8": 4, "rgba8": 4}[encoding]
    width, height, step = int(width), int(height), int(step)
    if width <= 0 or height <= 0:
        raise ValueError(f"empty image ({width}×{height})")
    if step < width * channels:
        raise ValueError(f"step {step} < width × channels = {width * channels}")
    buffer = np.frombuffer(bytes(data) if not isinstance(data, (bytes, bytearray, memoryview)) else data,
                           dtype=np.uint8)
    if buffer.size < step * height:
        raise ValueError(f"truncated image: {buffer.size} bytes for {height} rows of {step}")
    rows = buffer[: step * height].reshape(height, step)[:, : width * channels]
    if channels == 1:
        return np.ascontiguousarray(rows)
    pixels = rows.reshape(height, width, channels)
    code = {"bgr8": cv2.COLOR_BGR2GRAY, "rgb8": cv2.COLOR_RGB2GRAY, "bgra8": cv2.COLOR_BGRA2GRAY,
            "rgba8": cv2.COLOR_RGBA2GRAY}[encoding]
    return cv2.cvtColor(pixels, code)
