"""MetaImage (``.mhd`` + ``.raw``) headers and raw voxel files: parse, read and write.

Private to :mod:`porefsi.image.io` (use :func:`porefsi.image.read_image` and
:func:`porefsi.image.write_image`). ``DimSize = nx ny nz`` lists x first and x varies fastest on
disk, so raw bytes are read in Fortran order into an (nx, ny, nz) array. Header lengths are
converted to metres with exact rational arithmetic (:class:`~fractions.Fraction`), following
pnextract's ``Unit`` keyword and its spacing rule when the header states no unit (see
:func:`porefsi.image.read_image`, ``mhd_unit``). ``Offset`` is the centre of the first voxel
(ITK, VTK); ``VoxelImage.origin`` is its corner.
"""

from __future__ import annotations

import gzip
import math
import zlib
from fractions import Fraction
from pathlib import Path

import numpy as np

from porefsi.errors import InputError
from porefsi.image._memory import require_memory
from porefsi.image._tiff import _read_tiff
from porefsi.image.voxel_image import VoxelImage

#: Metres per file length unit for MetaImage spacing (``mhd_unit``); "auto" is described in
#: :func:`porefsi.image.read_image`. Public as ``porefsi.image.io.MHD_UNITS``.
MHD_UNITS = {"m": Fraction(1), "mm": Fraction(1, 10**3), "um": Fraction(1, 10**6), "nm": Fraction(1, 10**9)}


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
    require_memory(shp, dt, path)
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
        if min(shape) < 1:
            raise InputError(f"{path}: DimSize must be 3 positive integers, got {dims!r}")
        require_memory(shape, dt, path)
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


# writer --------------------------------------------------------------------------------------
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


def _write_mhd(image: VoxelImage, p: Path) -> Path:
    """Write ``image`` as ``p.mhd`` + ``p.raw`` (uint8, x fastest, metres); return the ``.mhd`` path."""
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
