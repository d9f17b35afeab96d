r"""Closed-form conduit geometry: hydraulic resistances of the pore–throat–pore conduit.

Two conduit models (:attr:`Network.conduit_model <porefsi.network.network.Network.conduit_model>`),
one switch used by every flow computation (permeability, drainage graph, invasion percolation,
the coupled run):

``"paper"``
    The seed paper's sphere–cylinder–sphere conduit: a circular cylinder of the inscribed throat
    radius between two spherical pore parts (:func:`sphere_segment_resistance`).
``"shape_factor"``
    Valvatne & Blunt (2004) / Patzek & Silin (2001): every segment is a straight duct whose section
    is a triangle, a square or a circle, chosen by its shape factor G = A/P² (:func:`shape_class`),
    of area ``A = r² / (4 G)`` (r the inscribed radius), with single-phase conductance per unit
    length ``k G A² / mu`` (:func:`tangential_conductance_factor`); a section of G below the
    equilateral triangle's takes the geometric mean of that and the rectangle of the same r and A
    (:func:`duct_conductance_factor`).

A throat conduit is three segments in series (pore-i part, cylinder, pore-j part). Each segment
has a *hydraulic resistance factor* ``h`` (1/m³) such that, for a fluid of viscosity ``mu`` in
that segment, its resistance to volumetric flow is ``mu * h`` (Pa·s/m³). The conduit
conductance is then

.. math:: g = \frac{1}{\mu_i h_i + \mu_t h_t + \mu_j h_j}

which is also how segments holding different fluids combine (in series, never in parallel;
the seed paper's eq. 2.6 writes a parallel sum, see ``docs/theory.md``).

A pore on a face of the image box is joined to that face (a reservoir) by a *boundary conduit*
running from the pore centre to the face (:func:`boundary_conduit_lengths`,
:func:`boundary_resistance`): a cylinder of the pore radius (``"paper"``), or a duct of the pore's
section in series with a duct of the section the face cuts through the pore (``"shape_factor"``).
Single-phase permeability and the drainage graph use the same definition.
"""

from __future__ import annotations

import numpy as np

from porefsi.image.voxel_image import axis_index
from porefsi.network.network import CIRCLE_SHAPE_FACTOR, Network

__all__ = [
    "TRIANGLE_MAX_G",
    "SQUARE_MAX_G",
    "SHAPE_K",
    "shape_class",
    "class_shape_factor",
    "duct_conductance_factor",
    "tangential_conductance_factor",
    "rectangle_conductance_factor",
    "duct_lengths",
    "cylinder_resistance",
    "sphere_segment_resistance",
    "resistance_factors",
    "conduit_conductance",
    "boundary_conduit_lengths",
    "boundary_resistance",
    "pore_duct_resistance",
]


#: Largest shape factor of a triangle (the equilateral one), sqrt(3)/36.
TRIANGLE_MAX_G = float(np.sqrt(3.0) / 36.0)

#: Shape factors below this (and above :data:`TRIANGLE_MAX_G`) are squares, above it circles: the
#: bound pnflow uses (``Element.cpp``), between the square's 1/16 and the circle's 1/(4 pi).
SQUARE_MAX_G = 0.07

#: Dimensionless conductance ``k`` of :math:`g = k G A^2 / \mu` per class (triangle, square,
#: circle): Patzek & Silin (2001) give 3/5 for the equilateral triangle (exact), 0.5623 for the
#: square (series solution) and 1/2 for the circle (Hagen–Poiseuille).
SHAPE_K = (0.6, 0.5623, 0.5)


def shape_class(shape_factor) -> np.ndarray:
    """Section class of each shape factor: 0 triangle, 1 square, 2 circle (int8 array).

    Triangle: ``G <= sqrt(3)/36`` (:data:`TRIANGLE_MAX_G`, with 1e-9 relative slack so the
    equilateral triangle's own value is one); square: ``G < 0.07`` (:data:`SQUARE_MAX_G`); circle
    above. As pnflow's ``Elem`` constructor.
    """
    G = np.asarray(shape_factor, dtype=float)
    out = np.full(G.shape, 2, dtype=np.int8)
    out[G < SQUARE_MAX_G] = 1
    out[G <= TRIANGLE_MAX_G * (1 + 1e-9)] = 0
    return out


def class_shape_factor(shape_factor) -> np.ndarray:
    """Shape factor the conduit model uses: G for triangles, 1/16 for squares, 1/(4 pi) for circles.

    pnflow models a square or circle element as the regular shape itself, whatever G it was given.
    """
    G = np.asarray(shape_factor, dtype=float)
    cls = shape_class(G)
    return np.where(cls == 0, G, np.where(cls == 1, 1.0 / 16.0, CIRCLE_SHAPE_FACTOR))


def rectangle_conductance_factor(short_side, long_side, n_terms: int = 20) -> np.ndarray:
    r"""Exact Poiseuille conductance per unit length times viscosity of an a × b rectangle, m⁴.

    .. math:: g\mu = \frac{a^3 b}{12}\left[1 - \frac{192\,a}{\pi^5 b}
              \sum_{n\ \mathrm{odd}} \frac{\tanh(n \pi b / 2a)}{n^5}\right], \quad a \le b

    (the series solution; ``n_terms`` odd terms, relative truncation error below 1e-6 for 20).
    The square's value is :math:`0.035144\,a^4` = Patzek & Silin's :math:`0.5623\,G A^2`.

    Parameters
    ----------
    short_side, long_side : array_like of float
        a <= b, m.
    """
    a = np.asarray(short_side, dtype=float)
    b = np.asarray(long_side, dtype=float)
    acc = np.zeros(np.broadcast(a, b).shape)
    for n in range(1, 2 * n_terms, 2):
        acc = acc + np.tanh(n * np.pi * b / (2.0 * a)) / n**5
    return a**3 * b / 12.0 * (1.0 - 192.0 * a / (np.pi**5 * b) * acc)


def tangential_conductance_factor(radius, shape_factor) -> np.ndarray:
    r"""Valvatne–Blunt duct conductance per unit length times viscosity, ``k G_c A^2``, m⁴.

    With inscribed radius r and the class shape factor :math:`G_c` (:func:`class_shape_factor`)
    the section area is :math:`A = r^2/(4G_c)`, so :math:`k G_c A^2 = k r^4 / (16 G_c)`: exact for
    the equilateral triangle, the square and the circle (Hagen–Poiseuille's :math:`\pi r^4 / 8`),
    i.e. for sections whose every side touches the inscribed circle.
    """
    r = np.asarray(radius, dtype=float)
    G = np.asarray(shape_factor, dtype=float)
    k = np.asarray(SHAPE_K)[shape_class(G)]
    Gc = class_shape_factor(G)
    return k * r**4 / (16.0 * Gc)


def duct_conductance_factor(radius, shape_factor) -> np.ndarray:
    r"""Conductance per unit length times viscosity of a straight duct of the measured section, m⁴.

    The section is known by its inscribed radius r and area :math:`A = r^2 / (4G)`. Down to the
    equilateral triangle's shape factor (:data:`TRIANGLE_MAX_G`; :math:`A \le 3\sqrt3\, r^2`) it is
    Valvatne & Blunt's :func:`tangential_conductance_factor`, exact for the circle, the square and
    the equilateral triangle. A section of smaller G is none of these: its r and A are shared by a
    triangle whose every side touches the inscribed circle (the Valvatne–Blunt law, 0.45–0.51× the
    exact flow of a slit) and by a rectangle :math:`2r \times A/(2r)` (:func:`rectangle_conductance_factor`,
    exact for slits, above the triangle law by 16 % at the equilateral triangle's G and by 2–2.2× for
    slits), which the pair cannot tell apart. The duct takes their geometric mean, the estimate
    whose worst ratio to either shape is smallest:

    .. math:: g\mu = \sqrt{g_{VB}\, g_{rect}}, \qquad G < \sqrt3/36.

    It is a duct of length L's resistance factor ``L / g`` (1/m³).

    Parameters
    ----------
    radius : array_like of float
        Inscribed radius r, m.
    shape_factor : array_like of float
        Measured G = A/P², in (0, 1/(4 pi)].

    Returns
    -------
    ndarray of float
        m⁴.
    """
    r = np.asarray(radius, dtype=float)
    G = np.asarray(shape_factor, dtype=float)
    vb = tangential_conductance_factor(r, G)
    elongated = G < TRIANGLE_MAX_G * (1 - 1e-9)
    if not np.any(elongated):
        return vb
    long_side = r / (8.0 * G)  # A / (2 r), > 3 sqrt(3) r / 2 where elongated
    rect = rectangle_conductance_factor(2.0 * r, np.maximum(long_side, 2.0 * r))
    return np.where(elongated, np.sqrt(vb * rect), vb)


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


def duct_lengths(net: Network) -> np.ndarray:
    """Lengths of the pore-i, throat and pore-j ducts of the shape-factor model, m, shape (Nt, 3).

    ``throat_duct_fraction`` times the conduit's pore-to-pore length when the network has it,
    else the stored ``throat_pore_length[:, 0]``, ``throat_length``, ``throat_pore_length[:, 1]``.
    """
    tpl = net.throat_pore_length
    L = np.column_stack([tpl[:, 0], net.throat_length, tpl[:, 1]])
    if net.throat_duct_fraction is None:
        return L
    return net.throat_duct_fraction * L.sum(axis=1, keepdims=True)


def resistance_factors(net: Network) -> np.ndarray:
    """Resistance factors of the three segments of every conduit, 1/m³, shape (Nt, 3).

    Columns: pore ``conns[:, 0]`` part, throat, pore ``conns[:, 1]`` part, under the network's
    conduit model (:attr:`Network.conduit_model`): sphere parts and a cylinder (``"paper"``), or
    three ducts of the pore, throat and pore sections (``"shape_factor"``: lengths
    ``throat_pore_length[:, 0]``, ``throat_length``, ``throat_pore_length[:, 1]`` over
    :func:`duct_conductance_factor` of the pore radius and pore shape factor, the throat's, ...).
    """
    c = net.throat_conns
    rt = net.throat_radius
    h = np.empty((net.n_throats, 3))
    if net.conduit_model == "shape_factor":
        L = duct_lengths(net)
        Rp, Gp = net.pore_radius, net.pore_shape_factor
        h[:, 0] = L[:, 0] / duct_conductance_factor(Rp[c[:, 0]], Gp[c[:, 0]])
        h[:, 1] = L[:, 1] / duct_conductance_factor(rt, net.throat_shape_factor)
        h[:, 2] = L[:, 2] / duct_conductance_factor(Rp[c[:, 1]], Gp[c[:, 1]])
        return h
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
    r"""Resistance factors of the boundary conduits to the low and high faces of ``axis``, 1/m³.

    Over the length :math:`L` of :func:`boundary_conduit_lengths`:

    * ``"paper"``: a cylinder of the pore radius, ``h = 8 L / (pi R^4)``;
    * ``"shape_factor"`` with the face cuts' sections (:attr:`Network.has_face_sections`): a duct of
      the pore's section and a duct of the *face cut's* section (the section of the pore region
      the face shows: radius :math:`r_f = \min(` ``pore_face_radius``, R), shape factor
      ``pore_face_shape_factor``) in series, the face-cut duct taking the share ``f`` =
      ``pore_face_duct_fraction`` of L (its resistance-equivalent constriction length, measured as
      for the throats):

      .. math:: h = \frac{(1 - f) L}{k G_p A_p^2} + \frac{f L}{k G_f A_f^2};

      a pore cut through a narrow neck joins the reservoir through that neck, a straight channel
      crossing the face (:math:`r_f = R`) through its own section;
    * ``"shape_factor"`` without them (older files): ``L / duct_conductance_factor(R, G_p)``.

    With viscosity ``mu`` the conductance is ``1 / (mu h)``. Single-phase permeability and the
    drainage graph both use this.

    Returns
    -------
    h_lo, h_hi : ndarray of float, shape (Np,)
        1/m³, finite and positive.
    """
    ax = axis_index(axis)
    L_lo, L_hi = boundary_conduit_lengths(net, ax)
    h_lo, h_hi = pore_duct_resistance(net, L_lo), pore_duct_resistance(net, L_hi)
    if net.conduit_model != "shape_factor" or not net.has_face_sections:
        return h_lo, h_hi
    out = []
    for h, L, col in ((h_lo, L_lo, 2 * ax), (h_hi, L_hi, 2 * ax + 1)):
        on = np.flatnonzero(net.pore_faces[:, col])
        f = net.pore_face_duct_fraction[on, col]
        rf = np.minimum(net.pore_face_radius[on, col], net.pore_radius[on])
        h = h.copy()
        h[on] = (1.0 - f) * h[on] + f * L[on] / duct_conductance_factor(rf, net.pore_face_shape_factor[on, col])
        out.append(h)
    return out[0], out[1]


def pore_duct_resistance(net: Network, length, pores=None) -> np.ndarray:
    """Resistance factor (1/m³) of a duct of each pore's own section over ``length`` (m).

    ``pores`` (indices) selects pores, ``length`` then has one entry per selected pore. A cylinder
    of the pore radius for ``"paper"``, the pore's shape-factor duct for ``"shape_factor"``.
    """
    idx = slice(None) if pores is None else np.asarray(pores, dtype=np.int64)
    R = net.pore_radius[idx]
    if net.conduit_model == "shape_factor":
        return np.asarray(length, dtype=float) / duct_conductance_factor(R, net.pore_shape_factor[idx])
    return cylinder_resistance(R, length)
