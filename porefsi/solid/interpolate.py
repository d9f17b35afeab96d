"""Evaluate a P1 nodal field of any tetrahedral mesh (uniform or graded) at arbitrary points."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from porefsi.errors import InputError
from porefsi.solid.mesh import SolidMesh

__all__ = ["p1_interpolate"]


def _barycentric(x: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (M, 4) of points X (M, 3) in tetrahedra with vertices x (M, 4, 3)."""
    T = np.transpose(x[:, 1:] - x[:, :1], (0, 2, 1))  # columns are edge vectors
    lam = np.linalg.solve(T, (X - x[:, 0])[..., None])[..., 0]
    return np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)


def p1_interpolate(mesh: SolidMesh, u: np.ndarray, X: np.ndarray,
                   n_candidates: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """The piecewise-linear field with nodal values ``u`` at points ``X``.

    Parameters
    ----------
    mesh : SolidMesh
    u : ndarray, shape (Nn,) or (Nn, k)
        Nodal values.
    X : ndarray of float, shape (M, 3)
        Points, m.
    n_candidates : int, default 24
        Tetrahedra (nearest centroids) searched per point.

    Returns
    -------
    values : ndarray, shape (M,) or (M, k)
        The field at ``X``; points in no tetrahedron (in pores, outside the mesh) take the value
        of the nearest node.
    inside : ndarray of bool, shape (M,)
        Whether each point was found in a tetrahedron.
    """
    u = np.asarray(u, float)
    X = np.atleast_2d(np.asarray(X, float))
    if u.shape[0] != mesh.n_nodes or X.shape[1:] != (3,):
        raise InputError(f"u must have {mesh.n_nodes} rows and X shape (M, 3), got {u.shape} and {X.shape}")
    pts, tets = mesh.points, mesh.tets
    h = float(np.cbrt(mesh.volume / mesh.n_tets))
    tol = 1e-9
    k = min(int(n_candidates), mesh.n_tets)
    _, cand = cKDTree(pts[tets].mean(axis=1)).query(X, k=k)
    cand = cand.reshape(len(X), k)
    found = np.full(len(X), -1, np.int64)
    bary = np.zeros((len(X), 4))
    for j in range(k):
        todo = np.flatnonzero(found < 0)
        if not len(todo):
            break
        e = cand[todo, j]
        b = _barycentric(pts[tets[e]], X[todo])
        ok = b.min(axis=1) >= -tol * max(1.0, h)
        found[todo[ok]], bary[todo[ok]] = e[ok], b[ok]
    inside = found >= 0
    _, near = cKDTree(pts).query(X[~inside])
    out = np.empty((len(X), *u.shape[1:]))
    out[~inside] = u[near]
    w = bary[inside]
    out[inside] = np.einsum("ma,ma...->m...", w, u[tets[found[inside]]])
    return out, inside
