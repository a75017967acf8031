"""The renderer's region-restricted effects (issue 11's cost of the hardware profile) give the same pixels as the
whole-frame operations they replace: the optical blur on the marker's region only, the occluding band rasterised
on its own bounding box, the lighting gradient into a kept buffer. The reference below is the former code."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
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


def test_the_lighting_gradient_kept_buffer_gives_the_former_sums():
    renderer = MarkerRenderer()
    rng = np.random.default_rng(2)
    for shape in ((480, 640), (480, 640), (240, 320)):
        pixels = rng.uniform(0.0, 255.0, shape).astype(np.float32)
        effects = FrameEffects(gain=1.1, offset=-3.0, gradient=rng.normal(0.0, 30.0, 2))
        height, width = shape
        xs = (np.arange(width, dtype=np.float32) - 0.5 * width) / width
        ys = (np.arange(height, dtype=np.float32) - 0.5 * height) / height
        a, b = (np.float32(v) for v in effects.gradient)
        expected = pixels * np.float32(1.1) + np.float32(-3.0)
        expected += np.add.outer(b * ys, a * xs)
        renderer._apply_photometric(pixels, effects)
        assert pixels.tobytes() == expected.tobytes()
