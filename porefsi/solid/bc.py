"""Boundary conditions of the solid: Dirichlet specs on box faces, loads on tagged facets.

Dirichlet values are affine in time, ``u_c(t) = value + rate * t`` (a constant strain rate on a
face is ``rate = -strain_rate * L``): the prescribed dofs have zero acceleration, so condensing
them out of a lumped or consistent mass system adds no inertial load.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from porefsi.errors import InputError
from porefsi.image.voxel_image import axis_index
from porefsi.solid.mesh import FACE_NAMES, FACET_TAGS

__all__ = ["Fixed", "Roller", "Prescribed", "Affine", "Traction", "Constraints", "uniaxial_bcs", "face_dofs"]


def _face(face: str) -> str:
    if face not in FACE_NAMES:
        raise InputError(f"unknown face {face!r}; use one of {FACE_NAMES}")
    return face


@dataclasses.dataclass(frozen=True)
class Fixed:
    """All displacement components zero on box face ``face`` ('xmin', ..., 'zmax')."""

    face: str

    def items(self):  # noqa: D102
        return [(_face(self.face), c, 0.0, 0.0) for c in range(3)]


@dataclasses.dataclass(frozen=True)
class Roller:
    """Zero normal displacement on ``face``; tangential motion free (frictionless wall)."""

    face: str

    def items(self):  # noqa: D102
        return [(_face(self.face), FACE_NAMES.index(self.face) // 2, 0.0, 0.0)]


@dataclasses.dataclass(frozen=True)
class Prescribed:
    """Component ``component`` on ``face`` follows ``value + rate * t`` (m, m/s)."""

    face: str
    component: int | str
    value: float = 0.0
    rate: float = 0.0

    def items(self):  # noqa: D102
        return [(_face(self.face), axis_index(self.component), float(self.value), float(self.rate))]


@dataclasses.dataclass(frozen=True, eq=False)
class Affine:
    """Kinematic uniform condition on ``face``: ``u(X, t) = (G + G_rate t) X + c`` (all components).

    Used for patch tests and for homogenisation with kinematic uniform boundary conditions.
    ``G``, ``G_rate``: (3, 3) (dimensionless, 1/s); ``c``: (3,) m.
    """

    face: str
    G: np.ndarray
    c: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    G_rate: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((3, 3)))

    def resolve(self, dof_points):  # noqa: D102
        out = []
        G, c, Gr = (np.asarray(a, dtype=float) for a in (self.G, self.c, self.G_rate))
        for comp in range(3):
            dofs = face_dofs(dof_points, self.face, comp)
            X = dof_points[dofs // 3]
            out.append((self.face, comp, dofs, X @ G[comp] + c[comp], X @ Gr[comp]))
        return out


@dataclasses.dataclass(frozen=True)
class Traction:
    """Dead surface load on the facets tagged ``tag``: a traction vector (Pa) and/or a pressure.

    ``pressure`` p pushes on the solid (traction ``-p N``, N the outward reference normal).
    """

    tag: str
    traction: tuple[float, float, float] | None = None
    pressure: float | None = None

    def __post_init__(self):
        if self.tag not in FACET_TAGS:
            raise InputError(f"unknown facet tag {self.tag!r}; use one of {sorted(FACET_TAGS)}")


def face_dofs(dof_points: np.ndarray, face: str, component: int, rtol: float = 1e-9) -> np.ndarray:
    """Dofs (interleaved numbering) of ``component`` at Lagrange nodes on the plane of ``face``."""
    ax = FACE_NAMES.index(_face(face)) // 2
    x = dof_points[:, ax]
    ext = float(np.ptp(dof_points, axis=0).max()) or 1.0
    plane = x.min() if face.endswith("min") else x.max()
    nodes = np.flatnonzero(np.abs(x - plane) <= rtol * ext)
    return 3 * nodes + int(component)


@dataclasses.dataclass(frozen=True, eq=False)
class Constraints:
    """Compiled Dirichlet conditions: ``dofs (nd,)`` sorted, ``u(t) = value + rate t`` on them.

    Attributes
    ----------
    dofs, value, rate : ndarray, shape (nd,)
    free : ndarray of int64, shape (n,)
        The complementary free dofs.
    n_full : int
    """

    dofs: np.ndarray
    value: np.ndarray
    rate: np.ndarray
    free: np.ndarray
    n_full: int

    @classmethod
    def build(cls, dof_points: np.ndarray, specs: Sequence) -> Constraints:
        """Compile ``specs`` (Fixed/Roller/Prescribed) on nodes at ``dof_points`` (N, 3).

        Raises
        ------
        InputError
            If two specs prescribe different motions for the same dof, or a face has no nodes.
        """
        n_full = 3 * len(dof_points)
        dofs_l, val_l, rate_l = [], [], []
        for spec in specs:
            if hasattr(spec, "resolve"):
                parts = spec.resolve(dof_points)
            else:
                parts = [(f, c, face_dofs(dof_points, f, c), v, r) for f, c, v, r in spec.items()]
            for face, _comp, dofs, val, rate in parts:
                if len(dofs) == 0:
                    raise InputError(f"face {face} has no mesh nodes")
                dofs_l.append(dofs)
                val_l.append(np.broadcast_to(np.asarray(val, dtype=float), dofs.shape))
                rate_l.append(np.broadcast_to(np.asarray(rate, dtype=float), dofs.shape))
        if dofs_l:
            d = np.concatenate(dofs_l)
            v = np.concatenate(val_l)
            r = np.concatenate(rate_l)
        else:
            d, v, r = np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
        dofs, first = np.unique(d, return_index=True)
        inv = np.searchsorted(dofs, d)
        scale = max(float(np.abs(v).max(initial=0)), float(np.abs(r).max(initial=0)), 1e-300)
        clash = (np.abs(v - v[first][inv]) > 1e-12 * scale) | (np.abs(r - r[first][inv]) > 1e-12 * scale)
        if np.any(clash):
            k = int(np.argmax(clash))
            raise InputError(
                f"conflicting Dirichlet conditions at dof {int(d[k])} (node {int(d[k]) // 3}, component "
                f"{int(d[k]) % 3}): value/rate {v[k]:g}/{r[k]:g} vs {v[first][inv][k]:g}/{r[first][inv][k]:g}; "
                "make the conditions agree on shared edges"
            )
        free = np.setdiff1d(np.arange(n_full, dtype=np.int64), dofs)
        return cls(dofs=dofs.astype(np.int64), value=v[first].copy(), rate=r[first].copy(), free=free,
                   n_full=n_full)

    def values(self, t: float) -> np.ndarray:
        """Prescribed displacements at time t, m, shape (nd,)."""
        return self.value + self.rate * float(t)


def uniaxial_bcs(axis: str | int = "z", *, displacement: float = 0.0, rate: float = 0.0,
                 lateral: str = "roller") -> list:
    """The paper's loading frame along ``axis``.

    The min face is fixed, the max face moves by ``displacement + rate * t`` along ``axis``
    (negative = compression) with its tangential components held (a bonded platen), and the four
    lateral faces are on rollers (``lateral='roller'``) or free (``lateral='free'``).
    """
    ax = axis_index(axis)
    lo, hi = FACE_NAMES[2 * ax], FACE_NAMES[2 * ax + 1]
    specs: list = [Fixed(lo), Prescribed(hi, ax, displacement, rate)]
    specs += [Prescribed(hi, c, 0.0, 0.0) for c in range(3) if c != ax]
    if lateral == "roller":
        specs += [Roller(FACE_NAMES[2 * a + s]) for a in range(3) if a != ax for s in (0, 1)]
    elif lateral != "free":
        raise InputError(f"lateral must be 'roller' or 'free', got {lateral!r}")
    return specs

