"""TIFF stacks: read a multi-page TIFF into an (nx, ny, nz) array and its voxel size.

Private to :mod:`porefsi.image.io` (use :func:`porefsi.image.read_image`). Axes: x = column,
y = row, z = page, i.e. ``tifffile.imread(path).transpose(2, 1, 0)``, as ImageJ/Fiji, ParaView,
ITK and pnextract read a stack. The voxel size comes from the ImageJ metadata (``unit``,
``spacing``) or the TIFF resolution tags, or is ``None`` when the file does not state one.
Also holds :func:`_require_3d`, the dimension check shared by every reader.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from porefsi.errors import InputError


def _require_3d(a: np.ndarray, what: str) -> np.ndarray:
    """Return ``a`` if it is 3-D, else raise InputError naming ``what`` (shared by all readers)."""
    if a.ndim == 3:
        return a
    hint = (
        "; a single slice is 2-D: add an axis, e.g. a[:, :, None], to make a one-voxel-thick image"
        if a.ndim == 2
        else "; pass a (nx, ny, nz) array"
    )
    raise InputError(f"{what} holds a {a.ndim}-D array of shape {a.shape}, need 3-D{hint}")


_LENGTH_UNITS = {
    "m": 1.0, "meter": 1.0, "cm": 1e-2, "centimeter": 1e-2, "mm": 1e-3, "millimeter": 1e-3,
    "um": 1e-6, "micron": 1e-6, "microns": 1e-6, "µm": 1e-6, "\u03bcm": 1e-6, "micrometer": 1e-6,
    "\\u00b5m": 1e-6, "nm": 1e-9, "nanometer": 1e-9, "inch": 0.0254,
}


def _read_tiff(path: Path, override: bool = False):
    """Return (array (x, y, z), voxel size in m or None) of a TIFF stack."""
    import tifffile

    try:
        with tifffile.TiffFile(path) as tf:
            arr = tf.asarray()
            ij = tf.imagej_metadata or {}
            tags = tf.pages[0].tags
            xres = tags["XResolution"].value if "XResolution" in tags else None
            yres = tags["YResolution"].value if "YResolution" in tags else None
            runit = int(tags["ResolutionUnit"].value) if "ResolutionUnit" in tags else 2
    except tifffile.TiffFileError as exc:
        raise InputError(f"{path} is not a readable TIFF file ({exc})") from None
    except ValueError as exc:
        if "imagecodecs" not in str(exc):
            raise
        raise InputError(f"{path} is compressed with a codec tifffile reads only with the imagecodecs "
                         f"package ({exc}); pip install \"porefsi[tiff]\" (or pip install imagecodecs), "
                         "or save the stack uncompressed/deflate") from None
    arr = _require_3d(arr, f"TIFF {path} (pages, rows, columns[, samples])")
    arr = arr.transpose(2, 1, 0)  # (page, row, column) -> (x=column, y=row, z=page)

    def size(res):
        return res[1] / res[0] if res and res[0] > 0 else None  # length units per pixel

    sx, sy = size(xres), size(yres)
    unit = None
    if ij.get("unit") is not None:
        unit = _LENGTH_UNITS.get(str(ij["unit"]).strip().lower())
    elif runit in (3, 4, 5):  # centimetre (TIFF); millimetre, micrometre (tifffile extensions)
        unit = {3: 1e-2, 4: 1e-3, 5: 1e-6}[runit]
    elif runit == 2 and xres is not None and round(1 / sx, 6) not in (72.0, 96.0, 300.0, 1.0):
        unit = 0.0254  # inches, unless a screen/printer default that says nothing about the scan
    if unit is None or sx is None:
        return arr, None
    sz = float(ij["spacing"]) if "spacing" in ij else sx
    sizes = np.array([sx, sy if sy is not None else sx, sz]) * unit
    if np.ptp(sizes) > 1e-6 * sizes.max():
        if override:
            return arr, None
        raise InputError(f"{path}: voxel sizes {sizes} m (x, y, z from the TIFF tags) are not cubic; "
                         "porefsi needs cubic voxels: resample the image, or pass voxel_size=... to override")
    return arr, float(sizes[0])
