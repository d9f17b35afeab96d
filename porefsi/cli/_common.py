"""Helpers shared by the subcommands: output of summaries, common arguments."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from porefsi.errors import InputError

__all__ = ["emit", "positive_float", "add_image_args", "to_jsonable"]


def to_jsonable(value):
    """Convert numpy scalars/arrays and non-finite floats into JSON-safe Python values."""
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


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
    """argparse type: a finite float > 0."""
    try:
        x = float(text)
    except ValueError:
        raise InputError(f"expected a number, got {text!r}") from None
    if not math.isfinite(x) or x <= 0:
        raise InputError(f"expected a positive finite number, got {text!r}")
    return x


def add_image_args(p) -> None:
    """Add the arguments every image-reading subcommand shares."""
    p.add_argument(
        "--voxel-size", type=float, default=None, metavar="M",
        help="voxel edge length in metres (required when the file does not carry one)",
    )
    p.add_argument("--threshold", type=float, default=None,
                   help="grey images: voxels with value <= THRESHOLD are pore (see --pore-above)")
    p.add_argument("--pore-value", type=float, default=None,
                   help="multi-valued labelled images: the value that marks pore voxels")
    p.add_argument("--invert", action="store_true",
                   help="binary images: 0 is pore and 1 is solid (default: 1/True = pore)")
