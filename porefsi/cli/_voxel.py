"""``porefsi permeability --method voxel``: the voxel Stokes reference (porefsi.stokes) on the command line.

Also its solution verification: ``--refine``, ``--extrapolate`` (whole-image refinement and
Richardson extrapolation where the finest grid fits in memory, else the sampled defect correction
of :mod:`porefsi.stokes.sampled`) and ``--sampled`` (that estimate, always).
"""

from __future__ import annotations

import argparse
import time

from porefsi.cli._common import _ArgumentError, emit, image_from_args, positive_float, positive_int
from porefsi.errors import InputError

__all__ = ["add_voxel_args", "reject_voxel_options", "run_voxel_permeability"]

#: ``--method voxel`` options and their defaults (a value other than these with --method network is an error).
_VOXEL_DEFAULTS = {"boundary": "pressure", "buffer": 2, "coarsen": 1, "rtol": 1e-6, "maxiter": 3000, "refine": 1,
                   "extrapolate": False, "wall": None, "sampled": False, "blocks": None, "block": None,
                   "resume": None}


def reject_voxel_options(args: argparse.Namespace) -> None:
    given = [f"--{k}" for k, v in _VOXEL_DEFAULTS.items() if getattr(args, k, v) != v]
    if given:
        raise InputError(f"{' '.join(given)}: voxel-solver options, for --method voxel only; add it or drop them")


def run_voxel_permeability(args: argparse.Namespace, extract_options=(), sample: str = "built-in sample") -> int:
    """``porefsi permeability --method voxel``: Stokes flow on the image's pore voxels.

    ``extract_options`` are the network-extraction option names (refused here) and ``sample`` the
    name of the built-in image, both from :mod:`porefsi.cli._extract`.
    """
    from porefsi.stokes import voxel_permeability

    t0, c0 = time.perf_counter(), time.process_time()
    source, image, work = _voxel_image(args, extract_options, sample)
    kw = dict(boundary=args.boundary, buffer=args.buffer, mirror=args.boundary == "periodic", rtol=args.rtol,
              maxiter=args.maxiter)
    if getattr(args, "wall", None) is not None:
        kw["wall"] = args.wall
    ext, extra = None, None
    if args.extrapolate or args.sampled:
        ext, extra = _extrapolate(work, args, kw)
        res = ext.native if extra["mode"] == "sampled" else ext.results[-1]
    else:
        res = voxel_permeability(work, args.axis, refine=args.refine, **kw)
    summary = {
        "permeability_m2": res.k_m2 if ext is None else ext.k_m2,
        "permeability_mD": res.k_mD if ext is None else ext.k_mD,
        "axis": res.axis,
        "method": "voxel",
        "source": str(source) if source is not None else sample,
        "shape": list(image.shape),
        "voxel_size_m": image.voxel_size,
        "porosity": image.porosity,
        "coarsen": args.coarsen,
        "solved_shape": list(work.shape),
        "refine": res.info["refine"],
        "solved_voxel_size_m": work.voxel_size / res.info["refine"],
        "connected_porosity": res.connected_porosity,
        "boundary": res.boundary,
        "wall": res.info["wall"],
        "buffer": res.info["buffer"],
        "length_m": res.length,
        "area_m2": res.area,
        "n_unknowns": res.n_unknowns,
        "iterations": res.iterations,
        "residual": res.residual,
        "flux_spread": res.flux_spread,
        "memory_estimate_bytes": res.memory_bytes,
        "seconds_solve": res.seconds,
        "cpu_seconds": time.process_time() - c0,
    }
    if extra is not None:  # the headline numbers next to k, also in text output; every detail in the dict
        summary.update(permeability_mD_native=extra["permeability_mD_native"], correction_factor=extra["factor"],
                       uncertainty_mD=extra["uncertainty_mD"], extrapolation_mode=extra["mode"], extrapolation=extra)
    summary["seconds"] = time.perf_counter() - t0
    emit(summary, args.json)
    return 0


def _voxel_image(args: argparse.Namespace, extract_options, sample: str):
    """``(source, image, work)``: the checked image and the (coarsened) image to solve."""
    from porefsi.network.convert import is_network_file

    source = getattr(args, "source", None)
    if source is not None and is_network_file(source):
        raise InputError(f"--method voxel needs an image, but {source} is a network file; pass the image it came from")
    ext_opts = [f"--{k.replace('_', '-')}" for k in extract_options if getattr(args, k, None) is not None]
    ext_opts += ["--keep-isolated"] if getattr(args, "keep_isolated", False) else []
    if ext_opts:
        raise InputError(f"{' '.join(ext_opts)}: network-extraction options, unused by --method voxel; drop them")
    if not (args.extrapolate or args.sampled) and (args.blocks is not None or args.block is not None
                                                   or args.resume is not None):
        raise InputError("--blocks/--block/--resume set the sampled estimate: add --extrapolate or --sampled, "
                         "or drop them")
    from porefsi.image.ops import downsample

    image = image_from_args(args, source)
    if image.porosity == 0.0:
        raise InputError(
            f"image {source or sample} has no pore voxels (all solid); porefsi reads 1 as pore: "
            "check --invert, --threshold or --pore-value"
        )
    return source, image, downsample(image, args.coarsen) if args.coarsen > 1 else image


def _extrapolate(work, args: argparse.Namespace, kw: dict):
    """``(result, summary dict)`` of --extrapolate / --sampled."""
    from porefsi.stokes import (
        extrapolated_permeability,
        extrapolation_mode,
        resume_sampled_permeability,
        sampled_permeability,
    )

    top = args.refine if args.refine >= 2 else 3
    buffer = args.buffer if args.boundary == "pressure" else 0
    mode = extrapolation_mode(work, args.axis, top, buffer, sampled=args.sampled)
    if mode == "whole" and args.resume is not None:
        raise InputError(f"--resume keeps the sampled estimate's solves, but refine {top} of the whole image fits "
                         "and is used: add --sampled, or drop --resume")
    if mode == "whole":
        ext = extrapolated_permeability(work, args.axis, levels=range(max(1, top - 2), top + 1), **kw)
        e = ext.extrapolation
        native = e.values[0] if e.levels[0] == 1 else float("nan")
        return ext, {
            "mode": "whole", "levels": list(e.levels), "permeability_mD_levels": list(e.values),
            "permeability_mD_native": native, "factor": e.value / native,
            "permeability_mD_extrapolated": e.value, "uncertainty_mD": e.uncertainty, "order": e.order,
            "order_observed": e.order_observed, "observed_order": e.observed_order,
            "error_finest": e.error_at(e.levels[-1]), "error_unrefined": ext.native_error,
            "iterations_levels": [r.iterations for r in ext.results],
        }
    levels = tuple(range(1, top + 1))  # every level: the order from the last three (as the benchmark)
    blocks = args.blocks if args.blocks is not None else 8
    if args.resume is not None:
        s = resume_sampled_permeability(work, args.resume, args.axis, levels, blocks, args.block, **kw)
    else:
        s = sampled_permeability(work, args.axis, levels=levels, blocks=blocks, block=args.block, **kw)
    return s, {
        "mode": "sampled", "reason": "--sampled" if args.sampled else f"refine {top} of the whole image does not fit",
        "levels": list(s.levels), "permeability_mD_native": s.native_k_mD, "factor": s.factor,
        "factor_uncertainty": s.factor_uncertainty, "factor_se": s.factor_se, "factor_gci": s.factor_gci,
        "permeability_mD_extrapolated": s.k_mD, "uncertainty_mD": s.uncertainty_mD, "order": s.order,
        "order_observed": s.order_observed, "blocks": len(s.blocks), "block_side": s.blocks[0].side,
        "block_origins": [list(b.origin) for b in s.blocks], "block_factors": [b.factor for b in s.blocks],
        "block_permeability_mD_levels": [list(b.k_mD) for b in s.blocks],
        "block_cpu_seconds": [b.cpu_seconds for b in s.blocks], "resume_file": args.resume,
    }


def add_voxel_args(p: argparse.ArgumentParser) -> None:
    d = _VOXEL_DEFAULTS
    p.add_argument("--method", choices=("network", "voxel"), default="network",
                   help="network: extract the pore network and solve Hagen-Poiseuille conduits (default); "
                   "voxel: solve Stokes flow on the image's pore voxels (the reference; slower, images only)")
    g = p.add_argument_group("voxel options (--method voxel; see porefsi.stokes.voxel_permeability)")
    g.add_argument("--boundary", choices=("pressure", "periodic"), default=d["boundary"],
                   help="pressure: reservoirs at two pressures beyond --buffer fluid layers, side faces no-slip "
                   "(default); periodic: the image plus its mirror image along --axis, driven by a body force")
    g.add_argument("--buffer", type=_non_negative_int, default=d["buffer"], metavar="LAYERS",
                   help=f"fluid layers added at inlet and outlet (--boundary pressure); default {d['buffer']}")
    g.add_argument("--coarsen", type=positive_int, default=d["coarsen"], metavar="F",
                   help="solve on the image coarsened F times (block average, pore if >= half pore; "
                   "porefsi.image.downsample): 8x fewer unknowns per factor 2; default 1 (full resolution)")
    g.add_argument("--refine", type=positive_int, default=d["refine"], metavar="N",
                   help="solve on the image refined N times (every voxel split into N^3; the same staircase, "
                   "a finer grid: 8x the unknowns per factor 2; the memory is checked first); default 1")
    g.add_argument("--extrapolate", action="store_true",
                   help="solve at refinements N-2..N (N = --refine, default 3; at least 1) and report the "
                   "Richardson-extrapolated k with the observed order and the discretisation error; if the "
                   "whole image refined N times does not fit in memory, the sampled estimate (--sampled)")
    g.add_argument("--sampled", action="store_true",
                   help="the sampled defect correction, also where the whole image's refinement fits: the whole "
                   "image at its own resolution times the pooled k_inf/k_1 of --blocks sub-blocks solved at "
                   "refinements 1..N (--extrapolate picks it by itself when refine N of the whole image does not fit)")
    g.add_argument("--blocks", type=_at_least_two, default=d["blocks"], metavar="K",
                   help="--sampled / --extrapolate: number of sub-blocks (stratified grid; default 8), each solved "
                   "at refinements 1, 2, ..., N")
    g.add_argument("--block", type=positive_int, default=d["block"], metavar="B",
                   help="--sampled / --extrapolate: block side in voxels (default: the largest <= 40 whose finest "
                   "level fits in memory)")
    g.add_argument("--resume", default=d["resume"], metavar="FILE",
                   help="--sampled / --extrapolate (sampled): keep every finished solve (native and each block "
                   "level) in FILE, JSON lines, and take them from it when run again with the same image, axis, "
                   "block side and options (porefsi.stokes.sampled_resume); an interrupted run loses one solve")
    g.add_argument("--wall", choices=("channel", "ghost"), default=d["wall"],
                   help="tangential no-slip closure: channel (exact for plane channels of any width in voxels; "
                   "the default) or ghost (reflection u_ghost = -u, the earlier scheme; 1.5x the flux of a "
                   "2-voxel channel)")
    g.add_argument("--rtol", type=_fraction_open, default=d["rtol"], metavar="TOL",
                   help=f"relative residual reduction at which the solver stops; default {d['rtol']:g}")
    g.add_argument("--maxiter", type=positive_int, default=d["maxiter"], metavar="N",
                   help=f"solver iteration limit; default {d['maxiter']}")


def _non_negative_int(text: str) -> int:
    """Argparse type: a whole number >= 0."""
    try:
        v = int(text)
    except ValueError:
        raise _ArgumentError(f"expected a whole number >= 0, got {text!r}") from None
    if v < 0:
        raise _ArgumentError(f"expected a whole number >= 0, got {text!r}")
    return v


def _fraction_open(text: str) -> float:
    """Argparse type: a number in (0, 1)."""
    x = positive_float(text)
    if x >= 1:
        raise _ArgumentError(f"expected a number in (0, 1), got {text!r}")
    return x




def _at_least_two(text: str) -> int:
    """Argparse type: a whole number >= 2."""
    n = positive_int(text)
    if n < 2:
        raise _ArgumentError(f"expected a whole number >= 2, got {text!r}")
    return n
