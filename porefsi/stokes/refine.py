r"""Solution verification of the voxel Stokes permeability: grid refinement and Richardson extrapolation.

The voxel solver's k depends on the grid: its 7-point stencil leaks flow past the staircase corners
and its wall closure errs by O(h²) (docs/stokes.md). Solving the same image refined
:math:`f_1 < f_2 < f_3` times (every voxel split into :math:`f^3`) gives a sequence
:math:`k_f = k_\infty + C\,f^{-p}`; three levels determine the observed order :math:`p` from

.. math:: \frac{k_{f_1} - k_{f_2}}{k_{f_2} - k_{f_3}} = \frac{f_1^{-p} - f_2^{-p}}{f_2^{-p} - f_3^{-p}},

and the Richardson value is

.. math:: k_\infty = k_{f_n} + \frac{k_{f_n} - k_{f_{n-1}}}{(f_n/f_{n-1})^p - 1}.

:math:`k_\infty` is the exact Stokes flow through the image's voxel staircase (what the grid
converges to), not the flow through the smooth rock the image was taken of. The uncertainty is
Roache's grid-convergence index, :math:`F_s |k_{f_n} - k_{f_{n-1}}| / ((f_n/f_{n-1})^p - 1)`,
with :math:`F_s = 1.25` for an observed order and 3 for an assumed one (two levels).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
from scipy.optimize import brentq

from porefsi.errors import InputError
from porefsi.image.voxel_image import axis_index
from porefsi.stokes._refine_grid import check_refine, check_refined_memory, pore_faces
from porefsi.stokes.permeability import StokesOptions, StokesResult, stokes_options, voxel_permeability
from porefsi.units import MILLIDARCY

__all__ = ["Extrapolation", "ExtrapolatedPermeability", "richardson", "extrapolated_permeability",
           "ASSUMED_ORDER"]

#: Order assumed when only two levels are solved: between the orders observed from levels 1, 2, 3
#: on Berea crops (1.2) and on staircase tubes (1.4-1.75), square ducts and plates (1.8-2.0);
#: docs/stokes.md, "Solution verification".
ASSUMED_ORDER = 1.5
#: Roache's safety factors of the grid-convergence index: observed order, assumed order.
SAFETY_OBSERVED, SAFETY_ASSUMED = 1.25, 3.0
#: Observed orders outside this range are not trusted (the assumed order is used, flagged). Below
#: 0.95: every closed form converges at p >= 1.2 with either wall closure (tubes, ducts, plates;
#: docs/stokes.md), but a sum of them need not look like it: a 1-voxel duct refined 2x keeps its
#: error exactly (a 2-voxel duct has the same relative error with the channel closure), so a
#: medium with 1-voxel throats shows a spurious p of 0.4-0.9 from levels 1, 2, 3 and extrapolating
#: with it overshoots (a 2-voxel duct plus 0.3 of a 1-voxel one: p 0.37, k 23 % low; with p = 1.5:
#: 0.6 % low; tests/test_stokes_refine.py).
ORDER_RANGE = (0.95, 6.0)


@dataclasses.dataclass(frozen=True)
class Extrapolation:
    """Richardson extrapolation of a quantity solved at several refinements.

    Attributes
    ----------
    levels : tuple of int
        Refinement factors, increasing.
    values : tuple of float
        The quantity at each level.
    order : float
        Order p used (observed, or :data:`ASSUMED_ORDER`).
    order_observed : bool
        Whether ``order`` was observed from three levels (False: assumed, or the observed one was
        out of :data:`ORDER_RANGE` / the sequence was not monotone).
    observed_order : float
        The order from the last three levels (NaN with two levels or a non-monotone sequence).
    value : float
        The extrapolated (converged) value.
    uncertainty : float
        Grid-convergence index of ``value`` (same unit), >= 0.
    """

    levels: tuple
    values: tuple
    order: float
    order_observed: bool
    observed_order: float
    value: float
    uncertainty: float

    def error_at(self, level: int) -> float:
        """Relative discretisation error of the value at ``level``: (value_level - value) / value."""
        return self.values[self.levels.index(level)] / self.value - 1.0


def observed_order(levels, values) -> float:
    """Order p of ``values[i] = v + C levels[i]**-p`` from three levels; NaN if none fits."""
    f1, f2, f3 = (float(x) for x in levels[-3:])
    k1, k2, k3 = (float(x) for x in values[-3:])
    d1, d2 = k1 - k2, k2 - k3
    if d2 == 0 or d1 == 0 or (d1 > 0) != (d2 > 0):
        return float("nan")
    ratio = d1 / d2

    def g(p):
        return (f1**-p - f2**-p) - ratio * (f2**-p - f3**-p)

    lo, hi = 1e-3, 20.0
    if g(lo) * g(hi) > 0:
        return float("nan")
    return float(brentq(g, lo, hi, xtol=1e-10))


def richardson(levels, values, order: float | None = None) -> Extrapolation:
    """Richardson-extrapolate ``values`` solved at refinement factors ``levels`` (see the module notes).

    Parameters
    ----------
    levels : sequence of int
        Refinement factors, strictly increasing, at least two.
    values : sequence of float
        The quantity at each level.
    order : float, optional
        Order to use; default: observed from the last three levels, or :data:`ASSUMED_ORDER` with
        two levels or an observed order outside :data:`ORDER_RANGE`.

    Examples
    --------
    >>> e = richardson([1, 2, 3], [1 + 1.0, 1 + 1 / 4, 1 + 1 / 9])   # 1 + f^-2
    >>> round(e.order, 6), round(e.value, 6), e.order_observed
    (2.0, 1.0, True)
    """
    levels = tuple(int(x) for x in levels)
    values = tuple(float(x) for x in values)
    if len(levels) < 2 or len(levels) != len(values):
        raise InputError(f"richardson needs two or more levels and one value per level, got {levels} and {values}")
    if any(b <= a for a, b in zip(levels, levels[1:], strict=False)) or levels[0] < 1:
        raise InputError(f"refinement levels must be increasing whole numbers >= 1, got {levels}")
    if not all(math.isfinite(v) for v in values):
        raise InputError(f"values must be finite, got {values}")
    p_obs = observed_order(levels, values) if len(levels) >= 3 else float("nan")
    trusted = ORDER_RANGE[0] <= p_obs <= ORDER_RANGE[1]
    if order is not None:
        if not (math.isfinite(order) and order > 0):
            raise InputError(f"order must be a positive number, got {order!r}")
        p, used_observed = float(order), False
    elif trusted:
        p, used_observed = p_obs, True
    else:
        p, used_observed = ASSUMED_ORDER, False
    f_prev, f_last = levels[-2], levels[-1]
    k_prev, k_last = values[-2], values[-1]
    denom = (f_last / f_prev) ** p - 1.0
    value = k_last + (k_last - k_prev) / denom
    fs = SAFETY_OBSERVED if used_observed else SAFETY_ASSUMED
    unc = fs * abs(k_last - k_prev) / denom
    return Extrapolation(levels, values, p, used_observed, p_obs, float(value), float(unc))


@dataclasses.dataclass(frozen=True, eq=False)
class ExtrapolatedPermeability:
    """Voxel Stokes permeability solved at several refinements and extrapolated.

    Attributes
    ----------
    k_m2, k_mD : float
        Richardson-extrapolated permeability, m² and mD.
    uncertainty_mD : float
        Grid-convergence index of ``k_mD``, mD.
    order : float
        Convergence order used; ``order_observed`` says whether it was observed (three levels).
    order_observed : bool
    native_error : float
        Relative discretisation error of the unrefined solve, (k_1 - k_inf) / k_inf (NaN if level 1
        was not solved).
    extrapolation : Extrapolation
        In mD.
    results : tuple of StokesResult
        One per level.
    seconds : float
        Wall time of all solves, s.
    """

    k_m2: float
    k_mD: float  # noqa: N815 - the unit is mD
    uncertainty_mD: float  # noqa: N815
    order: float
    order_observed: bool
    native_error: float
    extrapolation: Extrapolation
    results: tuple
    seconds: float


def extrapolated_permeability(image, axis="x", levels=(1, 2, 3), options: StokesOptions | None = None,
                              **overrides) -> ExtrapolatedPermeability:
    """Solve ``image`` refined at each of ``levels`` and Richardson-extrapolate k.

    Parameters
    ----------
    image : VoxelImage
    axis : {'x', 'y', 'z', 0, 1, 2}
    levels : sequence of int, default (1, 2, 3)
        Refinement factors, increasing; three or more give an observed order.
    options : StokesOptions, optional
        Passed to :func:`porefsi.stokes.voxel_permeability` (boundary, buffer, wall, rtol, ...;
        its ``refine`` and ``fields`` must be left at their defaults). ``max_memory`` bounds the
        finest level, whose estimate is checked before any solve.
    **overrides
        Fields of :class:`~porefsi.stokes.StokesOptions` by name.

    Returns
    -------
    ExtrapolatedPermeability

    Raises
    ------
    InputError
        Bad levels, or the finest level would not fit in memory.
    """
    t0 = time.perf_counter()
    if "refine" in overrides or "fields" in overrides:
        raise InputError("extrapolated_permeability sets refine itself (pass levels) and returns no fields")
    opts = stokes_options(options, **overrides)
    if opts.refine != 1 or opts.fields:
        raise InputError("extrapolated_permeability sets refine itself (pass levels) and returns no fields")
    levels = tuple(check_refine(f) for f in levels)
    if len(levels) < 2 or any(b <= a for a, b in zip(levels, levels[1:], strict=False)):
        raise InputError(f"levels must be two or more increasing refinement factors, got {levels}")
    if not hasattr(image, "pore"):
        raise InputError(f"expected a VoxelImage, got {type(image).__name__}; read one with porefsi.read_image")
    check_refined_memory(image.shape, int(np.count_nonzero(image.pore)), levels[-1], axis_index(axis),
                         opts.buffer_layers, opts.max_memory, n_faces=pore_faces(image.pore))
    results: list[StokesResult] = [voxel_permeability(image, axis, opts, refine=f) for f in levels]
    ext = richardson(levels, [r.k_mD for r in results])
    native = ext.error_at(1) if levels[0] == 1 else float("nan")
    return ExtrapolatedPermeability(
        k_m2=ext.value * MILLIDARCY, k_mD=ext.value, uncertainty_mD=ext.uncertainty, order=ext.order,
        order_observed=ext.order_observed, native_error=native, extrapolation=ext, results=tuple(results),
        seconds=time.perf_counter() - t0,
    )
