"""A 3D animation (GIF) of a flight from its ground truth, for the report folder (issue 14), ROS-free.

Drawn from :class:`fpr_experiments.records.FlightRecord`'s truth (F0, ENU, metres): the platform as the polygon of
its revolute joints A_i (P + R_p·r[cos α_i, sin α_i, 0], Table B.1 radius, (2.5)), each leg as the segment from
A_i to its quadrotor's CoM, each quadrotor as a cross of its body x/y arms (0.2 m, its true attitude) and the
commanded thrust direction as its body z; the ground grid at z = 0. Time runs ``speedup`` × faster than the
flight, ``fps`` frames per second of GIF (Pillow, through matplotlib's PillowWriter). Rendering costs ~0.1 s per
frame on this machine; ``max_frames`` caps it (a long flight is then shown faster).
"""

from __future__ import annotations

import os

import numpy as np
from fpr_model.geometry import leg_anchor_angles
from fpr_model.parameters import default_parameters
from fpr_model.rotations import quat_to_rotmat

from fpr_experiments.records import FlightRecord

ARM = 0.2  #: [m] drawn half-length of a quadrotor arm


def frame_times(record: FlightRecord, fps: float, speedup: float, max_frames: int) -> np.ndarray:
    """The flight instants [s] shown, one per GIF frame: every ``speedup / fps`` s of the flight, at most
    ``max_frames`` (evenly spread over the flight when there would be more)."""
    t = record.truth.t
    if len(t) == 0:
        return np.zeros(0)
    step = speedup / fps
    times = np.arange(t[0], t[-1] + 1e-9, step)
    if len(times) > max_frames:
        times = np.linspace(t[0], t[-1], max_frames)
    return times


def robot_segments(record: FlightRecord, index: int) -> dict[str, np.ndarray]:
    """The drawn geometry at truth sample ``index``: ``platform`` (n+1, 3) closed polygon of the joints A_i,
    ``legs`` (n, 2, 3), ``arms`` (n, 2, 2, 3) (two arms per quadrotor, each a segment), ``thrust`` (n, 2, 3)."""
    truth = record.truth
    n = record.n
    params = default_parameters(n)
    alphas = leg_anchor_angles(n)
    rotation = quat_to_rotmat(truth.quat[index])
    anchors_p = params.platform_radius * np.stack([np.cos(alphas), np.sin(alphas), np.zeros(n)], axis=1)
    anchors = truth.position[index] + anchors_p @ rotation.T
    uavs = truth.uav_positions[index]
    arms, thrust = np.zeros((n, 2, 2, 3)), np.zeros((n, 2, 3))
    for i in range(n):
        body = quat_to_rotmat(truth.uav_quats[index, i])
        for k, axis in enumerate((body[:, 0], body[:, 1])):
            arms[i, k] = [uavs[i] - ARM * axis, uavs[i] + ARM * axis]
        thrust[i] = [uavs[i], uavs[i] + 0.3 * body[:, 2]]
    return {"platform": np.vstack([anchors, anchors[:1]]), "legs": np.stack([anchors, uavs], axis=1),
            "arms": arms, "thrust": thrust}


def write_animation(record: FlightRecord, path: str, fps: float = 10.0, speedup: float = 4.0,
                    max_frames: int = 80, dpi: int = 60) -> str | None:
    """Write the GIF to ``path``; returns it (None when the record has no truth)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    times = frame_times(record, fps, speedup, max_frames)
    if len(times) == 0:
        return None
    truth = record.truth
    indices = np.clip(np.searchsorted(truth.t, times), 0, len(truth.t) - 1)
    everything = np.concatenate([truth.position, truth.uav_positions.reshape(-1, 3)])
    centre = 0.5 * (everything.min(axis=0) + everything.max(axis=0))
    half = max(1.2, 0.5 * float(np.max(everything.max(axis=0) - everything.min(axis=0))) + 0.3)
    fig = plt.figure(figsize=(6.0, 5.0))
    ax = fig.add_subplot(projection="3d")
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(0.0, max(2.0 * half, centre[2] + half))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    grid = np.linspace(centre[0] - half, centre[0] + half, 5)
    for g in grid:
        ax.plot([g, g], [centre[1] - half, centre[1] + half], [0, 0], color="0.85", lw=0.5)
    for g in np.linspace(centre[1] - half, centre[1] + half, 5):
        ax.plot([centre[0] - half, centre[0] + half], [g, g], [0, 0], color="0.85", lw=0.5)
    (platform,) = ax.plot([], [], [], color="tab:blue", lw=2.0)
    legs = [ax.plot([], [], [], color="0.3", lw=1.5)[0] for _ in range(record.n)]
    arms = [[ax.plot([], [], [], color="tab:red", lw=1.5)[0] for _ in range(2)] for _ in range(record.n)]
    thrusts = [ax.plot([], [], [], color="tab:orange", lw=1.0)[0] for _ in range(record.n)]
    label = ax.set_title("")

    def set_line(line, points: np.ndarray) -> None:
        line.set_data(points[:, 0], points[:, 1])
        line.set_3d_properties(points[:, 2])

    def draw(frame: int):
        k = int(indices[frame])
        shape = robot_segments(record, k)
        set_line(platform, shape["platform"])
        for i in range(record.n):
            set_line(legs[i], shape["legs"][i])
            set_line(thrusts[i], shape["thrust"][i])
            for j in range(2):
                set_line(arms[i][j], shape["arms"][i, j])
        roll, pitch, _ = np.degrees(truth.rpy[k])
        label.set_text(f"{record.experiment}/{record.variant}  t = {truth.t[k]:5.1f} s  "
                       f"roll {roll:+.1f}°  pitch {pitch:+.1f}°  (×{speedup:g})")
        return [platform, *legs, *thrusts, *(a for pair in arms for a in pair), label]

    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    animation = FuncAnimation(fig, draw, frames=len(times), blit=False)
    animation.save(path, writer=PillowWriter(fps=fps), dpi=dpi)
    plt.close(fig)
    return path


__all__ = ["frame_times", "robot_segments", "write_animation"]
