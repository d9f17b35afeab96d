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

import gzip
import math
import zipfile
import zlib
from fractions import Fraction
from importlib import resources
from pathlib import Path

import numpy as np

from porefsi.errors import InputError
from porefsi.image.voxel_image import VoxelImage

__all__ = ["segment", "read_image", "write_image", "load_sample", "SAMPLES", "READ_FORMATS", "MHD_UNITS"]

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

#: Metres per file length unit for MetaImage spacing (``mhd_unit``); "auto" is described in
#: :func:`read_image`.
MHD_UNITS = {"m": Fraction(1), "mm": Fraction(1, 10**3), "um": Fraction(1, 10**6), "nm": Fraction(1, 10**9)}

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
        vals = np.flatnonzero(np.bincount(a.reshape(-1).view(np.uint8), minlength=2))
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
    if threshold is not None:
        t = float(threshold)
        if math.isnan(t):
            raise InputError("threshold is NaN; pass a number (pore = value <= threshold)")
        pore = a > t if pore_above else a <= t
        how = f"value {'>' if pore_above else '<='} {threshold:g}"
    elif pore_value is not None:
        v = float(pore_value)
        if math.isnan(v):
            raise InputError("pore_value is NaN; pass the value that marks pore voxels")
        pore = a == v
        how = f"value == {pore_value:g}"
        if not pore.any():
            raise InputError(
                f"pore_value={pore_value:g} does not occur in the image (values found: "
                f"{_distinct(a)}...); pass one of the values present"
            )
    elif a.dtype == bool:
        pore, how = a, "True"
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
        pore, how = a != 0, "nonzero"
    if invert:
        pore = ~pore
        how = f"not ({how})"
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
# readers
# --------------------------------------------------------------------------------------------
def _require_3d(a: np.ndarray, what: str) -> np.ndarray:
    if a.ndim == 3:
        return a
    hint = (
        "; a single slice is 2-D: add an axis, e.g. a[:, :, None], to make a one-voxel-thick image"
        if a.ndim == 2
        else "; pass a (nx, ny, nz) array"
    )
    raise InputError(f"{what} holds a {a.ndim}-D array of shape {a.shape}, need 3-D{hint}")


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
                three = [k for k in keys if z[k].ndim == 3]
                if len(three) != 1:
                    net = " (it looks like a pore-network file)" if "pore.coords" in keys else ""
                    raise InputError(
                        f"cannot tell which array of {path} is the image{net}: keys {keys}, "
                        f"{len(three)} of them 3-D; pass key=... (CLI --key)"
                    )
                key = three[0]
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


def _raw_array(data: np.ndarray, shape, dtype: np.dtype, path, order: str) -> np.ndarray:
    n = int(np.prod(shape)) * dtype.itemsize
    size = data.nbytes
    if size != n:
        raise InputError(
            f"{path} holds {size} bytes of voxel data but shape {tuple(shape)} x {dtype} "
            f"({dtype.itemsize} bytes each) needs {n}; check shape/dtype (and HeaderSize)"
        )
    return data.view(dtype).reshape(tuple(shape), order=order)


def _read_raw(path: Path, shape, dtype, order: str, offset: int = 0) -> np.ndarray:
    try:
        dt = np.dtype(dtype)
    except TypeError:
        raise InputError(f"unknown dtype {dtype!r}; use e.g. 'uint8', 'uint16', '>u2' (big-endian)") from None
    shp = tuple(int(s) for s in np.atleast_1d(np.asarray(shape, dtype=np.int64)))
    if len(shp) != 3 or min(shp) < 1:
        raise InputError(f"raw shape must be 3 positive integers (nx, ny, nz), got {shape!r}")
    if order not in ("F", "C"):
        raise InputError(f"raw order must be 'F' (x fastest, MetaImage/ImageJ) or 'C', got {order!r}")
    data = np.fromfile(path, dtype=np.uint8, offset=offset)
    return _raw_array(data, shp, dt, path, order)


# MetaImage -----------------------------------------------------------------------------------
_MET_TYPES = {
    "MET_UCHAR": "u1", "MET_CHAR": "i1", "MET_USHORT": "u2", "MET_SHORT": "i2", "MET_UINT": "u4",
    "MET_INT": "i4", "MET_ULONG": "u4", "MET_LONG": "i4", "MET_ULONG_LONG": "u8",
    "MET_LONG_LONG": "i8", "MET_FLOAT": "f4", "MET_DOUBLE": "f8",
}
# pnextract/libvoxel processing keywords that change the image when pnextract reads the header.
_PNEXTRACT_COMMANDS = {
    "fillHoles", "reset", "rescale", "pore", "threshold", "threshold101", "Offset", "redirect",
    "direction", "crop", "cropD", "cropf", "resample", "resampleMean", "resampleMax", "resampleMode",
    "resliceZ", "rangeTo", "replaceRange", "read", "readAtZ", "modeFilter", "medianFilter", "medianX",
    "FaceMedian06", "PointMedian032", "faceMedNgrowToFrom", "delense032", "circleOut", "growLabel",
    "keepLargest0", "mapFrom", "Paint", "PaintAdd", "PaintBefore", "PaintAfter", "PaintAddBefore",
    "PaintAddAfter", "operation", "operat",
}
# MetaImage keys pnextract's header loop also accepts after ElementDataFile (lower case).
_MHD_KEYS = {
    "objecttype", "ndims", "elementtype", "offset", "elementsize", "elementspacing", "dimsize", "binarydata",
    "unit", "headersize", "outputformat", "defaultimageformat", "binarydatabyteordermsb",
    "elementbyteordermsb", "compresseddata", "compresseddatasize", "transformmatrix",
    "elementnumberofchannels", "centerofrotation", "anatomicalorientation",
}
_MHD_HARMLESS = {"info", "write", "write8bit", "skip", ";", "sliceToPng", "sliceToPngBW", "end"}


def _parse_mhd(path: Path):
    """Return (fields dict with str values, byte offset just after the ElementDataFile line)."""
    raw = path.read_bytes()
    fields: dict[str, str] = {}
    pos, data_end = 0, None
    tail_cmds = []
    lines = raw.split(b"\n")
    for line in lines:
        pos += len(line) + 1
        text = line.decode("latin-1").strip()
        if data_end is None:
            if not text or "=" not in text:
                continue
            k, v = (s.strip() for s in text.split("=", 1))
            fields[k.lower()] = v
            if k.lower() == "elementdatafile":
                data_end = pos
                if v.upper() == "LOCAL":
                    break
            continue
        # after ElementDataFile: pnextract keeps reading header keys (Unit) and commands.
        if not text or text[0] in "#'":
            continue
        word = text.split()[0].rstrip("=:")
        if word.lower() in _MHD_KEYS and "=" in text:  # pnextract reads header keys here too
            fields[word.lower()] = text.split("=", 1)[1].strip()
        elif word in _PNEXTRACT_COMMANDS:
            tail_cmds.append(text)
        elif word not in _MHD_HARMLESS:
            break
    if "elementdatafile" not in fields:
        raise InputError(f"{path} is not a MetaImage header: no 'ElementDataFile = ...' line")
    if tail_cmds:
        raise InputError(
            f"{path} asks pnextract to process the image after reading ({'; '.join(tail_cmds)}); porefsi "
            "does not run pnextract commands: apply them with porefsi (segment/crop/downsample) and "
            "comment the lines out with '#'"
        )
    return fields, data_end


def _fields_floats(fields, key, path, n=3) -> list[Fraction] | None:
    if key not in fields:
        return None
    try:
        vals = [Fraction(s) for s in fields[key].split()]
    except (ValueError, ZeroDivisionError):
        raise InputError(f"{path}: cannot read {key} = {fields[key]!r} as numbers") from None
    if len(vals) != n:
        raise InputError(f"{path}: {key} must have {n} values, got {fields[key]!r}")
    return vals


def _mhd_unit(fields, spacing, mhd_unit, path) -> Fraction:
    if mhd_unit is not None and mhd_unit != "auto":
        if isinstance(mhd_unit, str):
            key = {"µm": "um", "micron": "um", "microns": "um"}.get(mhd_unit, mhd_unit)
            if key not in MHD_UNITS:
                raise InputError(f"unknown mhd_unit {mhd_unit!r}; use 'auto' or one of {sorted(MHD_UNITS)}")
            return MHD_UNITS[key]
        u = float(mhd_unit)
        if not math.isfinite(u) or u <= 0:
            raise InputError(f"mhd_unit must be positive (metres per file unit), got {mhd_unit!r}")
        return Fraction(u)
    if "unit" in fields:  # pnextract: lengths are multiplied by Unit to give metres
        try:
            u = Fraction(fields["unit"].split()[0])
        except (ValueError, ZeroDivisionError, IndexError):
            raise InputError(f"{path}: cannot read Unit = {fields['unit']!r}") from None
        if u <= 0:
            raise InputError(f"{path}: Unit must be positive (metres per length unit), got {fields['unit']!r}")
        return u
    s = float(spacing[0])
    if s > 0.02:  # pnextract's rule: spacing above 0.02 is in micrometres
        return MHD_UNITS["um"]
    if s <= 1e-4:  # metres (voxels of at most 0.1 mm)
        return MHD_UNITS["m"]
    raise InputError(
        f"{path}: ElementSpacing {s:g} has no unit: pnextract would read it as metres ({s * 1e3:g} mm "
        f"voxels), ITK-based tools write millimetres ({s * 1e3:g} um voxels); state it with "
        "mhd_unit='m' or 'mm' (CLI --mhd-unit), or add a line 'Unit = 1e-3' (metres per unit) to the header"
    )


def _read_mhd(path: Path, mhd_unit, voxel_size=None, order: str = "F"):
    fields, data_end = _parse_mhd(path)
    if fields.get("ndims", "3").strip() != "3":
        raise InputError(f"{path}: NDims = {fields['ndims']}, need a 3-D image")
    if fields.get("elementnumberofchannels", "1").strip() != "1":
        raise InputError(f"{path}: ElementNumberOfChannels = {fields['elementnumberofchannels']}; need 1")
    dfile = fields["elementdatafile"]
    dims = fields.get("dimsize")
    etype = fields.get("elementtype", "").upper()
    if etype not in _MET_TYPES and not dfile.lower().endswith((".tif", ".tiff")):
        raise InputError(f"{path}: unsupported ElementType {fields.get('elementtype')!r}; "
                         f"supported: {sorted(_MET_TYPES)}")
    spacing = _fields_floats(fields, "elementspacing", path) or _fields_floats(fields, "elementsize", path)
    offset = _fields_floats(fields, "offset", path) or _fields_floats(fields, "position", path)
    # read the voxels
    if dfile.lower().endswith((".tif", ".tiff")):
        arr, _ = _read_tiff(path.parent / dfile, override=True)
    else:
        if dims is None:
            raise InputError(f"{path}: no DimSize line; add 'DimSize = nx ny nz'")
        try:
            shape = tuple(int(s) for s in dims.split())
        except ValueError:
            raise InputError(f"{path}: cannot read DimSize = {dims!r}") from None
        if len(shape) != 3:
            raise InputError(f"{path}: DimSize must have 3 values (nx ny nz), got {dims!r}")
        msb = fields.get("binarydatabyteordermsb", fields.get("elementbyteordermsb", "False"))
        dt = np.dtype((">" if msb.strip().lower() == "true" else "<") + _MET_TYPES[etype])
        nbytes = int(np.prod(shape)) * dt.itemsize
        try:
            hsize = int(fields.get("headersize", "0").split()[0])
        except (ValueError, IndexError):
            raise InputError(f"{path}: cannot read HeaderSize = {fields['headersize']!r}") from None
        compressed = fields.get("compresseddata", "false").strip().lower() == "true"
        if dfile.upper() == "LOCAL":
            dpath, start = path, data_end
        else:
            if "%" in dfile or dfile.upper().startswith("LIST"):
                raise InputError(f"{path}: multi-file ElementDataFile {dfile!r} is not supported; "
                                 "merge the slices into one .raw or a TIFF stack")
            dpath = Path(dfile) if Path(dfile).is_absolute() else path.parent / dfile
            if not dpath.exists():
                raise InputError(f"{path}: its data file {dpath} does not exist (ElementDataFile = {dfile})")
            start = 0
        if compressed or dpath.suffix.lower() == ".gz":
            with open(dpath, "rb") as fh:
                fh.seek(start)
                blob = fh.read()
            data = np.frombuffer(gzip.decompress(blob) if dpath.suffix.lower() == ".gz"
                                 else zlib.decompress(blob), dtype=np.uint8)
            data = data[(max(data.size - nbytes, 0) if hsize == -1 else hsize):]
        else:  # MetaImage HeaderSize = -1: the voxels are the last bytes of the file
            skip = max(dpath.stat().st_size - start - nbytes, 0) if hsize == -1 else hsize
            data = np.fromfile(dpath, dtype=np.uint8, offset=start + skip)
        arr = _raw_array(data, shape, dt, dpath, order)
    vs = origin = None
    if spacing is not None:
        if min(spacing) <= 0:
            raise InputError(f"{path}: ElementSpacing must be positive, got {[float(x) for x in spacing]}")
        try:
            if max(spacing) - min(spacing) > Fraction(1, 10**9) * max(spacing):
                raise InputError(f"{path}: ElementSpacing {[float(x) for x in spacing]} is not cubic; porefsi "
                                 "needs cubic voxels: resample the image, or pass voxel_size=... to override")
            units = [_mhd_unit(fields, spacing, mhd_unit, path)] * 3
            vs = float(spacing[0] * units[0])
        except InputError:
            if voxel_size is None:
                raise
            # the user's voxel size states the scale: metres per file unit along each axis
            units = [Fraction(float(voxel_size)) / s for s in spacing]
        if offset is not None:  # Offset = centre of the first voxel (ITK/VTK); origin = its corner
            # exact rational arithmetic, rounded once: porefsi's own headers round-trip bit for bit
            origin = np.array([float((o - s / 2) * u) for o, s, u in zip(offset, spacing, units, strict=True)])
    return arr, vs, origin


# TIFF ----------------------------------------------------------------------------------------
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
                         f"package ({exc}); pip install imagecodecs, or save the stack uncompressed/deflate") from None
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


def _read_any(p: Path, suffix: str, shape, dtype, key, mhd_unit, raw_order, voxel_size):
    """Dispatch on the suffix; return (array, voxel size from the file or None, origin or None)."""
    file_vs = origin = None
    if suffix == ".npy":
        arr = _require_3d(np.load(p, allow_pickle=False), str(p))
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
                f"{p} is raw voxel data without a header: pass shape=(nx, ny, nz) and dtype (CLI "
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


def read_image(
    path,
    *,
    voxel_size: float | None = None,
    shape=None,
    dtype=None,
    threshold: float | None = None,
    pore_value: float | None = None,
    invert: bool = False,
    pore_above: bool = False,
    key: str | None = None,
    mhd_unit: str | float = "auto",
    raw_order: str = "F",
) -> VoxelImage:
    """Read a rock image and segment it into a :class:`VoxelImage` (1 = pore).

    Parameters
    ----------
    path : str or Path
        ``.npy``, ``.npz``, ``.mhd`` (+ data file), ``.raw`` (with a ``.mhd`` of the same stem, or
        ``shape`` and ``dtype``), ``.bin``/``.dat`` (``shape`` and ``dtype``), ``.tif``/``.tiff``.
    voxel_size : float, optional
        Voxel edge length, m. Overrides the file's; required when the file has none.
    shape : sequence of 3 int, optional
        Raw files: (nx, ny, nz).
    dtype : str or numpy dtype, optional
        Raw files: voxel type, e.g. ``'uint8'``, ``'<u2'``, ``'>u2'`` (big-endian).
    threshold, pore_value, invert, pore_above
        How to tell pore from solid; see :func:`segment`.
    key : str, optional
        ``.npz``: the array to read.
    mhd_unit : {'auto', 'm', 'mm', 'um', 'nm'} or float, default 'auto'
        Length unit of MetaImage ``ElementSpacing``/``Offset`` (a float is metres per unit).
        ``'auto'`` follows pnextract (Imperial College): a ``Unit = u`` line (metres per unit) if
        the header has one; else spacing > 0.02 is micrometres and spacing <= 1e-4 is metres;
        spacing in between is ambiguous (metres for pnextract, millimetres for ITK tools) and
        raises :class:`InputError` asking for ``mhd_unit``.
    raw_order : {'F', 'C'}, default 'F'
        Raw files with explicit ``shape``: 'F' = x varies fastest in the file (MetaImage, ImageJ,
        pnextract); 'C' = z fastest (``ndarray.tofile`` of a C-ordered (nx, ny, nz) array).

    Returns
    -------
    VoxelImage
        Origin from the file (``.npz`` ``origin_m``, MetaImage ``Offset``) or zero.

    Raises
    ------
    InputError
        Missing file, unknown suffix, wrong raw size, non-3-D array, unknown voxel size,
        ambiguous pore convention, all-solid or all-pore image. Each message names the fix.

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
    p = Path(path)
    if not p.exists():
        raise InputError(f"image file {p} does not exist; check the path (run from the right directory?)")
    if p.is_dir():
        raise InputError(f"{p} is a directory; pass an image file ({', '.join(READ_FORMATS)})")
    suffix = "".join(p.suffixes[-2:]).lower() if p.name.lower().endswith(".raw.gz") else p.suffix.lower()
    try:
        arr, file_vs, origin = _read_any(p, suffix, shape, dtype, key, mhd_unit, raw_order, voxel_size)
    except InputError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        raise InputError(f"cannot read {p} as {suffix} ({type(exc).__name__}: {exc}); is the file complete "
                         "and of the format its suffix says?") from None
    if voxel_size is not None:
        vs = float(voxel_size)
        if not math.isfinite(vs) or vs <= 0:
            raise InputError(f"voxel_size must be a positive length in metres, got {voxel_size!r}")
    elif file_vs is not None:
        vs = file_vs
    else:
        raise InputError(
            f"voxel size unknown for {p}: the file does not store one; pass voxel_size=... in metres "
            "(CLI --voxel-size M, e.g. 5.345e-6)"
        )
    phases = segment(arr, threshold=threshold, pore_value=pore_value, invert=invert, pore_above=pore_above)
    return VoxelImage(phases, vs, np.zeros(3) if origin is None else origin)


# --------------------------------------------------------------------------------------------
# writers
# --------------------------------------------------------------------------------------------
def _decimal(x: Fraction) -> str:
    """A decimal string that :class:`~fractions.Fraction` parses back to exactly ``x``.

    ``x`` must have a terminating decimal expansion (denominator 2**a * 5**b).
    """
    den, a, b = x.denominator, 0, 0
    while den % 2 == 0:
        den, a = den // 2, a + 1
    while den % 5 == 0:
        den, b = den // 5, b + 1
    if den != 1:  # pragma: no cover - callers pass float/decimal sums only
        raise ValueError(f"{x} has no terminating decimal expansion")
    k = max(a, b)
    return f"{x.numerator * 10**k // x.denominator}e-{k}"


def _offset_text(origin: float, spacing_text: str) -> str:
    """Offset (voxel-centre position) text whose exact reading minus half the spacing is ``origin``.

    The reader computes ``float(Fraction(offset) - Fraction(spacing) / 2)``; the shortest repr of the
    centre usually satisfies that; otherwise the exact (longer) decimal is written.
    """
    half = Fraction(spacing_text) / 2
    target = Fraction(origin) + half
    short = repr(float(target))
    if float(Fraction(short) - half) == origin:
        return short
    return _decimal(target)


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
    hdr, raw = p.with_suffix(".mhd"), p.with_suffix(".raw")
    sp = repr(float(image.voxel_size))
    offset = " ".join(_offset_text(float(o), sp) for o in image.origin)
    nx, ny, nz = image.shape
    header = (
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
        "CompressedData = False\n"
        f"DimSize = {nx} {ny} {nz}\n"
        f"ElementSpacing = {sp} {sp} {sp}\n"
        f"Offset = {offset}\n"
        "Unit = 1\n"
        "ElementType = MET_UCHAR\n"
        f"ElementDataFile = {raw.name}\n"
    )
    image.phases.ravel(order="F").tofile(raw)
    hdr.write_text(header, encoding="ascii")
    return hdr


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
