"""The renderer's region-restricted effects (issue 11's cost of the hardware profile) give the same pixels as the
whole-frame operations they replace: the optical blur on the marker's region only, the occluding band rasterised
on its own bounding box, the grey-level pass (gain and offset through a table, the lighting gradient into a
kept buffer, the noise bank scaled once, in place). The reference below is the former code."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from fpr_model.calibration import CameraModel
from fpr_model.opencv_dispatch import opencv_dispatch
from fpr_sim.camera_renderer import FrameEffects, MarkerRenderer


def _former_band(image: np.ndarray, effects: FrameEffects) -> None:
    """fpr_sim.camera_renderer's occluding band before 2026-12-07: a whole-frame mask."""
    if effects.occluder is not None:
        mask = np.zeros_like(image)
        cv2.fillConvexPoly(mask, np.round(np.asarray(effects.occluder) * 16).astype(np.int32), 1,
                           lineType=cv2.LINE_8, shift=4)
        covered = mask.astype(bool)
        image[covered] = np.rint(image[covered] * float(effects.occluder_factor)).astype(np.uint8)


def _random_pose(rng: np.random.Generator) -> np.ndarray:
    from fpr_model.rotations import quat_from_rotvec, quat_to_rotmat

    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ quat_to_rotmat(quat_from_rotvec(rng.normal(0.0, 0.4, 3)))
    # near the frame's edges too (partly outside: in_view False, still drawn)
    T[:3, 3] = [*rng.uniform(-0.35, 0.35, 2), rng.uniform(0.25, 1.2)]
    return T


def _random_effects(rng: np.random.Generator, width: int, height: int) -> FrameEffects:
    centre = rng.uniform([-50.0, -50.0], [width + 50.0, height + 50.0])
    half = rng.uniform(5.0, 150.0, 2)
    angle = rng.uniform(0.0, np.pi)
    axes = np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]]) * half[:, None]
    band = np.array([centre - axes[0] - axes[1], centre + axes[0] - axes[1], centre + axes[0] + axes[1],
                     centre - axes[0] + axes[1]])
    return FrameEffects(occluder=band if rng.random() < 0.7 else None, occluder_factor=float(rng.uniform(0.0, 0.9)),
                        motion=rng.normal(0.0, 4.0, 2) if rng.random() < 0.7 else None)


@pytest.mark.parametrize("blur_sigma", [0.6, 1.7])
def test_regions_give_the_pixels_of_the_whole_frame_operations(blur_sigma):
    renderer = MarkerRenderer()
    rng = np.random.default_rng(11)
    width, height = renderer.camera.width, renderer.camera.height
    compared = drawn = occluded = 0
    for _ in range(150):
        T = _random_pose(rng)
        effects = _random_effects(rng, width, height)
        frame = renderer.render(T, blur_sigma=blur_sigma, effects=effects)
        # the former: the same drawing, the whole-frame band and smear, the whole-frame blur
        plain = renderer.render(T).image.copy()
        R, t = T[:3, :3], T[:3, 3]
        if frame.drawn:  # the band as before, then the motion smear (its region unchanged) as the renderer does it
            _former_band(plain, effects)
            renderer._occlude_and_smear(plain, renderer._project(renderer._outer @ R.T + t),
                                        FrameEffects(motion=effects.motion))
        expected = cv2.GaussianBlur(plain, (0, 0), blur_sigma)
        assert frame.image.tobytes() == expected.tobytes()
        compared += 1
        drawn += frame.drawn
        occluded += frame.drawn and effects.occluder is not None
    assert drawn > 60 and occluded > 30 and compared == 150  # the cases above were exercised


def _former_photometric_and_noise(image: np.ndarray, effects: FrameEffects, noise_sigma: float, noise_seed: int,
                                  rng: np.random.Generator) -> np.ndarray:
    """fpr_sim.camera_renderer's grey-level pass before 2026-12-07: whole-frame float32 operations, one after the
    other (gain, offset, the lighting gradient, σ × a window of the unit noise bank, rint, clip)."""
    height, width = image.shape
    noisy = image.astype(np.float32)
    if effects.gain != 1.0:
        noisy *= np.float32(effects.gain)
    if effects.offset != 0.0:
        noisy += np.float32(effects.offset)
    if effects.gradient is not None and np.any(effects.gradient):
        xs = (np.arange(width, dtype=np.float32) - 0.5 * width) / width
        ys = (np.arange(height, dtype=np.float32) - 0.5 * height) / height
        a, b = (np.float32(v) for v in effects.gradient)
        noisy += np.add.outer(b * ys, a * xs)
    if noise_sigma > 0.0:
        bank = np.random.default_rng(noise_seed).standard_normal((2 * height, 2 * width), dtype=np.float32)
        y, x = rng.integers(0, height + 1), rng.integers(0, width + 1)
        noisy += np.float32(noise_sigma) * bank[y:y + height, x:x + width]
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("dispatch", ["native", "baseline"])
def test_the_grey_level_pass_gives_the_former_pixels(dispatch):
    """Gain and offset through a table, the gradient into a kept buffer, the noise bank scaled once, the noise's
    addition rounded and clipped by OpenCV's saturating add: the bytes of the former whole-frame operations, for
    frames of two sizes and a change of σ, with OpenCV's SIMD code and with its baseline code (what the
    experiments fly, fpr_model.opencv_dispatch)."""
    with opencv_dispatch(dispatch):
        _compare_grey_level_pass()


def test_the_saturating_add_rounds_half_to_even_and_clips_like_numpy():
    """The renderer's last step, cv2.add(float32, float32, dtype=CV_8U), against np.rint + np.clip + astype on
    exact halves (…, -0.5, 0.5, 1.5, 2.5, …, 254.5, 255.5, …), values far outside 0-255 and a strided window."""
    grey = np.arange(-4.0, 260.0, 0.5, dtype=np.float32)
    grey = np.concatenate([grey, np.float32([-1e6, 1e6, 127.49999, 127.50001])])
    bank = np.tile(np.float32([0.0, 0.25, -0.25, 1.0]), (grey.size, 2))
    window = bank[:, 1:5]  # a view with a row stride, as the noise window is
    for dispatch in ("native", "baseline"):
        with opencv_dispatch(dispatch):
            pixels = np.repeat(grey[:, None], 4, axis=1)
            expected = np.clip(np.rint(pixels + window), 0, 255).astype(np.uint8)
            assert cv2.add(pixels, window, dtype=cv2.CV_8U).tobytes() == expected.tobytes()


def _compare_grey_level_pass() -> None:
    rng = np.random.default_rng(2)
    for width, height in ((640, 480), (320, 240)):
        renderer = MarkerRenderer(camera=CameraModel(fx=300.0, fy=300.0, cx=width / 2, cy=height / 2, width=width,
                                                     height=height)) if width != 640 else MarkerRenderer()
        assert (renderer.camera.width, renderer.camera.height) == (width, height)
        for k in range(12):
            T = _random_pose(rng)
            effects = FrameEffects(gain=float(rng.choice([1.0, rng.uniform(0.5, 1.6)])),
                                   offset=float(rng.choice([0.0, rng.uniform(-40.0, 40.0)])),
                                   gradient=rng.normal(0.0, 30.0, 2) if k % 3 else None)
            sigma = 2.0 if k < 8 else 3.5  # a change of σ rebuilds the scaled bank
            seed = int(rng.integers(1 << 30))
            frame = renderer.render(T, noise_sigma=sigma, rng=np.random.default_rng(seed), effects=effects)
            plain = renderer.render(T).image
            expected = _former_photometric_and_noise(plain, effects, sigma, renderer._noise_seed,
                                                     np.random.default_rng(seed))
            assert frame.image.tobytes() == expected.tobytes()
            # photometric changes without noise too
            frame = renderer.render(T, effects=effects)
            assert frame.image.tobytes() == _former_photometric_and_noise(plain, effects, 0.0, 0, rng).tobytes()
