r"""Permeability of a segmented image from a voxel-scale Stokes solve.

This is the reference porefsi's network models answer to.

Steady incompressible Stokes flow, :math:`\mu \nabla^2 \mathbf u = \nabla p`,
:math:`\nabla \cdot \mathbf u = 0`, on the pore voxels, no slip on the voxel faces of the solid,
discretised on the staggered voxel grid of :mod:`porefsi.stokes._grid` and solved by
block-preconditioned MINRES (:mod:`porefsi.stokes._solve`). Two boundary conditions:

``boundary="pressure"`` (default)
    ``buffer`` all-fluid layers are added before and after the image along the flow axis and
    their outer faces held at two pressures (reservoirs); the side faces are no-slip walls
    (``lateral="wall"``) or periodic. The pressure drop :math:`\Delta P` Darcy's law divides by is
    the drop between the two image faces: each face's pressure is the linear extrapolation, to the
    face, of the mean pressures of the two buffer layers next to it (with ``buffer=0``, the
    reservoir pressures themselves, applied on the image faces).
``boundary="periodic"``
    The flow axis wraps around (``mirror=True`` first appends the image's mirror image along the
    axis, so any image becomes periodic) and a uniform body force :math:`G` (a mean pressure
    gradient) drives the flow; :math:`\Delta P = G L`.

Either way, Darcy's law over the image box,

.. math:: k = \frac{Q \mu L}{A \, \Delta P},

with :math:`Q` the flow rate through any cross-section (they agree to the solver tolerance; their
relative spread is reported), :math:`L` the image length along the axis and :math:`A` the image
box cross-section (pore and solid), both from the image (buffers and mirror copies excluded).
"""

from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from porefsi.errors import ConvergenceError, InputError
from porefsi.image.voxel_image import AXES, VoxelImage, axis_index
from porefsi.stokes._domain import flowing_clusters, mirrored, with_buffers
from porefsi.stokes._grid import WALLS as _WALLS
from porefsi.stokes._grid import StaggeredSystem, assemble, with_neighbours
from porefsi.stokes._refine_grid import check_refine, check_refined_memory, pore_faces, upsample_mask
from porefsi.stokes._solve import log as _solve_log
from porefsi.stokes._solve import pressure_preconditioner, solve
from porefsi.units import MILLIDARCY

__all__ = ["StokesResult", "StokesOptions", "stokes_options", "voxel_permeability", "plane_fluxes"]

BOUNDARIES = ("pressure", "periodic")
LATERALS = ("wall", "periodic")
#: Tangential wall closures (:mod:`porefsi.stokes._grid`).
WALLS = tuple(_WALLS)
#: The closure :func:`voxel_permeability` uses unless told.
DEFAULT_WALL = "channel"
#: The true relative residual may exceed rtol (MINRES stops on the preconditioned one) by at most
#: this factor; measured 1.0-1.3 on every image in docs/stokes.md.
TRUE_RESIDUAL_FACTOR = 100.0


@dataclasses.dataclass(frozen=True, eq=False)
class StokesResult:
    r"""Permeability from a voxel Stokes solve, with its convergence report.

    Attributes
    ----------
    k_m2, k_mD : float
        Permeability along ``axis``, m² and millidarcy (1 mD = 9.869233e-16 m²).
    axis : str
        'x', 'y' or 'z' (array axes 0, 1, 2).
    flow_rate : float
        Volumetric flow rate Q through a cross-section, m³/s, at ``dp`` and ``viscosity``.
    dp : float
        Pressure drop across the image box along the axis, Pa.
    viscosity : float
        Dynamic viscosity, Pa s.
    length, area : float
        Image box length along the axis (m) and cross-section normal to it (m²).
    boundary : str
        'pressure' or 'periodic'.
    iterations : int
        MINRES iterations.
    residual : float
        Final relative residual :math:`\|b - Kx\|/\|b\|` of the saddle-point system.
    flux_spread : float
        (max - min) / mean of the flow rate over every cross-section of the working domain
        (mass conservation; ~ the solver tolerance).
    converged : bool
        Whether MINRES reached ``rtol``.
    seconds : float
        Wall time of the whole call, s.
    memory_bytes : int
        Estimate of the solver's working memory: matrices, preconditioner, Krylov vectors.
    n_unknowns : int
        Velocity plus pressure unknowns.
    porosity, connected_porosity : float
        Pore fraction of the image, and of the flow-carrying clusters kept for the solve.
    info : dict
        Details: buffer layers, wall seconds for the set-up (clusters, tables, preconditioner) and the
        iterations, CPU seconds, preconditioned residual history.
    pressure : ndarray of float, shape (nx, ny, nz), or None
        With ``fields=True``: pressure at the pore voxel centres, Pa, NaN in solid and removed
        voxels (periodic boundary: the periodic part, without the mean gradient).
    velocity : ndarray of float, shape (nx, ny, nz, 3), or None
        With ``fields=True``: voxel-centred velocity (mean of the two face values per component), m/s.
    """

    k_m2: float
    k_mD: float  # noqa: N815 - the unit is mD
    axis: str
    flow_rate: float
    dp: float
    viscosity: float
    length: float
    area: float
    boundary: str
    iterations: int
    residual: float
    flux_spread: float
    converged: bool
    seconds: float
    memory_bytes: int
    n_unknowns: int
    porosity: float
    connected_porosity: float
    info: dict
    pressure: np.ndarray | None = None
    velocity: np.ndarray | None = None


def plane_fluxes(system: StaggeredSystem, u: np.ndarray, axis: int) -> np.ndarray:
    """Flow rate (voxel units) through every face plane normal to ``axis``, shape (n_planes,)."""
    off = system.offsets
    return np.bincount(system.face_plane(axis), weights=u[off[axis]:off[axis + 1]],
                       minlength=system.n_planes[axis])


@dataclasses.dataclass(frozen=True)
class StokesOptions:
    """How :func:`voxel_permeability` solves (validated on construction).

    Attributes
    ----------
    boundary : {'pressure', 'periodic'}
        Reservoirs at two pressures beyond ``buffer`` fluid layers, or periodic with a body force
        (see the module notes).
    buffer : int, default 2
        Fluid layers added at each end (``boundary='pressure'`` only).
    lateral : {'wall', 'periodic'}
        The four box faces parallel to the flow: no-slip walls, or periodic.
    mirror : bool, default False
        ``boundary='periodic'``: append the image's mirror image along the axis first (needed for
        an image that is not periodic itself).
    wall : {'ghost', 'channel'}
        Tangential no-slip closure (:mod:`porefsi.stokes._grid`): ``'ghost'`` reflection
        (u_ghost = -u), or ``'channel'``, exact for cell-averaged plane Poiseuille flow in channels
        of any width in voxels.
    viscosity : float, default 1e-3
        Dynamic viscosity, Pa s (k does not depend on it; Q does).
    dp : float, default 1.0
        Pressure drop across the image box, Pa (k does not depend on it; Q does).
    rtol : float, default 1e-6
        Relative reduction of the preconditioned residual at which MINRES stops.
    maxiter : int, default 3000
        Iteration limit.
    fields : bool, default False
        Also return the pressure and voxel-centred velocity fields (on the refined grid if
        ``refine > 1``).
    refine : int, default 1
        Solve on the image refined ``refine`` times: every voxel split into ``refine**3`` voxels of
        edge ``voxel_size / refine`` (the same staircase, a finer grid; the buffers keep their
        thickness, ``buffer * refine`` refined layers). k converges with it to the exact flow
        through the voxel staircase; :func:`porefsi.stokes.extrapolated_permeability` extrapolates.
    max_memory : float, optional
        ``refine > 1``: memory budget, bytes (default: the address-space limit or the available
        memory, whichever is smaller); the estimate is checked before anything is allocated.
    """

    boundary: str = "pressure"
    buffer: int = 2
    lateral: str = "wall"
    mirror: bool = False
    wall: str = DEFAULT_WALL
    viscosity: float = 1e-3
    dp: float = 1.0
    rtol: float = 1e-6
    maxiter: int = 3000
    fields: bool = False
    refine: int = 1
    max_memory: float | None = None

    def __post_init__(self):
        _check_choices(self)
        _check_numbers(self)

    @property
    def buffer_layers(self) -> int:
        """Buffer layers actually added (0 with a periodic boundary), native voxels."""
        return self.buffer if self.boundary == "pressure" else 0


def _check_choices(o: StokesOptions) -> None:
    for name, value, allowed in (("boundary", o.boundary, BOUNDARIES), ("lateral boundary", o.lateral, LATERALS),
                                 ("wall closure", o.wall, WALLS)):
        if value not in allowed:
            raise InputError(f"unknown {name} {value!r}; use one of {tuple(allowed)}")
    if isinstance(o.buffer, bool) or not isinstance(o.buffer, (int, np.integer)) or o.buffer < 0:
        raise InputError(f"buffer must be a whole number of voxel layers >= 0, got {o.buffer!r}")
    check_refine(o.refine)


def _check_numbers(o: StokesOptions) -> None:
    for name, v in (("viscosity", o.viscosity), ("dp", o.dp), ("rtol", o.rtol)):
        if not (isinstance(v, (int, float, np.floating, np.integer)) and np.isfinite(v) and v > 0):
            raise InputError(f"{name} must be a positive number, got {v!r}")
    if o.rtol >= 1:
        raise InputError(f"rtol must be below 1 (a relative residual reduction), got {o.rtol!r}")
    if isinstance(o.maxiter, bool) or not isinstance(o.maxiter, (int, np.integer)) or o.maxiter < 1:
        raise InputError(f"maxiter must be a positive whole number, got {o.maxiter!r}")


def stokes_options(options: StokesOptions | None = None, **overrides) -> StokesOptions:
    """``options`` (default :class:`StokesOptions()`) with ``overrides`` replaced; unknown names are an InputError."""
    base = StokesOptions() if options is None else options
    if not isinstance(base, StokesOptions):
        raise InputError(f"options must be a StokesOptions, got {type(base).__name__}")
    unknown = sorted(set(overrides) - {f.name for f in dataclasses.fields(StokesOptions)})
    if unknown:
        raise InputError(f"unknown voxel_permeability option(s) {', '.join(unknown)}; see porefsi.stokes.StokesOptions")
    return dataclasses.replace(base, **overrides) if overrides else base


@dataclasses.dataclass(frozen=True)
class _Frame:
    """Where the image sits in the working domain and its scales (voxel units of the solved grid)."""

    axis: int
    boundary: str
    buffer: int  # refined buffer layers
    length: int  # image layers along the axis
    area: float  # image cross-section, voxels
    h: float  # solved voxel edge, m
    shape: tuple  # the (refined) image's shape


def voxel_permeability(image: VoxelImage, axis="x", options: StokesOptions | None = None,
                       **overrides) -> StokesResult:
    """Permeability of ``image`` along ``axis`` by a voxel-scale Stokes solve.

    Parameters
    ----------
    image : VoxelImage
        Segmented image, 1 = pore. Only the face-connected pore clusters touching both faces
        normal to ``axis`` are kept (the others carry no net flow).
    axis : {'x', 'y', 'z', 0, 1, 2}
        Flow axis.
    options : StokesOptions, optional
        How to solve (boundary, buffer, lateral, mirror, wall, viscosity, dp, rtol, maxiter,
        fields, refine, max_memory; see :class:`StokesOptions`).
    **overrides
        Any field of :class:`StokesOptions` by name, replacing the one in ``options``.

    Returns
    -------
    StokesResult

    Raises
    ------
    InputError
        Bad parameters, or a refined grid whose memory estimate exceeds ``max_memory``.
    NetworkError
        No face-connected pore path along ``axis``.
    ConvergenceError
        MINRES did not reach ``rtol`` in ``maxiter`` iterations, or the true residual is more than
        100 times ``rtol``.

    Examples
    --------
    >>> import numpy as np
    >>> from porefsi.image import VoxelImage
    >>> a = np.zeros((4, 6, 6), np.uint8); a[:, 1:5, 1:5] = 1   # a square duct 4 voxels wide, in a 6^2 box
    >>> img = VoxelImage(a, 1e-6)
    >>> r = voxel_permeability(img, "x", boundary="periodic", wall="ghost")
    >>> round(r.k_m2 / 1e-12, 4)   # White's series: 0.2499 (Q = 0.5623 (w/2)^4 G / mu over 36 um^2); +22 % at 4 voxels
    0.3056
    >>> round(voxel_permeability(img, "x", boundary="periodic", wall="channel").k_m2 / 1e-12, 4)   # +6 %
    0.266
    >>> r.flux_spread < 1e-5, r.converged
    (True, True)
    """
    t_start, c_start = time.perf_counter(), time.process_time()
    if not isinstance(image, VoxelImage):
        raise InputError(f"expected a VoxelImage, got {type(image).__name__}; read one with porefsi.read_image")
    opts = stokes_options(options, **overrides)
    ax = axis_index(axis)
    if opts.refine > 1:
        check_refined_memory(image.shape, int(np.count_nonzero(image.pore)), opts.refine, ax, opts.buffer_layers,
                             opts.max_memory, n_faces=pore_faces(image.pore))
    system, frame, (connected, n_clusters) = _build_system(image, ax, opts)
    ml = pressure_preconditioner(system)  # before the neighbour table: lower peak memory
    system = with_neighbours(system)
    t_setup = time.perf_counter() - t_start
    u, p, sinfo = solve(system, rtol=opts.rtol, maxiter=opts.maxiter, preconditioner=ml,
                        monitor=_progress(system, frame))
    del ml
    _check_converged(sinfo, ax, opts)
    q = plane_fluxes(system, u, ax)
    dp_vox = _face_pressure_drop(system, p, frame) if opts.boundary == "pressure" else float(frame.length)
    res = _result(opts, frame, (q, dp_vox), sinfo, dict(
        axis=AXES[ax], n_unknowns=system.n_u + system.n_p, porosity=image.porosity, connected_porosity=connected,
        info={"buffer": opts.buffer_layers, "refine": opts.refine, "mirror": bool(opts.mirror),
              "lateral": opts.lateral, "wall": opts.wall, "n_clusters": n_clusters,
              "seconds_setup": t_setup + sinfo.seconds_setup,
              "seconds_solve": sinfo.seconds_solve, "cpu_seconds": time.process_time() - c_start,
              "history": sinfo.history},
        seconds=time.perf_counter() - t_start))
    if opts.fields:
        scale = opts.dp / dp_vox  # voxel-unit pressure -> Pa
        pf, vf = _fields(system, (u, p), frame, (scale, frame.h / opts.viscosity * scale))
        res = dataclasses.replace(res, pressure=pf, velocity=vf)
    return res


def _result(opts: StokesOptions, frame: _Frame, flow, sinfo, rest: dict) -> StokesResult:
    """The :class:`StokesResult` of plane fluxes and face pressure drop ``flow`` = (q, dp), voxel units."""
    q, dp_vox = flow
    q_mean = float(q.mean())
    k = q_mean * frame.length / (frame.area * dp_vox) * frame.h**2
    scale = opts.dp / dp_vox  # voxel-unit pressure -> Pa
    return StokesResult(
        k_m2=float(k), k_mD=float(k / MILLIDARCY), flow_rate=float(q_mean * scale * frame.h**3 / opts.viscosity),
        dp=float(opts.dp), viscosity=float(opts.viscosity), length=frame.length * frame.h,
        area=frame.area * frame.h**2, boundary=opts.boundary, iterations=sinfo.iterations, residual=sinfo.residual,
        flux_spread=float((q.max() - q.min()) / abs(q_mean)) if q_mean else float("inf"),
        converged=sinfo.converged, memory_bytes=int(sinfo.memory_bytes), **rest)


def _build_system(image: VoxelImage, ax: int, opts: StokesOptions):
    """The coupling tables (no neighbour table yet) of the working domain, its frame and the clusters kept.

    Returns ``(system, frame, (connected porosity, number of clusters))``; the working domain is the
    flowing clusters, refined, with buffers or a mirror copy added.
    """
    periodic = [opts.lateral == "periodic"] * 3
    periodic[ax] = opts.boundary == "periodic"
    kept, n_clusters = flowing_clusters(image.pore, ax, periodic)
    connected = float(kept.mean())
    f = opts.refine
    kept = upsample_mask(kept, f)  # face connectivity is unchanged by the refinement
    frame = _Frame(ax, opts.boundary, opts.buffer_layers * f, kept.shape[ax], kept.size / kept.shape[ax],
                   image.voxel_size / f, kept.shape)
    if opts.boundary == "pressure":
        work = with_buffers(kept, ax, frame.buffer)
        del kept
        system = assemble(work, periodic=periodic, open_axis=ax, pressures=(float(work.shape[ax]), 0.0),
                          wall=opts.wall, neighbours=False)
    else:
        if not np.any(~kept) and opts.lateral == "periodic":
            raise InputError("an all-pore periodic box has no wall: the flow is unbounded; add solid")
        work = mirrored(kept, ax) if opts.mirror else kept
        del kept
        system = assemble(work, periodic=periodic, body_axis=ax, body_force=1.0, wall=opts.wall, neighbours=False)
    return system, frame, (connected, n_clusters)


def _check_converged(sinfo, ax: int, opts: StokesOptions) -> None:
    if not sinfo.converged:
        raise ConvergenceError(
            f"voxel Stokes solve along {AXES[ax]} did not converge in {opts.maxiter} MINRES iterations "
            f"(relative residual {sinfo.history[-1]:.2e} > rtol {opts.rtol:g}); raise maxiter or rtol",
            history=sinfo.history,
        )
    if not sinfo.residual <= TRUE_RESIDUAL_FACTOR * opts.rtol:
        raise ConvergenceError(
            f"voxel Stokes solve along {AXES[ax]}: the preconditioned residual reached rtol {opts.rtol:g} but the "
            f"true relative residual is {sinfo.residual:.2e} (a preconditioner defect); report this with the image",
            history=sinfo.history,
        )


def _progress(system, frame: _Frame):
    """A :func:`._solve.solve` monitor that logs the residual and the k (mD) of the current iterate.

    None when INFO logging of :mod:`._solve` is off (no flux is computed then).
    """
    if not _solve_log.isEnabledFor(logging.INFO):
        return None
    n = frame.length

    def monitor(it, res, x):
        q = float(plane_fluxes(system, x[:system.n_u], frame.axis).mean())
        dp_vox = _face_pressure_drop(system, x[system.n_u:], frame) if frame.boundary == "pressure" else float(n)
        k = q * n / (frame.area * dp_vox) * frame.h**2 / MILLIDARCY if dp_vox else float("nan")
        _solve_log.info("MINRES iteration %d: relative preconditioned residual %.3e, k of the iterate %.2f mD",
                        it, res, k)
    return monitor


def _layer_mean(system, p, ax, i):
    layer = np.unravel_index(system.pressure_cell, system.shape)[ax] == i
    return float(p[layer].mean())


def _face_pressure_drop(system: StaggeredSystem, p, frame: _Frame) -> float:
    """Pressure drop between the two image faces (voxel units): see the module notes."""
    ax, buffer = frame.axis, frame.buffer
    N = system.shape[ax]
    p_in, p_out = float(N), 0.0
    if buffer == 0:
        return p_in - p_out
    if buffer == 1:
        a, b = _layer_mean(system, p, ax, 0), _layer_mean(system, p, ax, N - 1)
        return (2 * a - p_in) - (2 * b - p_out)
    a1, a2 = _layer_mean(system, p, ax, buffer - 1), _layer_mean(system, p, ax, buffer - 2)
    b1, b2 = _layer_mean(system, p, ax, N - buffer), _layer_mean(system, p, ax, N - buffer + 1)
    return (a1 + 0.5 * (a1 - a2)) - (b1 + 0.5 * (b1 - b2))


def _fields(system, x, frame: _Frame, scales):
    """Pressure (Pa) and voxel-centred velocity (m/s) on the image's voxels.

    ``x`` = (u, p) in voxel units; ``scales`` = (pressure scale, velocity scale) to SI.
    """
    (u, p), (p_scale, u_scale), ax, shape = x, scales, frame.axis, frame.shape
    lo = frame.buffer
    sl = [slice(None)] * 3
    sl[ax] = slice(lo, lo + shape[ax])
    sl = tuple(sl)
    pw = np.full(system.shape, np.nan)
    pw.reshape(-1)[system.pressure_cell] = p * p_scale
    vf = np.zeros(shape + (3,))
    off = system.offsets
    for d in range(3):
        vals = np.zeros(system.plane_shape(d))
        vals.reshape(-1)[system.face_cells(d)] = u[off[d]:off[d + 1]]
        n_d = system.shape[d]
        lower = np.take(vals, np.arange(n_d), axis=d)
        upper = np.take(vals, (np.arange(n_d) + 1) % vals.shape[d], axis=d)
        vf[..., d] = (0.5 * (lower + upper))[sl] * u_scale
    pf = pw[sl]
    vf[np.isnan(pf)] = 0.0
    return np.ascontiguousarray(pf), vf
