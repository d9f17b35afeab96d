r"""Single-phase absolute permeability of a pore network.

Steady incompressible Stokes flow through the network is, conduit by conduit, Hagen–Poiseuille:
the flow from pore :math:`i` to pore :math:`j` is :math:`q_{ij} = g_{ij}(P_i - P_j)` with the
sphere–cylinder–sphere conduit conductance :math:`g_{ij}` of
:func:`porefsi.network.geometry.conduit_conductance`.

Boundary condition ``"conduit"`` (default). Each inlet pore is joined to an inlet reservoir at
:math:`\Delta P` and each outlet pore to an outlet reservoir at 0 by a *boundary conduit*, a
cylinder of the pore radius from the pore centre to the face
(:func:`porefsi.network.geometry.boundary_resistance`, conductance :math:`g^{lo}_i, g^{hi}_i`,
the same conduits as the drainage graph). Mass conservation at every pore,

.. math:: \sum_{j \sim i} g_{ij} (P_i - P_j) + g^{lo}_i (P_i - \Delta P)\,[i \in \mathrm{in}]
          + g^{hi}_i P_i\,[i \in \mathrm{out}] = 0,

is a graph Laplacian plus the Robin (mixed) boundary terms on its diagonal: symmetric positive
definite on every cluster that touches a face. The flow rate is
:math:`Q = \sum_{i \in \mathrm{in}} g^{lo}_i (\Delta P - P_i)`. The modelled flow path then runs
from face to face, the length Darcy's law divides by.

Boundary condition ``"centre"``: :math:`P = \Delta P` on the inlet pores and :math:`P = 0` on the
outlet pores (Dirichlet at the pore centres, eliminated; OpenPNM ``StokesFlow`` with value
boundary conditions on the face pores). The flow path then spans only the distance between the
inlet and outlet pore centres, shorter than the box: on straight tubes it overestimates k by the
ratio of the two lengths (25 % on the extracted bundle of ``tests/test_permeability_bundle.py``).
Kept for comparison with peer codes.

Either way, Darcy's law over the image box gives

.. math:: k = \frac{Q \mu L}{A \Delta P},

with :math:`L` the box length along the flow axis and :math:`A` the box cross-section normal to
it (both from :attr:`Network.extent`, i.e. the image, not the network's bounding box).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from porefsi.errors import ConvergenceError, InputError, NetworkError
from porefsi.image.voxel_image import AXES, axis_index
from porefsi.network.geometry import boundary_resistance, conduit_conductance
from porefsi.network.network import Network
from porefsi.units import MILLIDARCY

__all__ = ["PermeabilityResult", "absolute_permeability", "flow_field", "MILLIDARCY"]

#: Above this many unknowns the "auto" solver uses AMG-preconditioned CG instead of SuperLU.
#: Measured on random 3-D lattices (one core, noisy shared machine): SuperLU 0.08 s vs CG+AMG 0.04 s at
#: 4.9k unknowns, 1.4 s vs 0.2 s at 27k, 80 s vs 0.9 s at 125k (SuperLU fill-in grows fast in 3-D).
_DIRECT_MAX = 5_000


@dataclasses.dataclass(frozen=True, eq=False)
class PermeabilityResult:
    """Absolute permeability along one axis, with the pressure field that gave it.

    Attributes
    ----------
    k_m2 : float
        Permeability, m².
    k_mD : float
        Permeability, millidarcy (1 mD = 9.869233e-16 m²).
    flow_rate : float
        Total volumetric flow rate through the inlet face, m³/s, at ``dp`` and ``viscosity``.
    pressure : ndarray of float, shape (Np,)
        Pore pressures, Pa; NaN for pores excluded from the solve (not on an inlet–outlet cluster).
    axis : str
        'x', 'y' or 'z'.
    length : float
        Box length along the axis, m.
    area : float
        Box cross-section normal to the axis, m².
    n_pores_solved : int
        Pores on clusters that join the inlet to the outlet (face pores included).
    info : dict
        ``boundary`` ('conduit' or 'centre'), ``solver``, ``residual`` (relative 2-norm of the
        solved system), ``flow_rate_in``,
        ``flow_rate_out`` (m³/s), ``mass_balance_error`` (|in - out| / in), ``n_excluded_pores``,
        ``n_excluded_clusters``, ``n_inlet``, ``n_outlet``, ``viscosity``, ``dp``, ``seconds``.
    """

    k_m2: float
    k_mD: float  # noqa: N815 - the unit is mD
    flow_rate: float
    pressure: np.ndarray
    axis: str
    length: float
    area: float
    n_pores_solved: int
    info: dict


def _laplacian(n: int, conns: np.ndarray, g: np.ndarray) -> sp.csr_array:
    i, j = conns[:, 0], conns[:, 1]
    rows = np.concatenate([i, j, i, j])
    cols = np.concatenate([j, i, i, j])
    vals = np.concatenate([-g, -g, g, g])
    return sp.csr_array(sp.coo_array((vals, (rows, cols)), shape=(n, n)))


def _solve_spd(A: sp.csr_array, b: np.ndarray, method: str, rtol: float) -> tuple[np.ndarray, str]:
    if method == "auto":
        method = "direct" if A.shape[0] <= _DIRECT_MAX else "cg"
    if method == "direct":
        return spla.spsolve(sp.csc_array(A), b), "spsolve"
    if method != "cg":
        raise InputError(f"unknown solver {method!r}; use 'auto', 'direct' or 'cg'")
    import pyamg  # noqa: PLC0415 - only the iterative path needs it

    ml = pyamg.smoothed_aggregation_solver(sp.csr_matrix(A), symmetry="symmetric")
    M = ml.aspreconditioner(cycle="V")
    bnorm = float(np.linalg.norm(b))
    history: list[float] = []

    def cb(xk):
        history.append(float(np.linalg.norm(b - A @ xk)) / bnorm)

    x, code = spla.cg(A, b, rtol=rtol, atol=0.0, maxiter=max(200, A.shape[0] // 10), M=M, callback=cb)
    res = float(np.linalg.norm(b - A @ x)) / bnorm
    if code != 0 or res > 10 * rtol:
        raise ConvergenceError(
            f"CG on the pressure system ({A.shape[0]} unknowns) stopped at relative residual {res:.3e} "
            f"(target {rtol:.1e}, code {code}); use solver='direct'",
            history,
        )
    return x, "cg+amg"


def flow_field(net: Network, pressure: np.ndarray, viscosity: float = 1e-3) -> np.ndarray:
    """Flow rate through every throat from ``conns[:, 0]`` to ``conns[:, 1]``, m³/s, shape (Nt,).

    NaN pressures (excluded pores) give NaN rates.
    """
    g = conduit_conductance(net, viscosity)
    P = np.asarray(pressure, dtype=float)
    return g * (P[net.throat_conns[:, 0]] - P[net.throat_conns[:, 1]])


def _solve_centre(net, ax, keep, g, dp, solver, rtol):
    """Dirichlet pressures at the face pore centres; returns (P, q_in, q_out, info)."""
    n_p = net.n_pores
    conns = net.throat_conns
    inlet, outlet = net.inlet(ax), net.outlet(ax)
    fixed = inlet | outlet
    free = keep & ~fixed
    P = np.full(n_p, np.nan)
    P[keep & inlet] = dp
    P[keep & outlet] = 0.0
    t_keep = keep[conns[:, 0]]  # both ends share a cluster
    c, gk = conns[t_keep], g[t_keep]
    info: dict = {"solver": "none", "residual": 0.0}
    if free.any():
        L = _laplacian(n_p, c, gk)
        A = L[free][:, free]
        Pd = np.where(fixed & keep, P, 0.0)
        b = -(L[free][:, fixed & keep] @ Pd[fixed & keep])
        x, info["solver"] = _solve_spd(A, b, solver, rtol)
        bn = float(np.linalg.norm(b))
        info["residual"] = float(np.linalg.norm(b - A @ x)) / bn if bn > 0 else 0.0
        P[free] = x
    q = gk * (P[c[:, 0]] - P[c[:, 1]])  # from conns[:, 0] to conns[:, 1]
    # Flow leaving inlet pores into non-inlet pores; flow entering outlet pores from non-outlet pores.
    in0, in1 = inlet[c[:, 0]], inlet[c[:, 1]]
    out0, out1 = outlet[c[:, 0]], outlet[c[:, 1]]
    q_in = float(q[in0 & ~in1].sum() - q[in1 & ~in0].sum())
    q_out = float(q[out1 & ~out0].sum() - q[out0 & ~out1].sum())
    return P, q_in, q_out, info


def _solve_conduit(net, ax, keep, g, viscosity, dp, solver, rtol):
    """Face pores joined to reservoirs by boundary conduits (Robin rows); returns (P, q_in, q_out, info)."""
    n_p = net.n_pores
    conns = net.throat_conns
    n_k = int(keep.sum())
    idx = np.full(n_p, -1)
    idx[keep] = np.arange(n_k)
    t_keep = keep[conns[:, 0]]  # both ends share a cluster
    h_lo, h_hi = boundary_resistance(net, ax)
    g_lo = np.where(net.inlet(ax), 1.0 / (viscosity * h_lo), 0.0)[keep]
    g_hi = np.where(net.outlet(ax), 1.0 / (viscosity * h_hi), 0.0)[keep]
    A = _laplacian(n_k, idx[conns[t_keep]], g[t_keep]) + sp.diags_array(g_lo + g_hi, format="csr")
    b = g_lo * dp
    x, name = _solve_spd(sp.csr_array(A), b, solver, rtol)
    P = np.full(n_p, np.nan)
    P[keep] = x
    info = {"solver": name, "residual": float(np.linalg.norm(b - A @ x)) / float(np.linalg.norm(b))}
    q_in = float(np.sum(g_lo * (dp - x)))
    q_out = float(np.sum(g_hi * x))
    return P, q_in, q_out, info


def _check_args(viscosity, dp, rtol, boundary) -> None:
    """One-line InputError for a non-positive/non-finite number, ``rtol >= 1`` or an unknown boundary."""
    for label, val in (("viscosity", viscosity), ("dp", dp), ("rtol", rtol)):
        try:
            ok = bool(np.isfinite(val) and val > 0)
        except (TypeError, ValueError):  # not one number (None, a string, a list, ...)
            ok = False
        if not ok:
            raise InputError(f"{label} must be a positive finite number, got {val!r}")
    if rtol >= 1:  # CG would accept its zero start: no flow solved, a meaningless k
        raise InputError(f"rtol is CG's relative residual and must be < 1, got {rtol!r}")
    if boundary not in ("conduit", "centre"):
        raise InputError(f"unknown boundary {boundary!r}; use 'conduit' (default) or 'centre'")


def _flowing_pores(net: Network, ax: int, boundary: str):
    """Pores on clusters joining the two faces of ``ax`` and the cluster counts; NetworkError if none."""
    name = AXES[ax]
    net.require_inlet_outlet(ax)
    inlet, outlet = net.inlet(ax), net.outlet(ax)
    both = np.flatnonzero(inlet & outlet)
    if boundary == "centre" and both.size:
        p = int(both[0])
        raise NetworkError(
            f"{both.size} pore(s) (e.g. pore {p}, radius {net.pore_radius[p]:.3g} m) touch both the "
            f"{name}min and {name}max faces of a box {net.extent[ax]:.3g} m long: with boundary='centre' "
            f"its pressure would be both dp and 0; use boundary='conduit' or a longer image along {name}"
        )
    keep, n_comp, n_keep_comp = net.spanning_clusters(ax)
    if not keep.any():
        raise NetworkError(
            f"no connected path of pores joins the {name}min face to the {name}max face "
            f"({int(inlet.sum())} inlet and {int(outlet.sum())} outlet pores in {n_comp} clusters); "
            f"nothing flows along {name}: choose another --axis or a larger image"
        )
    return keep, n_comp - n_keep_comp


def _result(net, ax, keep, solved, viscosity, dp) -> PermeabilityResult:
    """The :class:`PermeabilityResult` of a solve ``solved = (P, q_in, q_out, info, n_excluded_clusters, t0)``."""
    P, q_in, q_out, info, n_excl, t0 = solved
    length = float(net.extent[ax])
    area = float(np.prod(np.delete(net.extent, ax)))
    k = q_in * viscosity * length / (area * dp)
    info.update(
        flow_rate_in=q_in, flow_rate_out=q_out, mass_balance_error=abs(q_in - q_out) / abs(q_in) if q_in else 0.0,
        n_excluded_pores=int(net.n_pores - keep.sum()), n_excluded_clusters=n_excl,
        n_inlet=int((net.inlet(ax) & keep).sum()), n_outlet=int((net.outlet(ax) & keep).sum()),
        viscosity=float(viscosity), dp=float(dp), seconds=time.perf_counter() - t0,
    )
    P.setflags(write=False)
    return PermeabilityResult(
        k_m2=float(k), k_mD=float(k / MILLIDARCY), flow_rate=q_in, pressure=P, axis=AXES[ax], length=length,
        area=area, n_pores_solved=int(keep.sum()), info=info,
    )


def absolute_permeability(
    net: Network,
    axis: str | int = "x",
    *,
    viscosity: float = 1e-3,
    dp: float = 1.0,
    boundary: str = "conduit",
    solver: str = "auto",
    rtol: float = 1e-12,
) -> PermeabilityResult:
    r"""Absolute permeability of ``net`` along ``axis`` from a steady single-phase pressure solve.

    Parameters
    ----------
    net : Network
    axis : {'x', 'y', 'z'} or int
        Flow axis: inlet pores ``net.inlet(axis)`` (low face, reservoir at :math:`\Delta P`),
        outlet pores ``net.outlet(axis)`` (high face, reservoir at 0).
    viscosity : float
        Dynamic viscosity, Pa·s, > 0. k does not depend on it (it cancels); Q does.
    dp : float
        Pressure drop, Pa, > 0. k does not depend on it; Q and the pressures scale with it.
    boundary : {'conduit', 'centre'}
        'conduit' (default): face pores joined to the reservoirs by boundary conduits to the face;
        'centre': reservoir pressures at the face pore centres (OpenPNM's ``StokesFlow`` with value
        conditions); biased high (module docstring).
    solver : {'auto', 'direct', 'cg'}
        SuperLU, or CG with smoothed-aggregation AMG; 'auto': direct up to 5 000 unknowns.
    rtol : float
        Relative residual required of CG, in (0, 1) (checked for every solver).

    Returns
    -------
    PermeabilityResult

    Raises
    ------
    InputError
        Non-positive, non-finite or non-numeric ``viscosity``/``dp``/``rtol``, unknown axis,
        boundary or solver.
    NetworkError
        No pores on the inlet or outlet face, no cluster joining inlet to outlet, or (with
        ``boundary='centre'`` only) a pore on both faces, whose pressure would be both
        :math:`\Delta P` and 0. With 'conduit' such a pore simply has both boundary conduits.
    ConvergenceError
        CG did not reach ``rtol`` (carries the residual history).

    Notes
    -----
    Clusters that do not touch both faces carry no flow and are left out (NaN pressures), so the
    matrix is SPD. Flow in and out are summed over the inlet and outlet boundary conduits
    ('conduit') or over the throats leaving the inlet and entering the outlet pores ('centre');
    their relative difference is ``info['mass_balance_error']``.

    Examples
    --------
    >>> import numpy as np
    >>> from porefsi.network.network import Network
    >>> net = Network(pore_coords=[[1e-5, 5e-6, 5e-6], [3e-5, 5e-6, 5e-6]], pore_radius=[4e-6, 4e-6],
    ...               pore_volume=[1e-16, 1e-16], throat_conns=[[0, 1]], throat_radius=[2e-6],
    ...               throat_length=[1e-5], throat_pore_length=[[5e-6, 5e-6]],
    ...               pore_faces=[[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0]], voxel_size=1e-6,
    ...               shape=(40, 10, 10))
    >>> res = absolute_permeability(net, "x")
    >>> bool(res.k_m2 > 0), res.n_pores_solved, res.info["boundary"]
    (True, 2, 'conduit')
    >>> bool(absolute_permeability(net, "x", boundary="centre").k_m2 > res.k_m2)
    True
    """
    t0 = time.perf_counter()
    ax = axis_index(axis)
    _check_args(viscosity, dp, rtol, boundary)
    keep, n_excl = _flowing_pores(net, ax, boundary)
    g = conduit_conductance(net, viscosity)
    if boundary == "conduit":
        P, q_in, q_out, info = _solve_conduit(net, ax, keep, g, viscosity, dp, solver, rtol)
    else:
        P, q_in, q_out, info = _solve_centre(net, ax, keep, g, dp, solver, rtol)
    info = {"boundary": boundary, **info}
    return _result(net, ax, keep, (P, q_in, q_out, info, n_excl, t0), viscosity, dp)
