"""Small convex-polytope helpers for the wrench feasibility analysis (thesis Ch. 5), built on qhull.

V-representation: a vertex array ``(m, d)``. H-representation: ``A @ x <= b`` with ``A`` ``(k, d)``,
``b`` ``(k,)``. Units are those of the points (N for thrusts and forces, N·m for moments).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

__all__ = ["Polytope", "convex_hull", "minkowski_sum_points"]

#: Two facet hyperplanes (unit normal ``a``, offset ``b``) are the same facet when the normals differ by
#: less than this and the offsets by less than this times the polytope's size.
COPLANAR_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Polytope:
    """A full-dimensional convex polytope in both representations.

    ``vertices``: (m, d) irredundant vertices. ``normals`` (k, d) unit outward normals and ``offsets`` (k,)
    of the facets, coplanar triangles of qhull merged, so ``normals @ x <= offsets`` describes the set.
    ``n_triangulated_facets``: the facet count before merging (qhull's simplicial facets).
    """

    vertices: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray
    volume: float
    n_triangulated_facets: int

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_facets(self) -> int:
        return int(self.normals.shape[0])

    def contains(self, points, tolerance: float = 1e-9) -> np.ndarray:
        """Boolean membership ``normals @ p <= offsets + tolerance`` of ``points`` (..., d)."""
        points = np.asarray(points, dtype=float)
        return np.all(points @ self.normals.T <= self.offsets + tolerance, axis=-1)


def convex_hull(points) -> Polytope:
    """Convex hull of ``points`` (m, d) as a :class:`Polytope` (qhull, then coplanar facets merged).

    Raises ValueError when the points do not span a full-dimensional set.
    """
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[0] <= points.shape[1]:
        raise ValueError(f"convex_hull: need more than d points in R^d, got shape {points.shape}")
    try:
        hull = ConvexHull(points)
    except Exception as error:  # scipy raises QhullError for flat point sets
        raise ValueError(f"convex_hull: qhull failed (degenerate point set?): {error}") from None
    normals, offsets = merge_coplanar(hull.equations[:, :-1], -hull.equations[:, -1], scale=_size(points))
    return Polytope(
        vertices=points[hull.vertices],
        normals=normals,
        offsets=offsets,
        volume=float(hull.volume),
        n_triangulated_facets=int(hull.equations.shape[0]),
    )


def merge_coplanar(normals: np.ndarray, offsets: np.ndarray, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Drop duplicate hyperplanes ``a @ x <= b`` (unit ``a``): keep one row per distinct facet plane."""
    keep: list[int] = []
    for j in range(normals.shape[0]):
        duplicate = False
        for k in keep:
            if (
                np.max(np.abs(normals[j] - normals[k])) < 1e3 * COPLANAR_TOLERANCE
                and abs(offsets[j] - offsets[k]) < 1e3 * COPLANAR_TOLERANCE * max(scale, 1.0)
            ):
                duplicate = True
                break
        if not duplicate:
            keep.append(j)
    return normals[keep].copy(), offsets[keep].copy()


def minkowski_sum_points(point_sets: list[np.ndarray]) -> np.ndarray:
    """All sums ``p_1 + ... + p_n`` with ``p_i`` a row of ``point_sets[i]`` (m_i, d): (Π m_i, d) candidates.

    The vertices of the Minkowski sum ⊕ conv(P_i) are a subset of these (5.15)-(5.16).
    """
    total = np.zeros((1, point_sets[0].shape[1]))
    for points in point_sets:
        total = (total[:, None, :] + np.asarray(points, dtype=float)[None, :, :]).reshape(-1, total.shape[1])
    return total


def _size(points: np.ndarray) -> float:
    return float(np.max(np.abs(points))) if points.size else 1.0
