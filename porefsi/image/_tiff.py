"""TIFF stacks: read a multi-page TIFF into an (nx, ny, nz) array and its voxel size.

Private to :mod:`porefsi.image.io` (use :func:`porefsi.image.read_image`). Axes: x = column,
y = row, z = page, i.e. ``tifffile.imread(path).transpose(2, 1, 0)``, as ImageJ/Fiji, ParaView,
ITK and pnextract read a stack. The voxel size comes from the ImageJ metadata (``unit``,
``spacing``) or the TIFF resolution tags, or is ``None`` when the file does not state one.
Also holds :func:`_require_3d`, the dimension check shared by every reader.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from porefsi.errors import InputError
from porefsi.image._memory import require_memory


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


def _describe(page) -> str:
    return f"{'x'.join(map(str, page.shape))} {page.dtype}"


def _stack(tf, path) -> np.ndarray:
    """The voxels of an open TIFF as (page, row, column).

    One multi-page series (ImageJ, ``imwrite`` of a 3-D array), or single pages written one at
    a time, as scanners and ``imwrite(..., append=True)`` do (one series per page).

    Raises
    ------
    InputError
        Colour (RGB/multi-sample) pages, pages of different sizes or types, hyperstacks, or an
        image larger than the memory available; each says what was found.
    """
    pages = list(tf.pages)
    if not pages:
        raise InputError(f"{path} holds no image (no TIFF pages)")
    for k, page in enumerate(pages):
        if getattr(page, "samplesperpixel", 1) > 1 or str(getattr(page, "photometric", "")).endswith(("RGB", "YCBCR")):
            raise InputError(
                f"{path} is a colour image (page {k}: {getattr(page, 'samplesperpixel', '?')} samples per pixel, "
                f"{_describe(page)}); porefsi reads greyscale or segmented stacks: convert it to one channel "
                "(e.g. ImageJ Image > Type > 8-bit) and segment it")
    series = tf.series
    if len(series) == 1:
        s0 = series[0]
        if len(s0.shape) > 3:
            raise InputError(f"{path} holds a {len(s0.shape)}-D image ({s0.axes} {tuple(s0.shape)}); porefsi reads "
                             "one 3-D stack: keep one channel and one time point (e.g. ImageJ Duplicate)")
        require_memory(s0.shape, s0.dtype, path)
        return s0.asarray()
    first = pages[0]
    odd = next((k for k, p in enumerate(pages) if (p.shape, p.dtype) != (first.shape, first.dtype)), None)
    if odd is not None:
        raise InputError(f"{path}: its {len(pages)} pages differ (page 0 is {_describe(first)}, page {odd} is "
                         f"{_describe(pages[odd])}); a 3-D stack needs pages of one size and type: re-export it")
    if len(first.shape) != 2 or sum(len(s.pages) for s in series) != len(pages):
        raise InputError(f"{path} holds {len(series)} image series of shape {tuple(series[0].shape)}; porefsi reads "
                         "one 3-D stack: save the volume as one series")
    require_memory((len(pages), *first.shape), first.dtype, path)
    out = np.empty((len(pages), *first.shape), dtype=first.dtype)
    for k, p in enumerate(pages):  # a stack written page by page: each page its own series
        out[k] = p.asarray()
    return out


_LENGTH_UNITS = {
    "m": 1.0, "meter": 1.0, "cm": 1e-2, "centimeter": 1e-2, "mm": 1e-3, "millimeter": 1e-3,
    "um": 1e-6, "micron": 1e-6, "microns": 1e-6, "µm": 1e-6, "\u03bcm": 1e-6, "micrometer": 1e-6,
    "\\u00b5m": 1e-6, "nm": 1e-9, "nanometer": 1e-9, "inch": 0.0254,
}


def _read_tiff(path: Path, override: bool = False):
    """Return (array (x, y, z), voxel size in m or None) of a TIFF stack."""
    import logging

    import tifffile

    log = logging.getLogger("tifffile")
    level = log.level
    log.setLevel(logging.CRITICAL + 1)  # tifffile's warnings about a damaged file would add lines to ours
    try:
        with tifffile.TiffFile(path) as tf:
            arr = _stack(tf, path)
            ij = tf.imagej_metadata or {}
            tags = tf.pages[0].tags
            xres = tags["XResolution"].value if "XResolution" in tags else None
            yres = tags["YResolution"].value if "YResolution" in tags else None
            runit = int(tags["ResolutionUnit"].value) if "ResolutionUnit" in tags else 2
    except InputError:
        raise
    except tifffile.TiffFileError as exc:
        raise InputError(f"{path} is not a readable TIFF file ({exc})") from None
    except ValueError as exc:
        if "imagecodecs" not in str(exc):
            raise InputError(f"{path} is a damaged TIFF file ({exc}); is the file complete?") from None
        raise InputError(f"{path} is compressed with a codec tifffile reads only with the imagecodecs "
                         f"package ({exc}); pip install \"porefsi[tiff]\" (or pip install imagecodecs), "
                         "or save the stack uncompressed/deflate") from None
    except (IndexError, KeyError, TypeError, AttributeError, OSError, EOFError, struct.error,
            RuntimeError) as exc:  # what tifffile raises on a malformed header or page table
        raise InputError(f"{path} is a damaged TIFF file ({type(exc).__name__}: {exc}); is the file complete?"
                         ) from None
    finally:
        log.setLevel(level)
    arr = _require_3d(arr, f"TIFF {path} (pages, rows, columns)")
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
