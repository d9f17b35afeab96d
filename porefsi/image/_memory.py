"""Memory checks before an image is read (private): refuse what the machine cannot hold.

A header (``.npy``, ``.npz`` member, MetaImage ``DimSize``, TIFF pages) states the size of the
array before any voxel is read; a corrupt or mistyped one can claim petabytes. The reader asks
:func:`require_memory` first and gets a one-line :class:`~porefsi.errors.InputError` that says
how much the array needs and how much the machine has, instead of a ``MemoryError`` (or the
operating system killing the process) later.
"""

from __future__ import annotations

import numpy as np

from porefsi._memory import available_memory, format_bytes
from porefsi.errors import InputError

__all__ = ["available_memory", "require_memory", "format_bytes", "npy_header"]


def require_memory(shape, dtype, path, what: str = "the image") -> int:
    """Refuse reading an array of ``shape`` x ``dtype`` that the machine cannot hold; return its bytes.

    Counted: the array itself plus one byte per voxel for the segmented copy made from it.

    Raises
    ------
    InputError
        The array (a header's claim) needs more memory than is available; the message names
        ``path``, the shape, the bytes needed and available, and the fix.
    """
    n_vox = int(np.prod([int(s) for s in shape], dtype=object))
    need = n_vox * np.dtype(dtype).itemsize + n_vox
    avail = available_memory()
    if avail is not None and need > avail:
        raise InputError(
            f"{path}: {what} is {tuple(int(s) for s in shape)} x {np.dtype(dtype)}, which needs about "
            f"{format_bytes(need)} of memory to read, but this machine has {format_bytes(avail)} available; "
            "check the file's header (a corrupt or mistyped size?), crop the image into a smaller file, or use "
            "a machine with more memory")
    return need


def npy_header(fh, path) -> tuple[tuple, np.dtype, bool]:
    """(shape, dtype, fortran_order) from the header of an ``.npy`` stream, reading nothing else.

    Raises
    ------
    InputError
        Not an ``.npy`` stream, or an array of Python objects (which would need a pickle).
    """
    from numpy.lib import format as npf

    try:
        version = npf.read_magic(fh)
        read = npf.read_array_header_1_0 if version == (1, 0) else npf.read_array_header_2_0
        shape, fortran, dtype = read(fh)
    except (ValueError, OSError, EOFError) as exc:
        raise InputError(f"{path} is not a readable .npy array ({exc}); is the file complete?") from None
    if dtype.hasobject:
        raise InputError(f"{path} holds Python objects, not numbers (porefsi never loads pickles); save the image "
                         "as a numeric array (numpy.save of a uint8/bool/float array)")
    return tuple(shape), dtype, fortran
