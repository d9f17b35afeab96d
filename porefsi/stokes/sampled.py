r"""Sampled defect correction: a solution-verified voxel permeability for images whose refinement does not fit.

Refining a whole image ``f`` times multiplies the unknowns by :math:`f^3` (the 400³ Berea at
``f = 2`` needs ~70 GiB), so :func:`porefsi.stokes.extrapolated_permeability` fits crops only. The
sampled estimate solves the whole image once at its own resolution, :math:`k_1`, and measures the
discretisation error on :math:`K` sub-blocks that do fit:

1. **Blocks** (:func:`choose_blocks`): cubes of side ``b`` centred in the cells of an
   :math:`m \times m \times m` grid over the image (a stratified systematic sample),
   :math:`m = \lceil K^{1/3} \rceil`, kept if a face-connected pore path crosses the block along
   the flow axis; if fewer than :math:`K` flow, :math:`m` grows by one (up to the lattice that
   tiles the image with blocks). The first :math:`K` flowing candidates in design order (by
   :math:`(i + j + k) \bmod m` of the cell indices, then lexicographic: a Latin-square design that
   spreads any leading subset over all three axes) are solved. Deterministic: the same image,
   axis, ``K`` and ``b`` give the same blocks.
2. **Levels**: every block is solved refined :math:`f = 1, 2, 3` (``levels``) with the same
   options as the whole image (its side faces, cut from the rock, are no-slip walls).
3. **Pooling**: the block permeabilities are summed per level, :math:`S_f = \sum_b k_{f,b}`, and
   the sequence :math:`S_f` is Richardson-extrapolated (:func:`porefsi.stokes.richardson`: the
   observed order from the last three levels) to :math:`S_\infty`. The factor is
   :math:`F = S_\infty / S_1` and the estimate :math:`k = F k_1`. With levels 1, 2, 3, 4 the order
   comes from 2, 3, 4, where rock sequences are closer to asymptotic than from 1, 2, 3;
   :func:`pool_blocks` also pools blocks whose finest level was solved on only some of them (the
   order from the complete ones, the others extrapolated at it from their own last two levels).

Why the pooled ratio. The whole image's k is a degree-one homogeneous function of the local
conductances, so by Euler's theorem a relative change :math:`\epsilon_b` of the conductance of
region :math:`b` changes k by :math:`\sum_b s_b \epsilon_b` to first order, with :math:`s_b` the
fraction of the viscous dissipation the flow spends in region :math:`b` (:math:`\sum s_b = 1`).
Under the mean pressure gradient a block feels, its dissipation is proportional to its k, so
:math:`s_b \propto k_{1,b}` and :math:`\sum_b s_b F_b = \sum_b k_{\infty,b} / \sum_b k_{1,b}`:
the pooled ratio is the dissipation-weighted mean of the block factors (an unweighted mean of
factors over-weights the low-k blocks, whose correction is the largest but which carry little of
the flow). Because Richardson extrapolation at a fixed order is linear, the pooled limit equals
the sum of the block limits at the pooled order.

**Uncertainty.** Two parts, combined in quadrature on :math:`F`: the sampling error of a ratio
estimator, :math:`\mathrm{SE}^2 = \sum_b (k_{\infty,b} - F k_{1,b})^2 / (K (K - 1)\, \bar k_1^2)`,
counted twice (about 95 %), and the grid-convergence index of the pooled sequence relative to
:math:`S_1` (Roache, :func:`porefsi.stokes.richardson`). What neither covers: the blocks' cut
faces (no-slip walls the whole image does not have) and their size; the estimator is validated
against whole-image extrapolation where that fits (docs/stokes.md, "Sampled defect correction").

**Known bias.** On the images validated the sampled estimate is high or about right, never low by
more than 1 %: +3-4 % on a 48³ Berea crop (16³-24³ blocks), +5.4, -0.6 and +7.1 % on three 80³
Berea crops with 40³ blocks (at p = 1; not ∝ 1/b: it depends on the throats the cuts close), +10 % on a
blob medium where only half the blocks carry flow by themselves (the blocks miss the narrow necks
between well-connected regions, whose correction is the largest). Read it as an upper estimate.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from porefsi.errors import InputError, NetworkError
from porefsi.image.voxel_image import AXES, VoxelImage, axis_index
from porefsi.stokes._domain import flowing_clusters
from porefsi.stokes._refine_grid import (
    available_memory_bytes,
    check_refine,
    check_refined_memory,
    pore_faces,
    refined_memory_bytes,
)
from porefsi.stokes.permeability import StokesOptions, stokes_options, voxel_permeability
from porefsi.stokes.refine import SAFETY_ASSUMED, SAFETY_OBSERVED, Extrapolation, richardson
from porefsi.units import MILLIDARCY

__all__ = ["SampledBlock", "SampledExtrapolation", "choose_blocks", "block_side", "sampled_permeability",
           "pool_blocks", "extrapolation_mode", "DEFAULT_BLOCKS", "DEFAULT_BLOCK_SIDE"]

#: Blocks solved unless told (a 2 x 2 x 2 stratified grid).
DEFAULT_BLOCKS = 8
#: Largest block side chosen automatically, voxels: a 40^3 Berea block takes ~2, 13 and 75 CPU s at
#: f = 1, 2, 3 (docs/stokes.md); larger blocks are allowed (``block=``) but slow at f = 3.
DEFAULT_BLOCK_SIDE = 40
#: Smallest block side accepted, voxels: below it a block holds a few pores at most.
MIN_BLOCK_SIDE = 8


@dataclasses.dataclass(frozen=True)
class SampledBlock:
    """One sub-block of a sampled estimate.

    Attributes
    ----------
    origin : tuple of 3 int
        Index of the block's first voxel in the image.
    side : int
        Edge of the cubic block, voxels.
    connected_porosity : float
        Pore fraction of the block's flowing clusters.
    k_mD : tuple of float
        Block permeability at each level solved (a leading run of the levels), mD.
    k_inf_mD : float
        Richardson value at the pooled order, mD.
    factor : float
        ``k_inf_mD / k_mD[0]``.
    cpu_seconds : float
        CPU time of the block's solves, s.
    """

    origin: tuple
    side: int
    connected_porosity: float
    k_mD: tuple  # noqa: N815 - the unit is mD
    k_inf_mD: float  # noqa: N815
    factor: float
    cpu_seconds: float


@dataclasses.dataclass(frozen=True, eq=False)
class SampledExtrapolation:
    """Native whole-image permeability corrected by a factor measured on refined sub-blocks.

    Attributes
    ----------
    k_m2, k_mD : float
        Corrected (estimated converged) permeability, ``factor * native_k_mD``; m² and mD.
    uncertainty_mD : float
        ``native_k_mD * factor_uncertainty``, mD.
    native_k_mD : float
        The whole image solved at its own resolution, mD (solved here, or given).
    factor : float
        Pooled k_inf / k_1 of the blocks.
    factor_uncertainty : float
        sqrt((2 SE)^2 + GCI^2), absolute on ``factor``.
    factor_se, factor_gci : float
        Sampling standard error of ``factor`` and the pooled grid-convergence index relative to S_1.
    factor_spread : tuple of 2 float
        Smallest and largest block factor.
    order : float
        Convergence order of the pooled sequence; ``order_observed`` says whether observed.
    order_observed : bool
    axis : str
    levels : tuple of int
    blocks : tuple of SampledBlock
    pooled : Extrapolation
        Richardson extrapolation of the pooled block sums (mD).
    native : StokesResult or None
        The whole-image solve, if done here.
    seconds : float
        Wall time, s.
    """

    k_m2: float
    k_mD: float  # noqa: N815 - the unit is mD
    uncertainty_mD: float  # noqa: N815
    native_k_mD: float  # noqa: N815
    factor: float
    factor_uncertainty: float
    factor_se: float
    factor_gci: float
    factor_spread: tuple
    order: float
    order_observed: bool
    axis: str
    levels: tuple
    blocks: tuple
    pooled: Extrapolation
    native: object
    seconds: float


def _check_levels(levels) -> tuple:
    levels = tuple(check_refine(f) for f in levels)
    if len(levels) < 2 or levels[0] != 1 or any(b <= a for a, b in zip(levels, levels[1:], strict=False)):
        raise InputError(f"sampled levels must start at 1 and increase (e.g. 1,2,3), got {levels}")
    return levels


def block_side(shape, porosity: float, f: int, axis: int, buffer: int, max_memory=None,
               largest: int = DEFAULT_BLOCK_SIDE) -> int:
    """Side of the largest cubic block whose solve refined ``f`` times fits ``max_memory`` bytes.

    The side is at most ``largest`` and half the image's smallest side, at least :data:`MIN_BLOCK_SIDE`.

    Raises :class:`InputError` if even the smallest block does not fit or the image is too small.
    """
    have = available_memory_bytes() if max_memory is None else float(max_memory)
    top = min(int(largest), min(int(s) for s in shape) // 2)
    if top < MIN_BLOCK_SIDE:
        raise InputError(f"image {'x'.join(map(str, shape))} is too small to sample blocks of >= {MIN_BLOCK_SIDE} "
                         "voxels; refine the whole image instead (extrapolated_permeability)")
    for b in range(top, MIN_BLOCK_SIDE - 1, -1):
        if refined_memory_bytes((b,) * 3, int(math.ceil(porosity * b**3)), f, axis, buffer) <= have:
            return b
    raise InputError(f"refine {f}: even a {MIN_BLOCK_SIDE}^3 block does not fit in {have / 2**30:.2f} GiB; "
                     "free memory or use fewer levels")


def _flows(pore: np.ndarray, axis: int) -> float:
    """Flowing (face-connected, spanning ``axis``) pore fraction of ``pore``; 0 if none spans."""
    try:
        kept, _ = flowing_clusters(pore, axis, [False] * 3)
    except NetworkError:
        return 0.0
    return float(kept.mean())


def _lattice(shape, side: int, m: int) -> list:
    """Origins of blocks of ``side`` centred in the cells of an m^3 grid over ``shape``, in design order.

    Design order: by ``(i + j + k) mod m`` of the cell indices, then lexicographic, so that the
    first ``m**2`` blocks are a Latin square (every index of every axis ``m`` times) and any
    leading subset spreads over all three axes.
    """
    per_axis = [sorted({min(max(int(round((i + 0.5) * n / m - side / 2)), 0), n - side) for i in range(m)})
                for n in shape]
    cells = [(i, j, k) for i in range(len(per_axis[0])) for j in range(len(per_axis[1]))
             for k in range(len(per_axis[2]))]
    cells.sort(key=lambda c: ((c[0] + c[1] + c[2]) % m, c))
    return [(per_axis[0][i], per_axis[1][j], per_axis[2][k]) for i, j, k in cells]


def choose_blocks(pore: np.ndarray, axis: int, count: int, side: int) -> list:
    """Origins of ``count`` flowing blocks of ``side`` voxels (the rule in the module notes).

    Returns a list of ``(origin, flowing porosity)``; fewer than ``count`` only if the finest
    lattice (blocks tiling the image) holds fewer flowing blocks.
    """
    m = max(1, math.ceil(count ** (1 / 3) - 1e-9))
    m_max = max(m, max(int(n) // side for n in pore.shape))
    while True:
        cand = []
        for o in _lattice(pore.shape, side, m):
            phi = _flows(pore[o[0]:o[0] + side, o[1]:o[1] + side, o[2]:o[2] + side], axis)
            if phi > 0:
                cand.append((o, phi))
        if len(cand) >= count or m >= m_max:
            break
        m += 1
    return cand[:count]


def pool_blocks(origins, side: int, k_levels, levels, cpu=None, porosity=None, order=None) -> tuple:
    """Pooled factor of blocks solved at ``levels``: ``(factor, se, gci, pooled, blocks)``.

    Every block must be solved at a leading run of ``levels`` (at least two); the finer levels may
    be missing (NaN) on some blocks, e.g. ``levels`` (1, 2, 3, 4) with level 4 solved only on the
    blocks that carry the most flow. The order is observed from the pooled sums of the *complete*
    blocks (``pooled``, :func:`porefsi.stokes.richardson`: from the last three levels, so from
    2, 3, 4 when four are given) and every block is extrapolated at that order from its own last two
    levels. The grid-convergence index adds, over the groups of blocks sharing their finest level,
    ``Fs |S_last - S_prev| / ((f_last/f_prev)^p - 1)``; ``Fs`` is the pooled one (1.25 if the order
    was observed and trusted) for the complete blocks and 3 for the others (the order is borrowed).

    Parameters
    ----------
    origins : sequence of 3-tuples
    side : int
    k_levels : array_like, shape (K, n_levels)
        Block permeability at each level (any unit); NaN for levels not solved (trailing only).
    levels : sequence of int
        Starting at 1.
    cpu, porosity : sequences of float, optional
        Per block, for the report.
    order : float, optional
        Convergence order (default: observed from the complete blocks' pooled sums, see
        :func:`porefsi.stokes.richardson`).
    """
    k = np.asarray(k_levels, float)
    solved = np.isfinite(k).sum(axis=1) if k.ndim == 2 else np.zeros(0, int)
    if k.ndim != 2 or k.shape[1] != len(levels) or k.shape[0] < 1 or np.any(k[np.isfinite(k)] <= 0) \
            or np.any(solved < 2) or not np.all(np.isfinite(k)[np.arange(k.shape[1]) < solved[:, None]]) \
            or not np.any(solved == len(levels)):
        raise InputError("k_levels must be positive, one row per block and one column per level, each row solved "
                         f"at a leading run of >= 2 levels (NaN after), one row complete; got {k.shape}")
    n_blocks, full = k.shape[0], solved == len(levels)
    pooled = richardson(levels, k[full].sum(axis=0), order=order)
    p, k_inf, gci = pooled.order, np.empty(n_blocks), 0.0
    for n in np.unique(solved):
        rows, (f_prev, f_last) = solved == n, levels[n - 2:n]
        denom = (f_last / f_prev) ** p - 1.0
        k_inf[rows] = k[rows, n - 1] + (k[rows, n - 1] - k[rows, n - 2]) / denom
        fs = (SAFETY_OBSERVED if pooled.order_observed else SAFETY_ASSUMED) if n == len(levels) else SAFETY_ASSUMED
        gci += fs * abs(np.sum(k[rows, n - 1] - k[rows, n - 2])) / denom
    factor = k_inf.sum() / k[:, 0].sum()
    if n_blocks > 1:
        resid = k_inf - factor * k[:, 0]
        se = float(np.sqrt(np.sum(resid**2) / (n_blocks * (n_blocks - 1))) / k[:, 0].mean())
    else:
        se = float("nan")
    cpu = [float("nan")] * n_blocks if cpu is None else cpu
    porosity = [float("nan")] * n_blocks if porosity is None else porosity
    blocks = tuple(SampledBlock(tuple(int(v) for v in o), int(side), float(phi), tuple(float(v) for v in row[:n]),
                                float(ki), float(ki / row[0]), float(c))
                   for o, row, n, ki, c, phi in zip(origins, k, solved, k_inf, cpu, porosity, strict=True))
    return float(factor), se, float(gci / k[:, 0].sum()), pooled, blocks


def _native_k(image: VoxelImage, ax: int, native, opts: StokesOptions):
    """``(k_mD, StokesResult or None)`` of the whole image at its own resolution: given, or solved."""
    if native is None:
        return None
    if hasattr(native, "k_mD"):
        if getattr(native, "axis", AXES[ax]) != AXES[ax]:
            raise InputError(f"native result is along {native.axis}, not {AXES[ax]}; pass the solve along {AXES[ax]}")
        info = getattr(native, "info", {}) or {}
        for key, want in (("wall", opts.wall), ("buffer", opts.buffer_layers), ("refine", 1)):
            if key in info and info[key] != want:
                raise InputError(f"native result was solved with {key}={info[key]!r}, the blocks with {want!r}; "
                                 "pass a native solve with the same options")
        return float(native.k_mD), native
    if isinstance(native, bool) or not isinstance(native, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(native) and native > 0):
        raise InputError(f"native must be a StokesResult or a positive permeability in mD, got {native!r}")
    return float(native), None


def sampled_permeability(image: VoxelImage, axis="x", levels=(1, 2, 3), blocks: int = DEFAULT_BLOCKS,
                         block: int | None = None, native=None, options: StokesOptions | None = None,
                         **overrides) -> SampledExtrapolation:
    """Whole-image voxel permeability corrected by refinement on sampled sub-blocks (module notes).

    Parameters
    ----------
    image : VoxelImage
    axis : {'x', 'y', 'z', 0, 1, 2}
    levels : sequence of int, default (1, 2, 3)
        Refinements of every block, starting at 1; three or more give an observed order.
    blocks : int, default 8
        Number of blocks K (>= 2).
    block : int, optional
        Block side, voxels; default: :func:`block_side` (the largest <= 40 whose finest level fits).
    native : StokesResult or float, optional
        The whole image already solved at its own resolution along ``axis`` with the same options
        (a result, or k in mD); default: solved here.
    options : StokesOptions, optional
        For every solve (``refine`` and ``fields`` must be left at their defaults); ``max_memory``
        bounds each solve, checked before anything is allocated.
    **overrides
        Fields of :class:`~porefsi.stokes.StokesOptions` by name.

    Returns
    -------
    SampledExtrapolation

    Raises
    ------
    InputError
        Bad parameters, or a solve that would not fit in memory.
    NetworkError
        Fewer than two blocks carry flow along ``axis``, or the whole image does not.
    """
    t0 = time.perf_counter()
    opts = _sampled_options(image, options, overrides)
    plan = prepare_sampled(image, axis, levels, blocks, block, native, opts)
    return run_sampled(image, plan, opts, None, t0)


def _sampled_options(image, options, overrides) -> StokesOptions:
    """The options of every solve of a sampled estimate (``refine`` and ``fields`` left alone), validated."""
    if not isinstance(image, VoxelImage):
        raise InputError(f"expected a VoxelImage, got {type(image).__name__}; read one with porefsi.read_image")
    opts = stokes_options(options, **overrides)
    if opts.refine != 1 or opts.fields:
        raise InputError("sampled_permeability sets refine itself (pass levels) and returns no fields")
    return opts


@dataclasses.dataclass(frozen=True)
class SampledPlan:
    """What a sampled estimate will solve (:func:`prepare_sampled`).

    Attributes: ``ax`` the axis index; ``levels``; ``side`` of the blocks, voxels; ``chosen``, the
    blocks' ``(origin, flowing porosity)``; ``given``, the native ``(k_mD, StokesResult or None)``,
    or None (solve it).
    """

    ax: int
    levels: tuple
    side: int
    chosen: tuple
    given: tuple | None


def prepare_sampled(image: VoxelImage, axis, levels, blocks, block, native, opts: StokesOptions) -> SampledPlan:
    """Validate a sampled estimate's parameters and choose its blocks, solving nothing.

    Raises as :func:`sampled_permeability`.
    """
    ax, levels = axis_index(axis), _check_levels(levels)
    if isinstance(blocks, bool) or not isinstance(blocks, (int, np.integer)) or blocks < 2:
        raise InputError(f"blocks must be a whole number >= 2 (the spread needs two), got {blocks!r}")
    side = _check_side(image, block, levels[-1], ax, opts)
    given = _native_k(image, ax, native, opts)
    if given is None:
        _check_native_memory(image, ax, opts)
    chosen = choose_blocks(image.pore, ax, int(blocks), side)
    if len(chosen) < 2:
        raise NetworkError(f"only {len(chosen)} block(s) of {side}^3 voxels carry flow along {AXES[ax]}; "
                           "use smaller blocks (--block) or refine the whole image")
    phi_max = max(float(np.mean(image.pore[o[0]:o[0] + side, o[1]:o[1] + side, o[2]:o[2] + side])) for o, _ in chosen)
    _check_block_memory(side, phi_max, levels[-1], ax, opts)
    return SampledPlan(ax, levels, side, tuple(chosen), given)


def run_sampled(image: VoxelImage, plan: SampledPlan, opts: StokesOptions, store=None,
                t0: float | None = None) -> SampledExtrapolation:
    """Solve (or take from ``store``) the native k and every block level of ``plan``, then pool.

    ``store`` (:class:`porefsi.stokes.sampled_resume.ResumeFile` or None) hands back the solves it
    holds and records each new one as soon as it is done, so an interrupted run loses at most the
    solve in progress.
    """
    t0 = time.perf_counter() if t0 is None else t0
    ax, levels, side = plan.ax, plan.levels, plan.side
    k_native, native_res = plan.given if plan.given is not None else (None, None)
    if k_native is None:
        native_res = voxel_permeability(image, ax, opts)
        if store is not None:
            store.put_native(native_res)
        k_native = native_res.k_mD
    rows, cpu = [], []
    for o, _phi in plan.chosen:
        sub = VoxelImage(np.ascontiguousarray(image.phases[o[0]:o[0] + side, o[1]:o[1] + side, o[2]:o[2] + side]),
                         image.voxel_size)
        row, c_block = [], 0.0
        for f in levels:
            hit = store.block(o, f) if store is not None else None
            if hit is None:
                c0 = time.process_time()
                r = voxel_permeability(sub, ax, opts, refine=f)
                hit = (r.k_mD, time.process_time() - c0)
                if store is not None:
                    store.put_block(o, f, r.k_mD, hit[1], r.iterations)
            row.append(hit[0])
            c_block += hit[1]
        rows.append(row)
        cpu.append(c_block)
    factor, se, gci, pooled, blk = pool_blocks([o for o, _ in plan.chosen], side, rows, levels, cpu,
                                               [phi for _, phi in plan.chosen])
    unc = math.hypot(2 * se, gci)
    return SampledExtrapolation(
        k_m2=factor * k_native * MILLIDARCY, k_mD=factor * k_native, uncertainty_mD=unc * k_native,
        native_k_mD=float(k_native), factor=factor, factor_uncertainty=unc, factor_se=se, factor_gci=gci,
        factor_spread=(min(b.factor for b in blk), max(b.factor for b in blk)), order=pooled.order,
        order_observed=pooled.order_observed, axis=AXES[ax], levels=levels, blocks=blk, pooled=pooled,
        native=native_res, seconds=time.perf_counter() - t0,
    )


def _check_side(image: VoxelImage, block, f: int, ax: int, opts: StokesOptions) -> int:
    """The block side: ``block`` validated against the image and memory, or :func:`block_side`."""
    if block is None:
        return block_side(image.shape, image.porosity, f, ax, opts.buffer_layers, opts.max_memory)
    if isinstance(block, bool) or not isinstance(block, (int, np.integer)) or block < MIN_BLOCK_SIDE \
            or block > min(image.shape):
        raise InputError(f"block must be a whole number of voxels in [{MIN_BLOCK_SIDE}, {min(image.shape)}] "
                         f"(the image's smallest side), got {block!r}")
    _check_block_memory(int(block), image.porosity, f, ax, opts)
    return int(block)


def _check_block_memory(side: int, porosity: float, f: int, ax: int, opts: StokesOptions) -> None:
    """Refuse (one line) blocks of ``side`` and pore fraction ``porosity`` whose level ``f`` would not fit."""
    need = refined_memory_bytes((side,) * 3, int(math.ceil(porosity * side**3)), f, ax, opts.buffer_layers)
    have = available_memory_bytes() if opts.max_memory is None else float(opts.max_memory)
    if need > have:
        raise InputError(f"refine {f}: a {side}^3 block needs ~{need / 2**30:.2f} GiB, above the "
                         f"{have / 2**30:.2f} GiB available; use a smaller --block or fewer levels")


def _check_native_memory(image: VoxelImage, ax: int, opts: StokesOptions) -> None:
    """Refuse (one line) a whole-image native solve whose estimate exceeds the memory budget."""
    need = refined_memory_bytes(image.shape, int(np.count_nonzero(image.pore)), 1, ax, opts.buffer_layers,
                                pore_faces(image.pore))
    have = available_memory_bytes() if opts.max_memory is None else float(opts.max_memory)
    if need > have:
        raise InputError(f"the native solve of the {'x'.join(map(str, image.shape))} image needs ~{need / 2**30:.2f} "
                         f"GiB, above the {have / 2**30:.2f} GiB available; crop or coarsen the image, or pass "
                         "native= (a solve already made)")


def extrapolation_mode(image: VoxelImage, axis, top: int, buffer: int, sampled: bool = False, max_memory=None) -> str:
    """How to solution-verify ``image``: 'whole' if it refined ``top`` times fits, else 'sampled'.

    ``buffer`` is the buffer layers of the solve (0 with a periodic boundary); ``sampled`` forces
    'sampled'; ``max_memory`` (bytes) defaults to the available memory.
    """
    if sampled:
        return "sampled"
    try:
        check_refined_memory(image.shape, int(np.count_nonzero(image.pore)), top, axis_index(axis), buffer, max_memory,
                             n_faces=pore_faces(image.pore))
    except InputError:
        return "sampled"
    return "whole"
