"""Meshes of simple shapes with closed-form elastic solutions (for verification and studies)."""

from __future__ import annotations

import numpy as np

from porefsi.errors import InputError
from porefsi.solid.mesh import SolidMesh, mesh_voxels

__all__ = ["box_mesh", "shell_octant_mesh"]


def box_mesh(shape: tuple[int, int, int], size: tuple[float, float, float], origin=(0.0, 0.0, 0.0)) -> SolidMesh:
    """5-tet mesh of the box ``origin + [0, size]`` with ``shape`` cells per axis.

    Parameters
    ----------
    shape : (int, int, int)
        Cells along x, y, z.
    size : (float, float, float)
        Edge lengths, m.
    origin : (float, float, float)
        Lower corner, m.
    """
    shape = tuple(int(s) for s in shape)
    if len(shape) != 3 or min(shape) < 1:
        raise InputError(f"shape must be three integers >= 1, got {shape}")
    size = np.asarray(size, dtype=float)
    if size.shape != (3,) or np.any(size <= 0):
        raise InputError(f"size must be three positive lengths (m), got {size}")
    ijk, tets, facets, tags = mesh_voxels(np.ones(shape, dtype=bool))
    origin = np.asarray(origin, float)
    pts = origin + ijk * (size / np.asarray(shape))
    return SolidMesh(points=pts, tets=tets, facets=facets, facet_tags=tags, box=np.stack([origin, origin + size]))


def shell_octant_mesh(inner_radius: float, outer_radius: float, n: int, n_inner: int | None = None) -> SolidMesh:
    """Mesh of the octant x, y, z >= 0 of the spherical shell ``inner_radius <= r <= outer_radius``.

    A cube of ``n`` cells per axis minus its corner cube of ``n_inner`` cells is mapped radially:
    a grid point p with cube "radius" s = max(p) goes to ``r(s) p / |p|`` with r linear in s, so
    the inner cube surface becomes the inner sphere (tag ``pore_wall``), the outer cube faces the
    outer sphere (tags ``xmax``, ``ymax``, ``zmax``) and the symmetry planes stay planes (tags
    ``xmin``, ``ymin``, ``zmin``). Nodes lie exactly on both spheres; facets are flat.

    Parameters
    ----------
    inner_radius, outer_radius : float
        Radii a < b, m.
    n : int
        Cells per axis of the cube (mesh size h ~ (b - a) / (n - n_inner)).
    n_inner : int, optional
        Cells per axis of the removed corner cube; default ``n // 2``.
    """
    a, b = float(inner_radius), float(outer_radius)
    if not (0 < a < b):
        raise InputError(f"need 0 < inner_radius < outer_radius, got {a}, {b}")
    n = int(n)
    m = n // 2 if n_inner is None else int(n_inner)
    if not (1 <= m < n):
        raise InputError(f"need 1 <= n_inner < n, got n_inner={m}, n={n}")
    solid = np.ones((n, n, n), dtype=bool)
    solid[:m, :m, :m] = False
    ijk, tets, facets, tags = mesh_voxels(solid)
    p = ijk.astype(float)
    s = p.max(axis=1)
    r = a + (b - a) * (s - m) / (n - m)
    pts = p * (r / np.linalg.norm(p, axis=1))[:, None]
    return SolidMesh(points=pts, tets=tets, facets=facets, facet_tags=tags)
