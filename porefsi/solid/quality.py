"""Shape quality of tetrahedra: dihedral angles and radius ratio (to find slivers)."""

from __future__ import annotations

import numpy as np

from porefsi.errors import InputError

__all__ = ["tet_quality", "quality_histogram"]

# The six edges (i, j) of a tetrahedron and, for each, the two other vertices (k, l).
_EDGES = ((0, 1, 2, 3), (0, 2, 1, 3), (0, 3, 1, 2), (1, 2, 0, 3), (1, 3, 0, 2), (2, 3, 0, 1))


def tet_quality(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum and maximum dihedral angle (degrees) and radius ratio of each tetrahedron.

    Parameters
    ----------
    points : ndarray of float, shape (Nn, 3)
    tets : ndarray of int, shape (Ne, 4)

    Returns
    -------
    min_dihedral, max_dihedral : ndarray, shape (Ne,)
        Degrees; 70.53 for the regular tetrahedron; a sliver has a min near 0 or a max near 180.
    radius_ratio : ndarray, shape (Ne,)
        ``3 r_in / r_circ``, 1 for the regular tetrahedron, 0 for a degenerate one.
    """
    x = np.asarray(points, float)[np.asarray(tets)]
    if x.ndim != 3 or x.shape[1:] != (4, 3):
        raise InputError(f"tets must be (Ne, 4) indices into (Nn, 3) points, got {np.shape(tets)}")
    angles = []
    for i, j, k, ll in _EDGES:
        e = x[:, j] - x[:, i]
        e /= np.linalg.norm(e, axis=1, keepdims=True)
        a, b = x[:, k] - x[:, i], x[:, ll] - x[:, i]  # the two faces' third vertices, projected off the edge
        a -= np.einsum("ij,ij->i", a, e)[:, None] * e
        b -= np.einsum("ij,ij->i", b, e)[:, None] * e
        cos = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        angles.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    ang = np.stack(angles, axis=1)
    vol = np.abs(np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])) / 6.0
    faces = ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2))
    area = sum(0.5 * np.linalg.norm(np.cross(x[:, b] - x[:, a], x[:, c] - x[:, a]), axis=1) for a, b, c in faces)
    r_in = 3.0 * vol / area
    # circumradius: |a|^2 (b x c) + |b|^2 (c x a) + |c|^2 (a x b) over 12 V (edges from vertex 0)
    a, b, c = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]
    num = ((a * a).sum(1)[:, None] * np.cross(b, c) + (b * b).sum(1)[:, None] * np.cross(c, a)
           + (c * c).sum(1)[:, None] * np.cross(a, b))
    with np.errstate(divide="ignore", invalid="ignore"):
        r_circ = np.linalg.norm(num, axis=1) / (12.0 * vol)
        ratio = np.where(vol > 0, 3.0 * r_in / r_circ, 0.0)
    return ang.min(axis=1), ang.max(axis=1), ratio


def quality_histogram(min_dihedral: np.ndarray, edges=(0, 10, 20, 30, 35, 40, 45, 50, 55, 60, 71)) -> dict:
    """Counts of tetrahedra per bin of minimum dihedral angle (degrees): ``{"30-35": n, ...}``."""
    counts, _ = np.histogram(min_dihedral, bins=np.asarray(edges, float))
    return {f"{lo:g}-{hi:g}": int(n) for lo, hi, n in zip(edges[:-1], edges[1:], counts, strict=True)}
