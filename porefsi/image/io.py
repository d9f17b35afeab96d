r"""Read and write segmented images; segment grey or labelled images; the built-in sample.

Conventions (see ``docs/images.md``):

* 1 = pore, 0 = solid in every :class:`~porefsi.image.VoxelImage`.
* Axes x, y, z are array axes 0, 1, 2. In files that name their axes (MetaImage ``DimSize``,
  TIFF pages/rows/columns) x is the axis that varies fastest on disk (the TIFF column), z the
  slowest (the TIFF page), as ImageJ/Fiji, ParaView, ITK and pnextract read them.
* The voxel size comes from the file when the file carries one; an explicit ``voxel_size``
  argument overrides it; if neither gives one, reading fails. It is never silently 1.
"""

from __future__ import annotations

import dataclasses
import math
import zipfile
import zlib
from importlib import resources
from pathlib import Path

import numpy as np

from porefsi.errors import InputError
from porefsi.image._memory import npy_header, require_memory
from porefsi.image._mhd import MHD_UNITS, _read_mhd, _read_raw, _write_mhd
from porefsi.image._tiff import _read_tiff, _require_3d
from porefsi.image.voxel_image import VoxelImage, positive_length

# MetaImage parsing/writing lives in _mhd.py, TIFF reading in _tiff.py; MHD_UNITS is re-exported here.
__all__ = ["segment", "read_image", "RawLayout", "check_voxel_size", "PlausibilityWarning", "VOXEL_SIZE_LIMITS",
           "PLAUSIBLE_VOXEL_SIZE", "write_image", "load_sample", "SAMPLES", "READ_FORMATS", "MHD_UNITS"]

#: Readable file suffixes and what each needs from the user.
READ_FORMATS = {
    ".npy": "NumPy array; voxel size required",
    ".npz": "NumPy archive; array key auto-detected (image/phases/im/data) or key=; voxel size from "
    "voxel_size_m if stored",
    ".mhd": "MetaImage header (+ .raw/.raw.gz/.tif data); voxel size from ElementSpacing",
    ".raw": "raw voxels: with a .mhd header of the same name, or shape= and dtype=",
    ".bin": "raw voxels with shape= and dtype=",
    ".dat": "raw voxels with shape= and dtype=",
    ".tif": "TIFF stack (one page per z slice); voxel size from ImageJ/resolution tags if present",
    ".tiff": "TIFF stack, as .tif",
}

#: Built-in samples: name -> (file in porefsi/data, description with attribution).
SAMPLES = {
    "berea120": (
        "berea_icl_120_paper.npz",
        "Berea sandstone, 120^3 voxels of 5.345 um (0.641 mm cube), porosity 0.1882: crop "
        "[180:300, 20:140, 220:340] of the Imperial College London pore-scale modelling group's "
        "400^3 Berea image (via LukasMosser/PorousMediaGan, MIT licence); the seed paper's table 2 "
        "sample. See porefsi/data/ATTRIBUTION.md.",
    ),
}

_NPZ_KEYS = ("image", "phases", "im", "data")


# --------------------------------------------------------------------------------------------
# segmentation
# --------------------------------------------------------------------------------------------
def _distinct(a: np.ndarray, limit: int = 8) -> list:
    """The first ``limit`` distinct values of ``a`` (sorted), as Python scalars."""
    if a.dtype == np.uint8 or a.dtype == bool:
        flat = a.reshape(-1).view(np.uint8)
        hist = np.zeros(256, np.int64)
        for start in range(0, flat.size, 1 << 22):  # bincount converts to int64: chunks bound that copy
            hist += np.bincount(flat[start:start + (1 << 22)], minlength=256)
        vals = np.flatnonzero(hist)
    else:
        vals = np.unique(a)
    return [v.item() for v in np.asarray(vals[:limit])]


def segment(
    array,
    *,
    threshold: float | None = None,
    pore_value: float | None = None,
    invert: bool = False,
    pore_above: bool = False,
) -> np.ndarray:
    """Turn an image into a pore indicator: uint8, 1 = pore, 0 = solid.

    Parameters
    ----------
    array : array_like, shape (nx, ny, nz)
        The image: bool, integer or float. Not modified.
    threshold : float, optional
        Grey images: pore where ``value <= threshold`` (dark pores, the usual micro-CT contrast),
        or where ``value > threshold`` with ``pore_above=True``.
    pore_value : float, optional
        Labelled images: pore where ``value == pore_value``.
    invert : bool, default False
        Swap pore and solid in the result (e.g. the ICL ``berea.tif``, where 0 = pore and
        255 = solid).
    pore_above : bool, default False
        With ``threshold``: values above it are pore.

    Returns
    -------
    ndarray of uint8, shape of ``array``
        1 = pore, 0 = solid.

    Raises
    ------
    InputError
        If the convention is ambiguous (more than two values, or two values neither of which
        is 0) and neither ``threshold`` nor ``pore_value`` is given; if the image holds NaN;
        if ``threshold`` and ``pore_value`` are both given; if the result is all solid or all pore.

    Notes
    -----
    Without ``threshold``/``pore_value`` only unambiguous images are accepted: bool images
    (True = pore) and two-valued images ``{0, v}`` (``v`` = pore). Then ``invert=True`` flips the
    convention. ``invert`` flips the result in every mode.

    Examples
    --------
    >>> import numpy as np
    >>> segment(np.array([[[0, 255], [255, 0]]]), invert=True).tolist()
    [[[1, 0], [0, 1]]]
    >>> segment(np.array([[[10, 200], [90, 150]]]), threshold=100).tolist()
    [[[1, 0], [1, 0]]]
    """
    a = np.asarray(array)
    _check_segment_args(a, threshold, pore_value, pore_above)
    if threshold is not None:
        pore, how = _threshold_mask(a, threshold, pore_above)
    elif pore_value is not None:
        pore, how = _value_mask(a, pore_value)
    else:
        pore, how = _two_valued_mask(a)
    if invert:
        pore = ~pore
        how = f"not ({how})"
    return _pore_uint8(pore, a, how)


def _check_segment_args(a: np.ndarray, threshold, pore_value, pore_above: bool) -> None:
    """Refuse non-numeric, empty or NaN images and contradictory options of :func:`segment`."""
    if a.dtype.kind not in "biuf":
        raise InputError(f"image dtype {a.dtype} is not numeric; pass a bool, integer or float array")
    if a.size == 0:
        raise InputError(f"image is empty (shape {a.shape})")
    if threshold is not None and pore_value is not None:
        raise InputError(
            f"threshold={threshold!r} and pore_value={pore_value!r} both given; pass only one "
            "(threshold for grey images, pore_value for labelled images)"
        )
    if pore_above and threshold is None:
        raise InputError("pore_above only applies with a threshold; pass threshold=... (CLI --threshold)")
    if a.dtype.kind == "f" and np.isnan(a).any():
        raise InputError(
            f"image holds {int(np.isnan(a).sum())} NaN voxels; fill or mask them before segmenting"
        )


def _threshold_mask(a: np.ndarray, threshold: float, pore_above: bool) -> tuple[np.ndarray, str]:
    """Grey image: pore where ``a <= threshold`` (or ``>`` with ``pore_above``), and how it was chosen."""
    t = float(threshold)
    if math.isnan(t):
        raise InputError("threshold is NaN; pass a number (pore = value <= threshold)")
    pore = a > t if pore_above else a <= t
    return pore, f"value {'>' if pore_above else '<='} {threshold:g}"


def _value_mask(a: np.ndarray, pore_value: float) -> tuple[np.ndarray, str]:
    """Labelled image: pore where ``a == pore_value``, and how it was chosen."""
    v = float(pore_value)
    if math.isnan(v):
        raise InputError("pore_value is NaN; pass the value that marks pore voxels")
    pore = a == v
    if not pore.any():
        raise InputError(
            f"pore_value={pore_value:g} does not occur in the image (values found: "
            f"{_distinct(a)}...); pass one of the values present"
        )
    return pore, f"value == {pore_value:g}"


def _two_valued_mask(a: np.ndarray) -> tuple[np.ndarray, str]:
    """Bool image (True = pore) or two-valued ``{0, v}`` image (``v`` = pore); anything else refused."""
    if a.dtype == bool:
        return a, "True"
    if a.dtype == np.uint8:  # a histogram, no full-size temporaries (a 1000^3 image: 3 GB saved)
        vals = _distinct(a, limit=3)
        lo, hi, two = vals[0], vals[-1], len(vals) <= 2
    else:
        lo, hi = a.min(), a.max()
        two = lo == hi or bool(((a == lo) | (a == hi)).all())
    if not two or (lo != hi and lo != 0 and hi != 0):
        vals = _distinct(a)
        n = "more than two" if not two else "two nonzero"
        raise InputError(
            f"image has {n} distinct values ({', '.join(map(str, vals))}{', ...' if len(vals) >= 8 else ''}) "
            "so which is pore is ambiguous; pass threshold=T (pore = value <= T; CLI --threshold, "
            "add --pore-above for bright pores) or pore_value=V (pore = value == V; CLI --pore-value)"
        )
    return a != 0, "nonzero"


def _pore_uint8(pore: np.ndarray, a: np.ndarray, how: str) -> np.ndarray:
    """``pore`` as a uint8 array that never aliases the caller's ``a``; all-solid/all-pore refused."""
    if pore is not a and pore.flags.c_contiguous:
        out = pore.view(np.uint8)  # a fresh mask: no copy needed
    else:  # never alias the caller's array
        out = np.array(pore, dtype=np.uint8, order="C", copy=True)
    n_pore = int(np.count_nonzero(out))
    if n_pore == 0:
        raise InputError(
            f"no pore voxel after segmentation (pore = {how}); check invert/threshold/pore_value "
            "(1/True/nonzero = pore by default; invert=True or CLI --invert if 0 is pore)"
        )
    if n_pore == out.size:
        raise InputError(
            f"every voxel is pore after segmentation (pore = {how}); check invert/threshold/pore_value "
            "(invert=True or CLI --invert if 0 is pore)"
        )
    return out


# --------------------------------------------------------------------------------------------
# plausibility
# --------------------------------------------------------------------------------------------
class PlausibilityWarning(UserWarning):
    """An input that is allowed but probably a mistake (e.g. a unit typed wrongly); names the likely cause."""


#: Voxel sizes outside this range (m) are refused: no rock image has them.
VOXEL_SIZE_LIMITS = (1e-10, 1.0)
#: Voxel sizes outside this range (m) are read with a :class:`PlausibilityWarning`.
PLAUSIBLE_VOXEL_SIZE = (1e-9, 1e-3)


def check_voxel_size(vs: float, source: str = "voxel size") -> float:
    """Return ``vs`` (m); refuse it outside :data:`VOXEL_SIZE_LIMITS`, warn outside :data:`PLAUSIBLE_VOXEL_SIZE`.

    Raises
    ------
    InputError
        ``vs`` is not a length a rock image can have (e.g. 1e300, or micrometres typed as metres: 5.3).
    """
    lo, hi = VOXEL_SIZE_LIMITS
    if not lo <= vs <= hi:
        raise InputError(f"{source} = {vs:g} m is not the voxel size of a rock image (allowed {lo:g} to {hi:g} m); "
                         "give it in metres, e.g. 5.345e-6 for 5.345 um")
    plo, phi = PLAUSIBLE_VOXEL_SIZE
    if not plo <= vs <= phi:
        import warnings

        hint = "micrometres typed as metres or millimetres?" if vs > phi else "metres typed as nanometres?"
        warnings.warn(f"{source} = {vs:g} m is outside 1 nm - 1 mm, where micro-CT voxels are ({hint}); "
                      "porefsi reads voxel sizes in metres", PlausibilityWarning, stacklevel=2)
    return vs


# --------------------------------------------------------------------------------------------
# readers
# --------------------------------------------------------------------------------------------
def _npz_member(z, key: str, path) -> tuple[tuple, np.dtype]:
    """(shape, dtype) of array ``key`` of an open ``.npz``, from its header alone."""
    with z.zip.open(f"{key}.npy") as fh:
        shape, dtype, _ = npy_header(fh, f"{path} [{key!r}]")
    return shape, dtype


def _read_npz(path: Path, key: str | None):
    with np.load(path, allow_pickle=False) as z:
        keys = list(z.files)
        if key is not None:
            if key not in keys:
                raise InputError(f"{path} has no array {key!r}; its keys are {keys}")
        else:
            found = [k for k in _NPZ_KEYS if k in keys]
            if found:
                key = found[0]
            else:
                three = [k for k in keys if len(_npz_member(z, k, path)[0]) == 3]
                if len(three) != 1:
                    net = " (it looks like a pore-network file)" if "pore.coords" in keys else ""
                    raise InputError(
                        f"cannot tell which array of {path} is the image{net}: keys {keys}, "
                        f"{len(three)} of them 3-D; pass key=... (CLI --key)"
                    )
                key = three[0]
        shape, dtype = _npz_member(z, key, path)
        require_memory(shape, dtype, f"{path} [{key!r}]")
        arr = z[key]
        vs = None
        for k in ("voxel_size_m", "voxel_size"):
            if k in keys:
                v = np.asarray(z[k], dtype=float).reshape(-1)
                if v.size not in (1, 3) or np.ptp(v) > 1e-9 * abs(v).max():
                    raise InputError(f"{path}: {k} = {v} is not one cubic voxel size; pass voxel_size=...")
                vs = float(v[0])
                break
        origin = np.asarray(z["origin_m"], dtype=float) if "origin_m" in keys else None
    return _require_3d(arr, f"{path} [{key!r}]"), vs, origin


def _read_npy(p: Path) -> np.ndarray:
    """An ``.npy`` image, its header checked first (3-D, numeric, complete, fits in memory)."""
    with open(p, "rb") as fh:
        shape, dtype, _ = npy_header(fh, p)
        offset = fh.tell()
    _require_3d(np.broadcast_to(np.zeros((), dtype), shape), str(p))  # a view: nothing allocated
    require_memory(shape, dtype, p)
    need = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if p.stat().st_size - offset < need:
        raise InputError(f"{p} is truncated: its header says {shape} x {dtype} ({need} bytes of data) but the file "
                         f"holds {p.stat().st_size - offset}; copy the complete file again")
    return _require_3d(np.load(p, allow_pickle=False), str(p))


@dataclasses.dataclass(frozen=True)
class RawLayout:
    """How a headerless raw file (``.raw``, ``.bin``, ``.dat`` without a ``.mhd``) stores its voxels.

    Attributes
    ----------
    shape : sequence of 3 int
        (nx, ny, nz).
    dtype : str or numpy dtype
        Voxel type, e.g. ``'uint8'``, ``'<u2'``, ``'>u2'`` (big-endian).
    order : {'F', 'C'}, default 'F'
        'F' = x varies fastest in the file (MetaImage, ImageJ, pnextract); 'C' = z fastest
        (``ndarray.tofile`` of a C-ordered (nx, ny, nz) array).
    """

    shape: tuple
    dtype: object
    order: str = "F"


def _read_any(p: Path, suffix: str, raw: RawLayout | None, key, mhd_unit, voxel_size):
    """Dispatch on the suffix; return (array, voxel size from the file or None, origin or None)."""
    shape, dtype, raw_order = (None, None, "F") if raw is None else (raw.shape, raw.dtype, raw.order)
    file_vs = origin = None
    if suffix == ".npy":
        arr = _read_npy(p)
    elif suffix == ".npz":
        arr, file_vs, origin = _read_npz(p, key)
    elif suffix == ".mhd":
        arr, file_vs, origin = _read_mhd(p, mhd_unit, voxel_size)
    elif suffix in (".raw", ".bin", ".dat", ".raw.gz"):
        hdr = p.parent / (p.name[: -len(suffix)] + ".mhd")
        if shape is None and dtype is None and hdr.exists():
            arr, file_vs, origin = _read_mhd(hdr, mhd_unit, voxel_size)
        elif shape is None or dtype is None:
            raise InputError(
                f"{p} is raw voxel data without a header: pass raw=RawLayout(shape=(nx, ny, nz), dtype=...) (CLI "
                f"--shape NX NY NZ --dtype uint8), or put a MetaImage header {hdr.name} next to it"
            )
        elif suffix == ".raw.gz":
            raise InputError(f"{p}: gzipped raw data needs a .mhd header; decompress it or add {hdr.name}")
        else:
            arr = _read_raw(p, shape, dtype, raw_order)
    elif suffix in (".tif", ".tiff"):
        arr, file_vs = _read_tiff(p, override=voxel_size is not None)
    else:
        raise InputError(
            f"unknown image format {p.suffix!r} of {p}; supported: {', '.join(READ_FORMATS)}"
        )
    return arr, file_vs, origin


def read_image(path, *, voxel_size: float | None = None, raw: RawLayout | None = None, key: str | None = None,
               mhd_unit: str | float = "auto", **segmentation) -> VoxelImage:
    """Read a rock image and segment it into a :class:`VoxelImage` (1 = pore).

    Parameters
    ----------
    path : str or Path
        ``.npy``, ``.npz``, ``.mhd`` (+ data file), ``.raw`` (with a ``.mhd`` of the same stem, or
        ``shape`` and ``dtype``), ``.bin``/``.dat`` (``shape`` and ``dtype``), ``.tif``/``.tiff``.
    voxel_size : float, optional
        Voxel edge length, m, finite and > 0 (checked before the file is read). Overrides the
        file's; required when the file has none.
    raw : RawLayout, optional
        Headerless raw files: shape, voxel type and byte order of the voxels.
    key : str, optional
        ``.npz``: the array to read.
    mhd_unit : {'auto', 'm', 'mm', 'um', 'nm'} or float, default 'auto'
        Length unit of MetaImage ``ElementSpacing``/``Offset`` (a float is metres per unit).
        ``'auto'`` follows pnextract (Imperial College): a ``Unit = u`` line (metres per unit) if
        the header has one; else spacing > 0.02 is micrometres and spacing <= 1e-4 is metres;
        spacing in between is ambiguous (metres for pnextract, millimetres for ITK tools) and
        raises :class:`InputError` asking for ``mhd_unit``.
    **segmentation
        How to tell pore from solid (``threshold``, ``pore_value``, ``invert``, ``pore_above``):
        passed on to :func:`segment`.

    Returns
    -------
    VoxelImage
        Origin from the file (``.npz`` ``origin_m``, MetaImage ``Offset``) or zero.

    Raises
    ------
    InputError
        Missing file, unknown suffix, wrong raw size, non-3-D array, unknown voxel size or one
        that is not a positive number, ambiguous pore convention, all-solid or all-pore image.
        Each message names the fix.

    Notes
    -----
    MetaImage ``DimSize = nx ny nz`` lists x first and x varies fastest on disk, so the raw
    bytes are read in Fortran order into an (nx, ny, nz) array: porefsi's x, y, z are the file's.
    TIFF stacks are read as x = column, y = row, z = page, i.e. ``tifffile.imread(path)``
    transposed by ``(2, 1, 0)``; the same volume saved as TIFF and as raw + mhd reads the same.
    ``Offset`` is the centre of the first voxel (ITK, VTK); ``VoxelImage.origin`` its corner.

    Examples
    --------
    >>> import os, tempfile
    >>> path = write_image(load_sample(), os.path.join(tempfile.mkdtemp(), "berea.mhd"))
    >>> img = read_image(path)
    >>> img.shape, img.voxel_size, round(img.porosity, 5)
    ((120, 120, 120), 5.345e-06, 0.18821)
    """
    if voxel_size is not None:  # before reading: a bad value must not surface as a read error
        voxel_size = positive_length(voxel_size, "voxel_size", "; pass a number such as 5.345e-6 (CLI --voxel-size M)")
    p, suffix = _image_path(path)
    try:
        arr, file_vs, origin = _read_any(p, suffix, raw, key, mhd_unit, voxel_size)
    except InputError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        # numpy's advice to pass allow_pickle is never right for a user's file: porefsi loads no pickles
        cause = "not numpy data (random bytes, a pickle or another format)" if "allow_pickle" in str(exc) \
            else f"{type(exc).__name__}: {exc}"
        raise InputError(f"cannot read {p} as {suffix} ({cause}); is the file complete "
                         "and of the format its suffix says?") from None
    vs = voxel_size if voxel_size is not None else file_vs
    if vs is None:
        raise InputError(
            f"voxel size unknown for {p}: the file does not store one; pass voxel_size=... in metres "
            "(CLI --voxel-size M, e.g. 5.345e-6)"
        )
    check_voxel_size(vs, "voxel_size (--voxel-size)" if voxel_size is not None else f"the voxel size stored in {p}")
    phases = segment(arr, **segmentation)  # a new array (never a view of arr)
    del arr
    phases.setflags(write=False)  # so VoxelImage keeps it without a copy (1 byte per voxel saved)
    return VoxelImage(phases, vs, np.zeros(3) if origin is None else origin)


def _image_path(path) -> tuple[Path, str]:
    """``path`` as a Path to an existing file, and its lower-case suffix (``.raw.gz`` kept whole)."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"image file {p} does not exist; check the path (run from the right directory?)")
    if p.is_dir():
        raise InputError(f"{p} is a directory; pass an image file ({', '.join(READ_FORMATS)})")
    return p, "".join(p.suffixes[-2:]).lower() if p.name.lower().endswith(".raw.gz") else p.suffix.lower()

# --------------------------------------------------------------------------------------------
# writers
# --------------------------------------------------------------------------------------------
def write_image(image: VoxelImage, path) -> Path:
    """Write ``image`` to ``.npz`` or to a MetaImage ``.mhd`` + ``.raw`` pair.

    Parameters
    ----------
    image : VoxelImage
        The image; not modified.
    path : str or Path
        ``*.npz`` (keys ``image`` uint8 1 = pore, ``voxel_size_m``, ``origin_m``), ``*.mhd`` (writes
        ``*.raw`` next to it) or ``*.raw`` (writes ``*.mhd`` next to it).

    Returns
    -------
    Path
        The file to pass to :func:`read_image` (the ``.npz`` or the ``.mhd``).

    Notes
    -----
    Both formats round-trip exactly (voxels, voxel size and origin bit for bit). The MetaImage
    header stores lengths in metres with ``Unit = 1`` (pnextract's keyword; ITK and ParaView ignore
    it and show metres, matching porefsi's network files), ``Offset`` = centre of voxel (0, 0, 0),
    ``DimSize = nx ny nz`` with x fastest in the ``.raw``.

    Examples
    --------
    >>> import os, tempfile
    >>> img = VoxelImage(np.eye(3, dtype=np.uint8)[:, :, None], 2e-6)
    >>> write_image(img, os.path.join(tempfile.mkdtemp(), "eye.raw")).name
    'eye.mhd'
    """
    if not isinstance(image, VoxelImage):
        raise InputError(f"write_image needs a VoxelImage, got {type(image).__name__}")
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".npz":
        np.savez_compressed(p, image=image.phases, voxel_size_m=np.float64(image.voxel_size),
                            origin_m=np.asarray(image.origin, dtype=np.float64))
        return p
    if suffix not in (".mhd", ".raw"):
        raise InputError(f"cannot write {p.suffix!r}; write_image writes .npz, .mhd (+ .raw) or .raw (+ .mhd)")
    return _write_mhd(image, p)


# --------------------------------------------------------------------------------------------
# built-in sample
# --------------------------------------------------------------------------------------------
def load_sample(name: str = "berea120") -> VoxelImage:
    """Load a built-in sample image (see :data:`SAMPLES`).

    Parameters
    ----------
    name : str, default 'berea120'
        Sample name.

    Returns
    -------
    VoxelImage
        The segmented sample, 1 = pore, voxel size from the file.

    Raises
    ------
    InputError
        If ``name`` is not a sample.

    Examples
    --------
    >>> img = load_sample()
    >>> img.shape, img.voxel_size
    ((120, 120, 120), 5.345e-06)
    """
    if name not in SAMPLES:
        raise InputError(f"unknown sample {name!r}; built-in samples: {', '.join(sorted(SAMPLES))}")
    ref = resources.files("porefsi").joinpath("data", SAMPLES[name][0])
    with ref.open("rb") as fh, np.load(fh, allow_pickle=False) as z:
        phases = np.asarray(z["image"])
        vs = float(z["voxel_size_m"])
    return VoxelImage(phases, vs)
