"""Synthetic on-board camera: mono8 images of the ArUco marker under the platform (thesis §4.2.1). ROS-free.

:class:`MarkerRenderer` draws the ARUCO_MIP_36h12 marker (id 0, side 0.109 m by default, generated with
``cv2.aruco.generateImageMarker``, surrounded by a white quiet zone) into a uniform grey image, seen from a camera
at the pose ``C_T_M`` (marker frame -> camera frame, OpenCV optical convention x right, y down, z forward; marker
frame as in :mod:`fpr_model.calibration`). Perspective is exact: the texture is mapped by the homography of the
projected quiet-zone corners (for a camera without distortion) or by a per-pixel remap through OpenCV's
distortion model (``cv2.undistortPoints``) when the camera has distortion. Only the bounding box of the
projected marker is warped, so a frame costs about a millisecond. The marker is not drawn when any of its
corners is behind (or within ``near_clip`` of) the camera, or when its bounding box misses the image.

Options: Gaussian blur (σ in px) before Gaussian pixel noise (σ in grey levels); deterministic for a seed.
Per-frame realism effects (:class:`FrameEffects`, drawn by :mod:`fpr_sim.cameras`), applied in the order light
meets them: an occluding band over the marker (a leg or its shadow), motion blur along the image motion during
the exposure (a line kernel on the marker's region only), the optical blur, then the photometric gain and offset
(a 256-entry table), the lighting gradient and the sensor noise on float32 grey levels, rounded to uint8 in the
noise's addition (OpenCV's saturating add: half to even, clipped). Without effects the image is bit-identical to
the effect-free renderer. That last pass (table, gradient, noise, rounding) runs in the compiled kernel when it is
available (:class:`fpr_sim._kernels.FrameKernel`, one pass, the same bits; ``kernel=`` / ``$FPR_SIM_KERNEL`` as
for the plant), else in numpy/OpenCV (the reference). The band and the optical blur work on the region they can
change (the rest of the frame is the uniform background, which a blur leaves as it is): the same pixels as
whole-frame operations (``test_render_regions.py`` keeps the former code as its reference).

:func:`emulate_relative_pose` gives the MOCAP-emulated relative pose of thesis §4.4.1: the true ``p_T_b`` with
Gaussian noise (default 2 cm and 2° per axis).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from fpr_model.calibration import CameraModel, aruco_dictionary, invert_transform, make_transform
from fpr_model.rotations import quat_from_rotvec, quat_to_rotmat

from fpr_sim._kernels import FrameKernel, resolve_kernel

__all__ = ["FrameEffects", "MarkerRenderer", "RenderResult", "emulate_relative_pose", "motion_blur_kernel"]


@dataclass
class FrameEffects:
    """Realism effects of one frame (image coordinates in px, grey levels 0-255).

    occluder: (4, 2) polygon [px] whose pixels are multiplied by ``occluder_factor`` (None: no occlusion).
    motion: (2,) image displacement of the marker during the exposure [px] (None or < 0.5 px: no motion blur).
    gain, offset: photometric I' = gain·I + offset [-, grey levels]. gradient: (2,) lighting gradient (a, b)
    [grey levels] across the image: + a·x̂ + b·ŷ, x̂ = (u − W/2)/W, ŷ = (v − H/2)/H.
    """

    occluder: np.ndarray | None = None
    occluder_factor: float = 1.0
    motion: np.ndarray | None = None
    gain: float = 1.0
    offset: float = 0.0
    gradient: np.ndarray | None = None

    @property
    def photometric(self) -> bool:
        return self.gain != 1.0 or self.offset != 0.0 or (self.gradient is not None and bool(np.any(self.gradient)))


def motion_blur_kernel(motion: np.ndarray) -> np.ndarray:
    """Normalised line kernel (float32, odd square side) of a linear image motion ``motion`` (2,) [px]: the box
    average of the exposure's positions, drawn anti-aliased with cv2.line on a 4× grid and area-reduced."""
    length = float(np.hypot(*motion))
    side = 2 * int(np.ceil(0.5 * length)) + 1
    s = 4
    fine = np.zeros((side * s, side * s), dtype=np.float32)
    centre = np.array([side * s / 2.0 - 0.5] * 2)
    a, b = centre - 0.5 * s * np.asarray(motion), centre + 0.5 * s * np.asarray(motion)
    shift = 4
    cv2.line(fine, tuple(int(round(v * (1 << shift))) for v in a), tuple(int(round(v * (1 << shift))) for v in b),
             1.0, thickness=s, lineType=cv2.LINE_AA, shift=shift)
    kernel = cv2.resize(fine, (side, side), interpolation=cv2.INTER_AREA)
    return kernel / max(float(kernel.sum()), 1e-12)

@dataclass
class RenderResult:
    """One rendered frame.

    image: (height, width) uint8 mono8.
    drawn: the marker (or part of it) was drawn.
    in_view: all four marker corners are inside the image (with a 1 px margin) and in front of the camera.
    corners: (4, 2) projected marker corners (TL, TR, BR, BL) [px], NaN when behind the camera.
    """

    image: np.ndarray
    drawn: bool
    in_view: bool
    corners: np.ndarray


class MarkerRenderer:
    """Renders one marker for one camera. Build once, call :meth:`render` per frame.

    camera: intrinsics and distortion. marker_size: black-square side [m]. quiet_zone_cells: white border width in
    marker cells (the 36h12 marker is 8 cells wide incl. its black border). background: grey level of the
    scene. pixels_per_cell: resolution of the finest texture (mip levels are derived by halving).
    noise_seed: seed of the pixel-noise bank (see :meth:`render`). supersampling: s x s samples per pixel,
    averaged (pixel-area integration; 1 = point sampling, whose aliasing moves edges by up to ~0.3 px).
    kernel: the frame's last pass in 'compiled' C or 'python' (numpy/OpenCV); None: ``$FPR_SIM_KERNEL`` (default
    'auto': compiled when built). The same images either way.
    """

    def __init__(self, camera: CameraModel | None = None, marker_size: float = 0.109,
                 dictionary: str = "DICT_ARUCO_MIP_36H12", marker_id: int = 0,
                 quiet_zone_cells: float = 1.0, background: int = 110, pixels_per_cell: int = 32,
                 near_clip: float = 0.02, noise_seed: int = 0, supersampling: int = 4,
                 kernel: str | None = None) -> None:
        self.camera = camera if camera is not None else CameraModel()
        if not marker_size > 0.0:
            raise ValueError(f"marker_size must be positive, got {marker_size}")
        self.marker_size = float(marker_size)
        self.background = int(np.clip(background, 0, 255))
        self.near_clip = float(near_clip)
        if int(supersampling) < 1:
            raise ValueError(f"supersampling must be >= 1, got {supersampling}")
        self.supersampling = int(supersampling)
        dictionary_obj = aruco_dictionary(dictionary)
        cells = dictionary_obj.markerSize + 2  # bits + 1-cell black border on each side
        quiet_px = int(round(quiet_zone_cells * pixels_per_cell))
        marker = cv2.aruco.generateImageMarker(dictionary_obj, int(marker_id), cells * pixels_per_cell)
        texture = cv2.copyMakeBorder(marker, quiet_px, quiet_px, quiet_px, quiet_px, cv2.BORDER_CONSTANT,
                                     value=255)
        # Mip pyramid (area-averaged halvings) to avoid aliasing when the marker is small in the image.
        self._mips = [texture]
        while self._mips[-1].shape[0] > 16:
            self._mips.append(cv2.resize(self._mips[-1], None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA))
        half_outer = 0.5 * self.marker_size * (cells + 2.0 * quiet_px / pixels_per_cell) / cells
        #: Quiet-zone outer corners in the marker frame (TL, TR, BR, BL), matching the texture's corners.
        self._outer = np.array([[-half_outer, half_outer, 0.0], [half_outer, half_outer, 0.0],
                                [half_outer, -half_outer, 0.0], [-half_outer, -half_outer, 0.0]])
        half = 0.5 * self.marker_size
        self.marker_corners = np.array([[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0],
                                        [-half, -half, 0.0]])
        self._K = self.camera.camera_matrix
        self._distorted = self.camera.has_distortion
        self._noise_seed = int(noise_seed)
        self._noise_bank: np.ndarray | None = None  # scaled by _noise_bank_sigma
        self._noise_bank_sigma = 0.0
        self._gradient_buffer: np.ndarray | None = None
        self._gradient_axes: tuple[np.ndarray, np.ndarray] | None = None
        #: 'compiled' or 'python': where the frame's last pass runs
        self.kernel = resolve_kernel(kernel)
        self._frame_kernel = FrameKernel() if self.kernel == "compiled" else None

    # ----------------------------------------------------------------------------------------------------
    def _project(self, points_camera: np.ndarray) -> np.ndarray:
        if self._distorted:
            return self.camera.project(points_camera)
        uvw = points_camera @ self._K.T
        return uvw[:, :2] / uvw[:, 2:3]

    def render(self, camera_T_marker, blur_sigma: float = 0.0, noise_sigma: float = 0.0,
               rng: np.random.Generator | None = None, effects: FrameEffects | None = None) -> RenderResult:
        """Render the frame for the marker pose ``C_T_M`` (4×4, metres).

        blur_sigma [px] and noise_sigma [grey levels] add optical blur and sensor noise. The noise is a window,
        at an offset drawn from ``rng``, of a fixed bank of Gaussian samples (2×2 frames, seeded by
        ``noise_seed``): the same seeds give the same images (a default_rng(0) is used when noise is requested
        without an ``rng``). ``effects`` (:class:`FrameEffects`): occlusion, motion blur, photometric changes.
        """
        T = np.asarray(camera_T_marker, dtype=float)
        width, height = self.camera.width, self.camera.height
        image = np.full((height, width), self.background, dtype=np.uint8)
        R, t = T[:3, :3], T[:3, 3]
        outer_c = self._outer @ R.T + t
        corners_c = self.marker_corners @ R.T + t
        drawn = False
        in_view = False
        corners = np.full((4, 2), np.nan)
        content = None  # (x0, y0, x1, y1) [px, end exclusive]: every pixel outside is the background
        if np.isfinite(T).all() and np.all(outer_c[:, 2] > self.near_clip):
            corners = self._project(corners_c)
            in_view = bool(np.all((corners[:, 0] >= 1.0) & (corners[:, 0] <= width - 2.0)
                                  & (corners[:, 1] >= 1.0) & (corners[:, 1] <= height - 2.0)))
            outer_px = self._project(outer_c)
            drawn = self._draw(image, outer_px, R, t)
            if drawn:
                content = _box(outer_px, 2)
                if effects is not None:
                    content = _union(content, self._occlude_and_smear(image, outer_px, effects))
        if blur_sigma > 0.0 and content is not None:
            # the optical blur of the marker's region only: a uniform background blurs to itself, and a margin of
            # the kernel's radius + 1 of background around the region gives the border pixels the same neighbours
            # as a whole-frame blur (the same bits, tested); ~15× less work on a 640 × 480 frame
            margin = int(np.ceil(3.0 * blur_sigma)) + 2  # OpenCV's uint8 kernel: round(6σ + 1) | 1 taps
            x0, y0 = max(content[0] - margin, 0), max(content[1] - margin, 0)
            x1, y1 = min(content[2] + margin, width), min(content[3] + margin, height)
            if x1 > x0 and y1 > y0:
                image[y0:y1, x0:x1] = cv2.GaussianBlur(image[y0:y1, x0:x1], (0, 0), float(blur_sigma))
        photometric = effects is not None and effects.photometric
        if (noise_sigma > 0.0 or photometric) and self._frame_kernel is not None:
            table, row_terms, column_terms = self._photometric_terms(effects) if photometric else (None, None, None)
            noise = self._noise_patch(rng if rng is not None else np.random.default_rng(0), noise_sigma) \
                if noise_sigma > 0.0 else None
            image = self._frame_kernel.finish(image, table, row_terms, column_terms, noise)
        elif noise_sigma > 0.0 or photometric:
            noisy = self._photometric(image, effects) if photometric else image.astype(np.float32)
            if noise_sigma > 0.0:
                rng = rng if rng is not None else np.random.default_rng(0)
                # one pass: the float32 sum, then OpenCV's saturate_cast to uint8 (round half to even, clipped to
                # 0-255): the bits of np.rint + np.clip + astype in a third of their time (test_render_regions)
                image = cv2.add(noisy, self._noise_patch(rng, noise_sigma), dtype=cv2.CV_8U)
            else:
                # in place: a fresh 1.2 MB array per operation cost its page faults (issue 15)
                np.rint(noisy, out=noisy)
                np.clip(noisy, 0, 255, out=noisy)
                image = noisy.astype(np.uint8)
        return RenderResult(image, drawn, in_view, corners)

    def _occlude_and_smear(self, image: np.ndarray, outer_px: np.ndarray,
                           effects: FrameEffects) -> Box | None:
        """In place: the occluding band (pixels × factor), then the motion blur on the marker's padded region.
        Returns the box (x0, y0, x1, y1) [px, end exclusive, may exceed the frame] of every pixel it may have
        changed, None if none. The band is rasterised on its own bounding box only (the polygon moved by whole
        pixels in OpenCV's 1/16-px fixed point: the same pixels as on a whole-frame mask, tested)."""
        height, width = image.shape
        touched = None
        if effects.occluder is not None:
            points = np.round(np.asarray(effects.occluder) * 16).astype(np.int32)
            x0, y0 = max(int(points[:, 0].min()) // 16 - 2, 0), max(int(points[:, 1].min()) // 16 - 2, 0)
            x1 = min(-(-int(points[:, 0].max()) // 16) + 3, width)
            y1 = min(-(-int(points[:, 1].max()) // 16) + 3, height)
            if x1 > x0 and y1 > y0:
                region = image[y0:y1, x0:x1]
                mask = np.zeros_like(region)
                cv2.fillConvexPoly(mask, points - np.array([16 * x0, 16 * y0], dtype=np.int32), 1,
                                   lineType=cv2.LINE_8, shift=4)
                covered = mask.astype(bool)
                region[covered] = np.rint(region[covered] * float(effects.occluder_factor)).astype(np.uint8)
                touched = (x0, y0, x1, y1)
        motion = effects.motion
        if motion is None or float(np.hypot(*motion)) < 0.5:
            return touched
        kernel = motion_blur_kernel(np.asarray(motion, dtype=float))
        pad = kernel.shape[0]
        x0 = max(int(np.floor(outer_px[:, 0].min())) - pad, 0)
        y0 = max(int(np.floor(outer_px[:, 1].min())) - pad, 0)
        x1 = min(int(np.ceil(outer_px[:, 0].max())) + pad + 1, width)
        y1 = min(int(np.ceil(outer_px[:, 1].max())) + pad + 1, height)
        if x1 > x0 and y1 > y0:
            roi = image[y0:y1, x0:x1]
            roi[...] = cv2.filter2D(roi, -1, kernel, borderType=cv2.BORDER_REPLICATE)
            touched = _union(touched, (x0, y0, x1, y1))
        return touched

    def _photometric_terms(self, effects: FrameEffects) -> tuple[np.ndarray | None, np.ndarray | None,
                                                                    np.ndarray | None]:
        """The photometric change of :class:`FrameEffects` as float32 pieces: the 256-entry table of
        ``np.float32(I)·gain + offset`` (None when gain 1 and offset 0) and the gradient's row terms ``b·ŷ``
        (height,) and column terms ``a·x̂`` (width,) (None, None without gradient)."""
        table = None
        if effects.gain != 1.0 or effects.offset != 0.0:
            table = np.arange(256, dtype=np.float32)
            if effects.gain != 1.0:
                table *= np.float32(effects.gain)
            if effects.offset != 0.0:
                table += np.float32(effects.offset)
        if effects.gradient is None or not np.any(effects.gradient):
            return table, None, None
        if self._gradient_axes is None:
            width, height = self.camera.width, self.camera.height
            self._gradient_axes = ((np.arange(width, dtype=np.float32) - 0.5 * width) / width,
                                   (np.arange(height, dtype=np.float32) - 0.5 * height) / height)
        xs, ys = self._gradient_axes
        a, b = (np.float32(v) for v in effects.gradient)
        return table, b * ys, a * xs

    def _photometric(self, image: np.ndarray, effects: FrameEffects) -> np.ndarray:
        """The float32 grey levels ``gain·I + offset + a·x̂ + b·ŷ`` of the uint8 ``image`` (see
        :class:`FrameEffects`, :meth:`_photometric_terms`): the table in one pass (cv2.LUT), then the gradient's
        outer sum (the reference of the compiled :class:`~fpr_sim._kernels.FrameKernel`)."""
        table, row_terms, column_terms = self._photometric_terms(effects)
        pixels = cv2.LUT(image, table) if table is not None else image.astype(np.float32)
        if row_terms is not None:
            if self._gradient_buffer is None or self._gradient_buffer.shape != pixels.shape:
                self._gradient_buffer = np.empty(pixels.shape, dtype=np.float32)
            # into a buffer kept from frame to frame: a fresh 1.2 MB array per frame cost its page faults
            pixels += np.add.outer(row_terms, column_terms, out=self._gradient_buffer)
        return pixels

    def _noise_patch(self, rng: np.random.Generator, sigma: float) -> np.ndarray:
        """A (height, width) window of Gaussian noise of standard deviation ``sigma`` [grey levels] at a random
        offset (drawn from ``rng``) into a fixed bank of 2×2 frames of unit samples (seeded by ``noise_seed``)
        scaled by ``np.float32(sigma)`` once (the same bits as scaling each window): 20× cheaper than fresh
        samples, and deterministic."""
        height, width = self.camera.height, self.camera.width
        if self._noise_bank is None or self._noise_bank_sigma != sigma:
            self._noise_bank = np.float32(sigma) * np.random.default_rng(self._noise_seed).standard_normal(
                (2 * height, 2 * width), dtype=np.float32)
            self._noise_bank_sigma = sigma
        y, x = rng.integers(0, height + 1), rng.integers(0, width + 1)
        return self._noise_bank[y:y + height, x:x + width]

    def _draw(self, image: np.ndarray, outer_px: np.ndarray, R: np.ndarray, t: np.ndarray) -> bool:
        height, width = image.shape
        x0 = max(int(np.floor(outer_px[:, 0].min())) - 1, 0)
        y0 = max(int(np.floor(outer_px[:, 1].min())) - 1, 0)
        x1 = min(int(np.ceil(outer_px[:, 0].max())) + 2, width)
        y1 = min(int(np.ceil(outer_px[:, 1].max())) + 2, height)
        if x1 <= x0 or y1 <= y0:
            return False
        s = self.supersampling
        # Mip level: the finest texture not more than ~3x finer than the supersampled quiet-zone side.
        side_px = s * max(float(np.max(np.linalg.norm(np.roll(outer_px, -1, axis=0) - outer_px, axis=1))), 1.0)
        level = 0
        while level + 1 < len(self._mips) and self._mips[level + 1].shape[0] >= 1.5 * side_px:
            level += 1
        texture = self._mips[level]
        size = texture.shape[0]
        # OpenCV convention: integer coordinates are pixel CENTRES, so the texture's outer edges (the quiet
        # zone's corners) are at -0.5 and size-0.5, and image pixel (u, v) covers [u-0.5, u+0.5]x[v-0.5, v+0.5].
        tex_corners = np.array([[-0.5, -0.5], [size - 0.5, -0.5], [size - 0.5, size - 0.5], [-0.5, size - 0.5]],
                               dtype=np.float32)
        # Supersampled ROI: fine pixel (X, Y) has its centre at image coordinates x0 - 0.5 + (X + 0.5)/s
        # (s x s fine pixels tile each image pixel); averaging each s x s block (INTER_AREA, integer factor)
        # integrates the texture over the pixel area like a sensor does, instead of point-sampling it (which
        # moves straight edges by up to ~0.3 px and biases the detected corners).
        roi_w, roi_h = x1 - x0, y1 - y0
        fine = np.full((roi_h * s, roi_w * s), self.background, dtype=np.uint8)
        if not self._distorted:
            fine_px = s * (outer_px - [x0, y0] + 0.5) - 0.5  # image -> fine-grid pixel-centre coordinates
            H = cv2.getPerspectiveTransform(tex_corners, fine_px.astype(np.float32))
            cv2.warpPerspective(texture, H, (roi_w * s, roi_h * s), dst=fine, flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_TRANSPARENT)
        else:
            # With distortion: fine pixel centre -> undistorted normalised ray -> marker plane -> texture.
            offsets = (np.arange(s, dtype=np.float64) + 0.5) / s - 0.5
            xs = (np.arange(x0, x1, dtype=np.float64)[:, None] + offsets[None, :]).ravel()
            ys = (np.arange(y0, y1, dtype=np.float64)[:, None] + offsets[None, :]).ravel()
            us, vs = np.meshgrid(xs, ys)
            pixels = np.stack([us.ravel(), vs.ravel()], axis=1).reshape(-1, 1, 2)
            rays = cv2.undistortPoints(pixels, self._K, self.camera.dist_coeffs).reshape(-1, 2)
            outer_norm = (self._outer @ R.T + t)
            outer_norm = (outer_norm[:, :2] / outer_norm[:, 2:3]).astype(np.float32)
            H = cv2.getPerspectiveTransform(outer_norm, tex_corners)  # normalised image plane -> texture
            mapped = cv2.perspectiveTransform(rays.reshape(-1, 1, 2).astype(np.float32), H).reshape(
                roi_h * s, roi_w * s, 2)
            cv2.remap(texture, mapped[..., 0], mapped[..., 1], cv2.INTER_LINEAR, dst=fine,
                      borderMode=cv2.BORDER_TRANSPARENT)
        roi = image[y0:y1, x0:x1]
        if s == 1:
            roi[...] = fine
        else:
            roi[...] = cv2.resize(fine, (roi_w, roi_h), interpolation=cv2.INTER_AREA)
        return True

    def render_from_poses(self, platform_T_body, body_T_camera, platform_T_marker, **kwargs) -> RenderResult:
        """Render from the UAV pose in the platform frame: ``C_T_M = (b_T_C)^{-1} (p_T_b)^{-1} p_T_M`` (4.2)."""
        camera_T_marker = invert_transform(body_T_camera) @ invert_transform(platform_T_body) @ platform_T_marker
        return self.render(camera_T_marker, **kwargs)


def emulate_relative_pose(platform_T_body, rng: np.random.Generator, position_sigma: float = 0.02,
                          angle_sigma: float = np.radians(2.0)) -> np.ndarray:
    """Noisy copy of ``p_T_b`` (thesis §4.4.1, MOCAP-emulated detections): ``p + N(0, σ_p² I)`` [m] and the
    rotation right-multiplied by ``exp(N(0, σ_a² I))`` (σ_a rad per body axis)."""
    T = np.asarray(platform_T_body, dtype=float)
    position = T[:3, 3] + rng.normal(0.0, position_sigma, 3)
    rotation = T[:3, :3] @ quat_to_rotmat(quat_from_rotvec(rng.normal(0.0, angle_sigma, 3)))
    return make_transform(rotation, position)


Box = tuple[int, int, int, int]


def _box(points: np.ndarray, margin: int) -> Box:
    """Pixel box (x0, y0, x1, y1), end exclusive, around (k, 2) points [px] with ``margin`` px on every side."""
    return (int(np.floor(points[:, 0].min())) - margin, int(np.floor(points[:, 1].min())) - margin,
            int(np.ceil(points[:, 0].max())) + margin + 1, int(np.ceil(points[:, 1].max())) + margin + 1)


def _union(a: Box | None, b: Box | None) -> Box | None:
    """The box around two boxes (None: no box)."""
    if a is None or b is None:
        return a if b is None else b
    return min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])
