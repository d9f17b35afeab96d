"""Helpers shared by the subcommands: output of summaries, common arguments, reading the image."""

from __future__ import annotations

import argparse
import json
import math

from porefsi.errors import InputError
from porefsi.io.results import jsonable as to_jsonable  # the one JSON converter

__all__ = [
    "emit",
    "positive_float",
    "positive_int",
    "add_image_args",
    "image_from_args",
    "to_jsonable",
    "SEGMENT_OPTIONS",
]


class _ArgumentError(InputError, argparse.ArgumentTypeError):
    """An :class:`InputError` that argparse also reports with its own message."""


def emit(summary: dict, as_json: bool) -> None:
    """Print ``summary`` as one JSON object (``as_json``) or as aligned ``key: value`` lines."""
    data = to_jsonable(summary)
    if as_json:
        print(json.dumps(data))
        return
    width = max((len(k) for k in data), default=0)
    for k, v in data.items():
        if isinstance(v, float):
            v = f"{v:.6g}"
        print(f"{k:<{width}}  {v}")


def positive_float(text: str) -> float:
    """Argparse type: a finite float > 0 (else an error naming the value)."""
    try:
        x = float(text)
    except ValueError:
        raise _ArgumentError(f"expected a number, got {text!r}") from None
    if not math.isfinite(x) or x <= 0:
        raise _ArgumentError(f"expected a positive finite number, got {text!r}")
    return x


def positive_int(text: str) -> int:
    """Argparse type: an integer >= 1."""
    try:
        n = int(text)
    except ValueError:
        raise _ArgumentError(f"expected a positive integer, got {text!r}") from None
    if n < 1:
        raise _ArgumentError(f"expected a positive integer, got {text!r}")
    return n


def _finite_float(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise _ArgumentError(f"expected a number, got {text!r}") from None
    if not math.isfinite(x):
        raise _ArgumentError(f"expected a finite number, got {text!r}")
    return x


#: Attribute names of the segmentation options :func:`add_image_args` adds.
SEGMENT_OPTIONS = ("threshold", "pore_value", "invert", "pore_above")


def add_image_args(p: argparse.ArgumentParser) -> None:
    """Add the options every image-reading subcommand shares (see :func:`image_from_args`)."""
    g = p.add_argument_group("image options")
    g.add_argument(
        "--voxel-size", type=positive_float, default=None, metavar="M",
        help="voxel edge length in metres; required when the file does not store one, "
        "overrides the file's value when given",
    )
    g.add_argument("--threshold", type=_finite_float, default=None, metavar="T",
                   help="grey images: voxels with value <= T are pore (see --pore-above)")
    g.add_argument("--pore-above", action="store_true",
                   help="with --threshold: voxels with value > T are pore (bright pores)")
    g.add_argument("--pore-value", type=_finite_float, default=None, metavar="V",
                   help="labelled images: voxels equal to V are pore")
    g.add_argument("--invert", action="store_true",
                   help="swap pore and solid (binary images where 0 is pore, e.g. ICL berea.tif; "
                   "default: 1/True/nonzero = pore)")
    g.add_argument("--shape", type=positive_int, nargs=3, default=None, metavar=("NX", "NY", "NZ"),
                   help="headerless raw files: voxels along x, y, z (x varies fastest in the file)")
    g.add_argument("--dtype", default=None, metavar="TYPE",
                   help="headerless raw files: voxel type, e.g. uint8, uint16, '>u2' (big-endian)")
    g.add_argument("--raw-order", choices=("F", "C"), default="F",
                   help="headerless raw files: F = x fastest (ImageJ, MetaImage; default), "
                   "C = z fastest (numpy tofile of an (nx, ny, nz) array)")
    g.add_argument("--mhd-unit", default="auto", choices=("auto", "m", "mm", "um", "nm"),
                   help="length unit of ElementSpacing in .mhd headers (default auto: pnextract's rule, "
                   "a 'Unit' line if present, else > 0.02 is um, <= 1e-4 is m, ambiguous otherwise)")
    g.add_argument("--key", default=None, metavar="NAME",
                   help=".npz files: the array to read (default: image/phases/im/data or the only 3-D array)")


def image_from_args(args: argparse.Namespace, path):
    """Read the image a subcommand was given, with the options of :func:`add_image_args`.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments; options that the parser lacks take their defaults.
    path : str or Path or None
        The image file; ``None`` loads the built-in sample (``porefsi.image.load_sample()``),
        where only ``--voxel-size`` applies.

    Returns
    -------
    VoxelImage

    Raises
    ------
    InputError
        Whatever :func:`porefsi.image.read_image` raises; segmentation or raw options given
        without an image file.
    """
    from porefsi.image import VoxelImage, load_sample, read_image

    opt = {name: getattr(args, name, None) for name in (
        "voxel_size", "threshold", "pore_value", "shape", "dtype", "key")}
    flags = {name: bool(getattr(args, name, False)) for name in ("invert", "pore_above")}
    mhd_unit = getattr(args, "mhd_unit", None) or "auto"
    raw_order = getattr(args, "raw_order", None) or "F"
    if path is None:
        given = [f"--{k.replace('_', '-')}" for k, v in {**opt, **flags}.items()
                 if v not in (None, False) and k != "voxel_size"]
        if given:
            raise InputError(
                f"{' '.join(given)} apply to an IMAGE file, but none was given and the built-in sample is "
                "already segmented; pass an IMAGE path or drop those options"
            )
        image = load_sample()
        if opt["voxel_size"] is not None:
            from porefsi.image.io import check_voxel_size

            check_voxel_size(opt["voxel_size"], "--voxel-size")
            image = VoxelImage(image.phases, opt["voxel_size"], image.origin)
        return image
    from porefsi.image.io import RawLayout

    raw = None if opt["shape"] is None and opt["dtype"] is None else RawLayout(opt["shape"], opt["dtype"], raw_order)
    return read_image(path, voxel_size=opt["voxel_size"], raw=raw, key=opt["key"], mhd_unit=mhd_unit,
                      threshold=opt["threshold"], pore_value=opt["pore_value"], invert=flags["invert"],
                      pore_above=flags["pore_above"])
