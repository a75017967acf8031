"""fpr_experiments.animation: the report's 3D GIF is drawn from the truth (geometry checked against the record)."""

from __future__ import annotations

import numpy as np
import pytest
from fpr_experiments.animation import frame_times, robot_segments, write_animation
from fpr_experiments.records import FlightRecord, TruthSeries
from fpr_model.rotations import euler_zyx_to_quat


def _record(n: int = 3, samples: int = 41) -> FlightRecord:
    t = np.linspace(0.0, 4.0, samples)
    quat = np.array([euler_zyx_to_quat(0.1, -0.05, 0.3)] * samples)
    position = np.column_stack([0.1 * t, np.zeros(samples), 1.0 + 0.1 * t])
    uav_positions = position[:, None, :] + np.array([[0.8, 0.0, 0.6], [-0.4, 0.7, 0.6], [-0.4, -0.7, 0.6]])[None]
    truth = TruthSeries(t=t, position=position, quat=quat, rpy=np.tile([0.1, -0.05, 0.3], (samples, 1)),
                        legs=np.full((samples, n), 1.0), leg_rates=np.zeros((samples, n)),
                        velocity=np.zeros((samples, 3)), rate=np.zeros((samples, 3)),
                        thrusts=np.full((samples, n), 11.0), uav_positions=uav_positions,
                        uav_quats=np.tile([1.0, 0.0, 0.0, 0.0], (samples, n, 1)),
                        external_wrench=np.zeros((samples, 6 + n)), contact_force=np.zeros(samples),
                        payload_mass=np.zeros(samples), battery=np.full((samples, n), 12.0))
    return FlightRecord(n=n, truth=truth, command=None, uavs=[], names=None, experiment="test", variant="v")


def test_frames_follow_the_speedup_and_the_cap():
    record = _record()
    assert len(frame_times(record, fps=10.0, speedup=4.0, max_frames=150)) == 11  # 4 s at 0.4 s per frame
    assert len(frame_times(record, fps=10.0, speedup=0.1, max_frames=25)) == 25


def test_segments_are_the_truth():
    record = _record()
    shape = robot_segments(record, 10)
    legs = shape["legs"]
    assert np.allclose(legs[:, 1], record.truth.uav_positions[10])  # each leg ends at its UAV
    radius = np.linalg.norm(legs[:, 0] - record.truth.position[10], axis=1)
    assert np.allclose(radius, 0.127, atol=1e-9)  # the joints A_i on the Table B.1 platform radius
    assert np.allclose(shape["platform"][0], shape["platform"][-1])  # closed polygon
    arm = shape["arms"][0, 0]
    assert np.linalg.norm(arm[1] - arm[0]) == pytest.approx(0.4)


def test_gif_is_written(tmp_path):
    path = write_animation(_record(), str(tmp_path / "flight.gif"), max_frames=5)
    with open(path, "rb") as stream:
        assert stream.read(6) in (b"GIF89a", b"GIF87a")
