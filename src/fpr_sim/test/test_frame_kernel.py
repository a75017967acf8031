"""The compiled last pass of a rendered frame (fpr_sim._kernels.FrameKernel: photometric table, lighting
gradient, sensor noise, rounding to uint8) gives the images of the numpy/OpenCV reference bit for bit: whole
renders with every effect, and the pass alone on edge cases (ties at .5, saturation both ways, huge gains, a width
that is not a multiple of the 16-pixel SIMD block)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from fpr_model.calibration import CameraModel
from fpr_sim._kernels import FrameKernel, compiler_available, kernel_status
from fpr_sim.camera_renderer import FrameEffects, MarkerRenderer


@pytest.fixture(autouse=True)
def _compiled_kernel() -> None:
    if not kernel_status().available:
        if compiler_available():
            pytest.fail(f"a C compiler exists but the compiled kernel is unavailable: {kernel_status().reason}")
        pytest.skip("no C compiler on this machine: the compiled kernel cannot be built")


def _pose(rng: np.random.Generator) -> np.ndarray:
    from fpr_model.rotations import quat_from_rotvec, quat_to_rotmat

    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ quat_to_rotmat(quat_from_rotvec(rng.normal(0.0, 0.4, 3)))
    T[:3, 3] = [*rng.uniform(-0.3, 0.3, 2), rng.uniform(0.25, 1.2)]
    return T


def _effects(rng: np.random.Generator) -> FrameEffects:
    effects = FrameEffects(motion=rng.normal(0.0, 3.0, 2) if rng.random() < 0.5 else None)
    if rng.random() < 0.8:
        effects.gain = max(0.0, 1.0 + 0.4 * float(rng.standard_normal())) if rng.random() < 0.8 else 1.0
        effects.offset = 30.0 * float(rng.standard_normal()) if rng.random() < 0.8 else 0.0
        effects.gradient = 60.0 * rng.standard_normal(2) if rng.random() < 0.8 else None
    return effects


@pytest.mark.parametrize("camera", [CameraModel(), CameraModel(width=333, height=251, fx=300.0, fy=300.0, cx=166.0,
                                                                 cy=125.0)], ids=["640x480", "333x251"])
def test_compiled_renders_are_the_reference_renders(camera):
    compiled = MarkerRenderer(camera, noise_seed=4, kernel="compiled")
    reference = MarkerRenderer(camera, noise_seed=4, kernel="python")
    assert (compiled.kernel, reference.kernel) == ("compiled", "python")
    rng = np.random.default_rng(5)
    streams = [np.random.default_rng(9), np.random.default_rng(9)]
    varied = 0
    for k in range(60):
        T, effects = _pose(rng), _effects(rng)
        noise = (0.0, 2.0, 3.0)[k % 3]
        blur = 0.6 if k % 2 else 0.0
        a = compiled.render(T, blur_sigma=blur, noise_sigma=noise, rng=streams[0], effects=effects)
        b = reference.render(T, blur_sigma=blur, noise_sigma=noise, rng=streams[1], effects=effects)
        assert a.image.dtype == b.image.dtype == np.uint8
        np.testing.assert_array_equal(a.image, b.image)
        varied += int(effects.photometric or noise > 0.0)
    assert varied > 40  # the pass ran in most frames
    assert streams[0].random() == streams[1].random()  # the same draws from the frames' stream


def _reference_pass(image, table, row_terms, column_terms, noise):
    """The renderer's numpy/OpenCV pass (camera_renderer.MarkerRenderer.render / _photometric)."""
    pixels = cv2.LUT(image, table) if table is not None else image.astype(np.float32)
    if row_terms is not None:
        pixels += np.add.outer(row_terms, column_terms)
    if noise is not None:
        return cv2.add(pixels, noise, dtype=cv2.CV_8U)
    np.rint(pixels, out=pixels)
    np.clip(pixels, 0, 255, out=pixels)
    return pixels.astype(np.uint8)


@pytest.mark.parametrize("width", [16, 17, 31, 640])
def test_the_pass_alone_on_edge_cases(width):
    kernel = FrameKernel()
    rng = np.random.default_rng(width)
    height = 7
    bank = rng.standard_normal((2 * height, 2 * width), dtype=np.float32) * np.float32(40.0)
    ties = np.arange(256, dtype=np.float32) + np.float32(0.5)  # every value a tie: half to even
    cases = [(None, None, None, True), (ties, None, None, False), (ties, None, None, True)]
    for gain, offset in ((1.0, 0.0), (0.0, 0.0), (1.7, -40.0), (0.3, 90.0), (1e6, 0.0), (-1e6, 5.0), (1.0, 1e9)):
        table = np.arange(256, dtype=np.float32) * np.float32(gain) + np.float32(offset)
        cases.append((table, None, None, True))
        cases.append((table, np.float32(50.0) * rng.standard_normal(height, dtype=np.float32),
                      np.float32(50.0) * rng.standard_normal(width, dtype=np.float32), bool(rng.random() < 0.5)))
    for table, row_terms, column_terms, with_noise in cases:
        image = rng.integers(0, 256, (height, width), dtype=np.uint8)
        y, x = rng.integers(0, height + 1), rng.integers(0, width + 1)
        noise = bank[y:y + height, x:x + width] if with_noise else None
        want = _reference_pass(image, table, row_terms, column_terms, noise)
        got = kernel.finish(image.copy(), table, row_terms, column_terms, noise)
        np.testing.assert_array_equal(got, want)


def test_the_pass_refuses_what_it_cannot_read():
    kernel = FrameKernel()
    image = np.zeros((4, 8), dtype=np.uint8)
    with pytest.raises(ValueError, match="uint8"):
        kernel.finish(image.astype(np.float32), None, None, None, None)
    with pytest.raises(ValueError, match="float32 vector of 256"):
        kernel.finish(image, np.arange(255, dtype=np.float32), None, None, None)
    with pytest.raises(ValueError, match="both row and column"):
        kernel.finish(image, None, np.zeros(4, dtype=np.float32), None, None)
    with pytest.raises(ValueError, match="noise window"):
        kernel.finish(image, None, None, None, np.zeros((4, 8), dtype=np.float64))
    with pytest.raises(ValueError, match="noise window"):
        kernel.finish(image, None, None, None, np.zeros((8, 16), dtype=np.float32)[::2, ::2])


def test_a_hardware_rig_renders_the_same_frames_with_either_kernel():
    """The whole camera rig of the hardware profile (true cameras with calibration error, occlusion, photometric
    changes, blur, noise), flown a few frames along a moving state: identical frames with either kernel."""
    from fpr_sim.cameras import CameraRig
    from fpr_sim.plant import Plant
    from fpr_sim.quadrotor import AttitudeCommand
    from fpr_sim.scenario import scenario_from_dict

    scenario = scenario_from_dict({"initial_state": {"mode": "hover", "leg_angles": 1.0, "position": [0, 0, 1.5]}},
                                  realism="hardware")
    assert scenario.cameras.lighting_gradient > 0.0 and scenario.cameras.occlusion_probability > 0.0
    plant = Plant(scenario)
    hover = plant.fleet.thrust() / plant.fleet.max_thrust()
    plant.set_command(AttitudeCommand(plant.fleet.quat, 1.05 * hover, np.ones(plant.n, dtype=bool)))
    rigs = [CameraRig(scenario.cameras, plant.n, scenario.seed, kernel=k) for k in ("compiled", "python")]
    for _ in range(12):
        for _ in range(50):
            plant.step()
        truth = plant.ground_truth()
        compiled, reference = (rig.render(truth) for rig in rigs)
        for a, b in zip(compiled, reference, strict=True):
            np.testing.assert_array_equal(a.image, b.image)
