"""Grid refinement of a voxel image for the Stokes solver: upsampling and its memory budget.

Refining by ``f`` splits every voxel into ``f**3`` voxels of edge ``h/f``: the same staircase
geometry on a finer grid, so the voxel solver's k converges, as ``f`` grows, to the exact Stokes
flow through the image's voxel staircase (docs/stokes.md, "Solution verification").
"""

from __future__ import annotations

import numpy as np

from porefsi._memory import available_memory, format_bytes
from porefsi.errors import InputError

__all__ = ["upsample_mask", "refined_memory_bytes", "available_memory_bytes", "check_refined_memory",
           "check_refine"]

#: Working memory per flowing pore voxel of the solved grid, bytes: ~150 bytes per unknown
#: (docs/stokes.md, "Method"), about 4 unknowns (a pressure and three faces) per pore voxel.
BYTES_PER_PORE_VOXEL = 600
#: Per voxel of the solved box (pore and solid, buffers included): masks, labels, index tables.
BYTES_PER_BOX_VOXEL = 24


def check_refine(refine) -> int:
    """``refine`` as an int >= 1, or an :class:`InputError`."""
    if isinstance(refine, bool) or not isinstance(refine, (int, np.integer)) or refine < 1:
        raise InputError(f"refine must be a whole number >= 1 (voxels split into refine^3), got {refine!r}")
    return int(refine)


def upsample_mask(mask: np.ndarray, f: int) -> np.ndarray:
    """Every voxel of a 3-D ``mask`` as an ``f x f x f`` block: shape ``(f*n0, f*n1, f*n2)``."""
    if f == 1:
        return mask
    n0, n1, n2 = mask.shape
    blocks = np.broadcast_to(mask[:, None, :, None, :, None], (n0, f, n1, f, n2, f))
    return np.ascontiguousarray(blocks).reshape(n0 * f, n1 * f, n2 * f)


def refined_memory_bytes(shape, n_pore: int, f: int, axis: int, buffer: int) -> int:
    """Estimated memory (bytes) a voxel Stokes solve of an image refined ``f`` times allocates.

    Parameters
    ----------
    shape : tuple of 3 int
        Image shape before refinement.
    n_pore : int
        Pore voxels before refinement (an upper bound for the flowing ones).
    f : int
        Refinement factor.
    axis : int
        Flow axis (the buffer layers are added along it).
    buffer : int
        Buffer layers at each end, in voxels of the unrefined image.
    """
    box = int(np.prod(shape, dtype=np.int64))
    slab = box // shape[axis] * 2 * buffer  # all-fluid buffer voxels
    f3 = f**3
    return int(f3 * (BYTES_PER_BOX_VOXEL * (box + slab) + BYTES_PER_PORE_VOXEL * (n_pore + slab)))


def available_memory_bytes() -> int:
    """Bytes a new allocation may take, 2**62 if unknown.

    :func:`porefsi._memory.available_memory`: MemAvailable, lowered to the room the address-space
    limit leaves.
    """
    avail = available_memory()
    return 2**62 if avail is None else int(avail)


def check_refined_memory(shape, n_pore: int, f: int, axis: int, buffer: int, max_memory=None) -> int:
    """Raise :class:`InputError` (one line, naming a refinement that fits) if the refined solve would not fit.

    ``max_memory`` (bytes) defaults to :func:`available_memory_bytes`. Returns the estimate.
    """
    need = refined_memory_bytes(shape, n_pore, f, axis, buffer)
    have = available_memory_bytes() if max_memory is None else float(max_memory)
    if need <= have:
        return need
    fits = [g for g in range(f - 1, 0, -1) if refined_memory_bytes(shape, n_pore, g, axis, buffer) <= have]
    hint = f"use refine {fits[0]} (--refine {fits[0]})" if fits and fits[0] > 1 else "solve without refinement"
    side = int(max(shape))
    while side > 8 and refined_memory_bytes((side,) * 3, n_pore * side**3 // max(int(np.prod(shape)), 1), f,
                                            axis, buffer) > have:
        side = int(side * 0.8)
    raise InputError(
        f"refine {f}: the {'x'.join(str(f * s) for s in shape)} grid needs ~{format_bytes(need)}, "
        f"above the {format_bytes(have)} available; {hint}, or crop the image to ~{side}^3 voxels"
    )
