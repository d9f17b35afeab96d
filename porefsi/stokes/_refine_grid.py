"""Grid refinement of a voxel image for the Stokes solver: upsampling and its memory budget.

Refining by ``f`` splits every voxel into ``f**3`` voxels of edge ``h/f``: the same staircase
geometry on a finer grid, so the voxel solver's k converges, as ``f`` grows, to the exact Stokes
flow through the image's voxel staircase (docs/stokes.md, "Solution verification").
"""

from __future__ import annotations

import numpy as np

from porefsi._memory import available_memory, format_bytes
from porefsi.errors import InputError

__all__ = [
    "upsample_mask",
    "pore_faces",
    "refined_memory_bytes",
    "available_memory_bytes",
    "check_refined_memory",
    "check_refine",
]

#: Working memory per unknown of the solved grid (a face velocity between two pore voxels, or a
#: pore voxel's pressure), bytes: neighbour table, diagonal, wall flags, pressure ids, Krylov vectors
#: and the pressure preconditioner (with its assembled set-up matrices); the upper envelope of the
#: measured peaks, 105-136 bytes (docs/stokes.md, "Memory").
BYTES_PER_UNKNOWN = 145
#: Per voxel of the solved box (pore and solid, buffers included): masks, labels, index tables.
BYTES_PER_BOX_VOXEL = 8
#: Fixed cost of a solve: the compiled kernels loaded on first use (~50 MiB) and small tables.
BYTES_FIXED = 64 * 2**20


def pore_faces(pore: np.ndarray) -> int:
    """Faces shared by two face-adjacent pore voxels of ``pore`` (bool 3-D), along all three axes."""
    pore = np.asarray(pore, dtype=bool)
    return int(
        sum(
            np.count_nonzero(
                np.logical_and(
                    pore[(slice(None),) * a + (slice(1, None),)], pore[(slice(None),) * a + (slice(None, -1),)]
                )
            )
            for a in range(3)
        )
    )


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


def refined_memory_bytes(shape, n_pore: int, f: int, axis: int, buffer: int, n_faces: int | None = None) -> int:
    """Estimated peak memory (bytes) of a voxel Stokes solve of an image refined ``f`` times.

    Unknowns of the refined grid from the unrefined counts: every pore voxel becomes ``f**3``
    pressure cells with ``3 f**2 (f - 1)`` faces between them, every face between two pore voxels
    ``f**2`` faces; the buffer layers are all fluid (3 faces per voxel), and each end face of the
    image adds at most one face per voxel of its cross-section. Then
    ``BYTES_PER_UNKNOWN * (faces + cells) + BYTES_PER_BOX_VOXEL * box + BYTES_FIXED``: an upper
    envelope of the measured peak resident memory above the interpreter's (docs/stokes.md, "Memory").

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
    n_faces : int, optional
        Faces between two pore voxels of the unrefined image (:func:`pore_faces`); default: the
        upper bound ``3 * n_pore`` (every face of every pore voxel open).
    """
    box = int(np.prod(shape, dtype=np.int64))
    slab = box // shape[axis] * 2 * buffer  # all-fluid buffer voxels
    faces = 3 * int(n_pore) if n_faces is None else int(n_faces)
    cells = int(n_pore) + slab
    # buffer voxels: 3 faces each; the image's two end faces: at most one face per voxel of the
    # cross-section (the buffers' contact, or the periodic wrap)
    n_u = f**2 * (3 * (f - 1) * cells + faces + 3 * slab + 2 * (box // shape[axis]))
    n_p = f**3 * cells
    return int(BYTES_PER_UNKNOWN * (n_u + n_p) + BYTES_PER_BOX_VOXEL * f**3 * (box + slab) + BYTES_FIXED)


def available_memory_bytes() -> int:
    """Bytes a new allocation may take, 2**62 if unknown.

    :func:`porefsi._memory.available_memory`: MemAvailable, lowered to the room the address-space
    limit leaves.
    """
    avail = available_memory()
    return 2**62 if avail is None else int(avail)


def check_refined_memory(
    shape, n_pore: int, f: int, axis: int, buffer: int, max_memory=None, n_faces: int | None = None
) -> int:
    """Raise :class:`InputError` (one line, naming a refinement that fits) if the refined solve would not fit.

    ``max_memory`` (bytes) defaults to :func:`available_memory_bytes`; ``n_faces`` as in
    :func:`refined_memory_bytes`. Returns the estimate.
    """
    need = refined_memory_bytes(shape, n_pore, f, axis, buffer, n_faces)
    have = available_memory_bytes() if max_memory is None else float(max_memory)
    if need <= have:
        return need
    fits = [g for g in range(f - 1, 0, -1) if refined_memory_bytes(shape, n_pore, g, axis, buffer, n_faces) <= have]
    hint = f"use refine {fits[0]} (--refine {fits[0]})" if fits and fits[0] > 1 else "solve without refinement"
    side = int(max(shape))
    box = max(int(np.prod(shape)), 1)
    while (
        side > 8
        and refined_memory_bytes(
            (side,) * 3, n_pore * side**3 // box, f, axis, buffer, None if n_faces is None else n_faces * side**3 // box
        )
        > have
    ):
        side = int(side * 0.8)
    raise InputError(
        f"refine {f}: the {'x'.join(str(f * s) for s in shape)} grid needs ~{format_bytes(need)}, "
        f"above the {format_bytes(have)} available; {hint}, or crop the image to ~{side}^3 voxels"
    )
