r"""Closed-form conduit geometry: hydraulic resistances of the sphere–cylinder–sphere conduit.

A throat conduit is three segments in series (pore-i part, cylinder, pore-j part). Each segment
has a *hydraulic resistance factor* ``h`` (1/m³) such that, for a fluid of viscosity ``mu`` in
that segment, its resistance to volumetric flow is ``mu * h`` (Pa·s/m³). The conduit
conductance is then

.. math:: g = \frac{1}{\mu_i h_i + \mu_t h_t + \mu_j h_j}

which is also how segments holding different fluids combine (in series, never in parallel;
the seed paper's eq. 2.6 writes a parallel sum, see ``docs/theory.md``).

A pore on a face of the image box is joined to that face (a reservoir) by a *boundary conduit*:
a cylinder of the pore radius running from the pore centre to the face
(:func:`boundary_conduit_lengths`, :func:`boundary_resistance`). Single-phase permeability and
the drainage graph use the same definition.
"""

from __future__ import annotations

import numpy as np

from porefsi.image.voxel_image import axis_index
from porefsi.network.network import Network

__all__ = [
    "cylinder_resistance",
    "sphere_segment_resistance",
    "resistance_factors",
    "conduit_conductance",
    "boundary_conduit_lengths",
    "boundary_resistance",
]


def cylinder_resistance(radius, length):
    """Hagen–Poiseuille resistance factor of a cylinder, ``8 L / (pi r^4)``, 1/m³.

    Parameters
    ----------
    radius, length : array_like of float
        Cylinder radius and length, m (broadcast together).
    """
    r = np.asarray(radius, dtype=float)
    return 8.0 * np.asarray(length, dtype=float) / (np.pi * r**4)


def sphere_segment_resistance(pore_radius, throat_radius, length):
    r"""Resistance factor of the part of a conduit inside a spherical pore, 1/m³.

    The segment runs from the pore centre (x = 0) outwards for ``length``. Its cross-section is
    the sphere's, ``A(x) = pi (R^2 - x^2)``, until the sphere narrows to the throat radius at
    ``a = sqrt(R^2 - r_t^2)``; any remainder is a cylinder of the throat radius. For a slowly
    varying section, Hagen–Poiseuille gives ``h = 8 pi \int dx / A(x)^2``, whose closed form is

    .. math:: h = \frac{8}{\pi}\left[\frac{s}{2R^2(R^2-s^2)}
              + \frac{1}{4R^3}\ln\frac{R+s}{R-s}\right] + \frac{8(L-s)}{\pi r_t^4},
              \quad s = \min(L, a).

    Parameters
    ----------
    pore_radius, throat_radius, length : array_like of float
        R, r_t (<= R) and L, m.

    Returns
    -------
    ndarray of float
        h, 1/m³, finite and positive for R >= r_t > 0, L > 0.
    """
    R = np.asarray(pore_radius, dtype=float)
    rt = np.asarray(throat_radius, dtype=float)
    L = np.asarray(length, dtype=float)
    a = np.sqrt(np.maximum(R * R - rt * rt, 0.0))
    s = np.minimum(L, a)
    d = R * R - s * s
    sphere = (8.0 / np.pi) * (s / (2.0 * R * R * d) + np.log((R + s) / (R - s)) / (4.0 * R**3))
    return sphere + cylinder_resistance(rt, L - s)


def resistance_factors(net: Network) -> np.ndarray:
    """Resistance factors of the three segments of every conduit, 1/m³, shape (Nt, 3).

    Columns: pore ``conns[:, 0]`` part, cylinder, pore ``conns[:, 1]`` part.
    """
    c = net.throat_conns
    rt = net.throat_radius
    h = np.empty((net.n_throats, 3))
    h[:, 0] = sphere_segment_resistance(net.pore_radius[c[:, 0]], rt, net.throat_pore_length[:, 0])
    h[:, 1] = cylinder_resistance(rt, net.throat_length)
    h[:, 2] = sphere_segment_resistance(net.pore_radius[c[:, 1]], rt, net.throat_pore_length[:, 1])
    return h


def conduit_conductance(net: Network, viscosity) -> np.ndarray:
    """Single-fluid hydraulic conductance of every conduit, m³/(Pa·s), shape (Nt,).

    Parameters
    ----------
    net : Network
    viscosity : float or ndarray of float, shape (Nt, 3)
        Dynamic viscosity, Pa·s: one value, or one per segment (pore-i part, cylinder, pore-j part).
    """
    h = resistance_factors(net)
    mu = np.broadcast_to(np.asarray(viscosity, dtype=float), h.shape)
    return 1.0 / np.sum(mu * h, axis=1)


def boundary_conduit_lengths(net: Network, axis: str | int) -> tuple[np.ndarray, np.ndarray]:
    r"""Lengths of the boundary conduits from every pore to the low and high faces of ``axis``, m.

    .. math:: L_{lo} = \max(x_i - x_{lo},\ R_i/4), \qquad L_{hi} = \max(x_{hi} - x_i,\ R_i/4),

    with :math:`x_i` the pore centre along the axis, :math:`x_{lo}, x_{hi}` the faces of the image
    box (``net.origin`` and ``net.origin + net.extent``) and :math:`R_i` the pore radius. The floor
    keeps a finite conductance for a centre on (or, after a deformation, beyond) the face. Only the
    entries of pores on the corresponding face (``net.inlet(axis)`` / ``net.outlet(axis)``) are used
    by the flow models; the others are returned for convenience.

    Parameters
    ----------
    net : Network
    axis : {'x', 'y', 'z'} or int

    Returns
    -------
    L_lo, L_hi : ndarray of float, shape (Np,)
        m, each >= R / 4 > 0.
    """
    ax = axis_index(axis)
    lo = float(net.origin[ax])
    hi = lo + float(net.extent[ax])
    x = net.pore_coords[:, ax]
    floor = 0.25 * net.pore_radius
    return np.maximum(x - lo, floor), np.maximum(hi - x, floor)


def boundary_resistance(net: Network, axis: str | int) -> tuple[np.ndarray, np.ndarray]:
    """Resistance factors of the boundary conduits to the low and high faces of ``axis``, 1/m³.

    Each is a cylinder of the pore radius over :func:`boundary_conduit_lengths`:
    ``h = 8 L / (pi R^4)``; with viscosity ``mu`` its conductance is ``1 / (mu h)``.

    Returns
    -------
    h_lo, h_hi : ndarray of float, shape (Np,)
        1/m³, finite and positive.
    """
    L_lo, L_hi = boundary_conduit_lengths(net, axis)
    return cylinder_resistance(net.pore_radius, L_lo), cylinder_resistance(net.pore_radius, L_hi)
