"""``porefsi extract`` and ``porefsi permeability``: image -> pore network -> absolute permeability.

Also the shared ``IMAGE_OR_NET`` argument (:func:`add_network_args`, :func:`network_from_args`)
that every subcommand working on a network uses: a network file (``NET.npz`` written by
``porefsi extract -o``, or any npz of OpenPNM-keyed arrays with porefsi's extras) is loaded as is;
anything else is read as an image, reduced to its pore cluster percolating along ``--axis`` and
extracted.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from porefsi.cli._common import (
    _ArgumentError,
    add_image_args,
    emit,
    image_from_args,
    positive_float,
)
from porefsi.cli._voxel import add_voxel_args, reject_voxel_options, run_voxel_permeability
from porefsi.errors import InputError
from porefsi.image.voxel_image import AXES
from porefsi.network.floor import FLOOR_PER_HYDRAULIC_RADIUS, MIN_RADIUS_VOXELS
from porefsi.network.network import CONDUCTANCE_MODELS, Network

__all__ = ["register", "add_network_args", "network_from_args", "run_extract", "run_permeability"]

_SAMPLE = "built-in sample berea120"

#: Defaults of :func:`porefsi.network.extract.extract_network`'s tuning parameters, repeated for the
#: ``--help`` text so that building the parser does not import numba (tests check they match).
EXTRACT_DEFAULTS = {"min_radius": "auto", "extent": 2.0, "merge_ratio": 0.9}

#: Attribute names of the extraction options :func:`_add_extraction_args` adds.
EXTRACT_OPTIONS = tuple(EXTRACT_DEFAULTS)


def add_network_args(p: argparse.ArgumentParser) -> None:
    """Add ``IMAGE_OR_NET``, ``--axis``, ``--keep-isolated``, the extraction and the image options to ``p``."""
    p.add_argument(
        "source",
        nargs="?",
        default=None,
        metavar="IMAGE_OR_NET",
        help="a network file (NET.npz from 'porefsi extract -o') or a segmented image "
        "(.npy .npz .raw+.mhd .raw .tif); default: the built-in 120^3 Berea sample",
    )
    _add_axis_args(p)
    _add_extraction_args(p)
    add_image_args(p)


def _fraction(text: str) -> float:
    """Argparse type: a number in (0, 1]."""
    x = positive_float(text)
    if x > 1:
        raise _ArgumentError(f"expected a number in (0, 1], got {text!r}")
    return x


def _at_least_one(text: str) -> float:
    """Argparse type: a finite number >= 1."""
    x = positive_float(text)
    if x < 1:
        raise _ArgumentError(f"expected a number >= 1, got {text!r}")
    return x


def _min_radius(text: str) -> str | float:
    """Argparse type: ``auto`` or a finite number >= 1."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return _at_least_one(text)
    except _ArgumentError:
        raise _ArgumentError(f"expected 'auto' or a finite number >= 1, got {text!r}") from None


def _add_extraction_args(p: argparse.ArgumentParser) -> None:
    d = EXTRACT_DEFAULTS
    g = p.add_argument_group("extraction options (images only; see porefsi.network.extract.extract_network)")
    g.add_argument(
        "--min-radius",
        type=_min_radius,
        default=None,
        metavar="auto|VOXELS",
        help="noise floor: a pore must hold a maximal ball at least this many voxels in radius; 'auto' sets it "
        f"from the image ({FLOOR_PER_HYDRAULIC_RADIUS:g} hydraulic radii from the wall, at least "
        f"{MIN_RADIUS_VOXELS:g} voxels: the same pores at any voxel size); "
        f"a number (>= 1) fixes it in voxels, lower to find pores only a few voxels wide; default {d['min_radius']}",
    )
    g.add_argument(
        "--extent",
        type=_at_least_one,
        default=None,
        metavar="RADII",
        help="family reach in pore radii: a ball of about a pore's size farther than this from its centre "
        "starts a new pore; lower it (>= 1) to split long channels into chains of pores; "
        f"default {d['extent']:g}",
    )
    g.add_argument(
        "--merge-ratio",
        type=_fraction,
        default=None,
        metavar="R",
        help="balls smaller than R times a pore's radius join that pore, and pores whose throat is at least "
        f"R times the smaller pore radius are merged; in (0, 1]; default {d['merge_ratio']:g}",
    )


def _extraction_kwargs(args: argparse.Namespace) -> dict:
    """The extraction options given on the command line, as ``extract_network`` keywords."""
    return {k: getattr(args, k) for k in EXTRACT_OPTIONS if getattr(args, k, None) is not None}


def _add_axis_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--axis", choices=AXES, default="x", help="flow axis (x, y, z = array axes 0, 1, 2); default x")
    p.add_argument(
        "--keep-isolated",
        action="store_true",
        help="images: extract every pore cluster instead of only the one percolating along --axis",
    )
    p.add_argument(
        "--conductance",
        choices=CONDUCTANCE_MODELS,
        default=None,
        help="conduit model: shape_factor (Valvatne-Blunt sections measured from the image; the "
        "default for extracted networks) or paper (circular cylinders of the inscribed radius, "
        "the seed paper's model and radius convention); a network file keeps its own unless given",
    )


def _network_and_details(args: argparse.Namespace) -> tuple[Network, dict]:
    """Network from ``args.source`` plus a summary of how it was obtained."""
    from porefsi.network.convert import is_network_file, load_network

    source = getattr(args, "source", None)
    axis = getattr(args, "axis", "x") or "x"
    t0 = time.perf_counter()
    if source is not None and is_network_file(source):
        image_opts = [
            f"--{k.replace('_', '-')}"
            for k in ("voxel_size", "threshold", "pore_value", "shape", "dtype", "key", *EXTRACT_OPTIONS)
            if getattr(args, k, None) is not None
        ]
        image_opts += [
            f"--{k.replace('_', '-')}" for k in ("invert", "pore_above", "keep_isolated") if getattr(args, k, False)
        ]
        if image_opts:
            raise InputError(
                f"{' '.join(image_opts)} apply to images, but {source} is a network file (it stores its "
                "own voxel size and geometry); drop those options"
            )
        net = load_network(source)
        if getattr(args, "conductance", None):
            net = net.with_conductance(args.conductance)
        return net, {
            "source": str(source),
            "source_kind": "network",
            "conductance": net.conduit_model,
            "voxel_size_m": net.voxel_size,
            "shape": list(net.shape),
            "seconds_read": time.perf_counter() - t0,
        }
    details = _extract_from_image(args, source, axis, keep_isolated=getattr(args, "keep_isolated", False))
    return details.pop("_network"), details


def _extract_from_image(args, source, axis, *, keep_isolated: bool) -> dict:
    from porefsi.image.ops import percolating_cluster
    from porefsi.network.cluster import percolating_pores
    from porefsi.network.extract import _extract, check_memory

    t0 = time.perf_counter()
    image = image_from_args(args, source)
    t_read = time.perf_counter() - t0
    porosity = image.porosity
    if porosity == 0.0:
        raise InputError(
            f"image {source or _SAMPLE} has no pore voxels (all solid); porefsi reads 1 as pore: "
            "check --invert, --threshold or --pore-value"
        )
    # before the cluster filter (about 3 bytes/voxel) and the extraction (about 7): refuse what cannot fit
    check_memory(image.shape, int(round(porosity * image.phases.size)))
    removed = 0.0
    shape = list(image.shape)
    work = image
    if not keep_isolated and porosity < 1.0:
        work, removed = percolating_pores(image, axis)  # the voxels of percolating_cluster, no cluster labels
        if removed == 1.0:
            percolating_cluster(image, axis)  # raises the NetworkError that counts the clusters
    del image
    connected_porosity, voxel_size = work.porosity, work.voxel_size
    holder = [work]
    del work  # handed over: the extraction frees the image once its distance map is computed (1 byte/voxel)
    t1 = time.perf_counter()
    kw = {**EXTRACT_DEFAULTS, "conductance": getattr(args, "conductance", None), **_extraction_kwargs(args)}
    ext = _extract(holder, **kw)
    t_ext = time.perf_counter() - t1
    net = ext.network
    return {
        "_network": net,
        "_extraction": ext,
        "source": str(source) if source is not None else _SAMPLE,
        "source_kind": "image",
        "conductance": net.conduit_model,
        "shape": shape,
        "voxel_size_m": voxel_size,
        "porosity": porosity,
        "axis": axis,
        "removed_fraction": removed,
        "connected_porosity": connected_porosity,
        "network_porosity": float(ext.porosity),
        "min_radius_voxels": ext.info.min_radius,
        "min_radius_rule": ext.info.min_radius_rule,
        "extent_radii": ext.info.extent,
        "merge_ratio": ext.info.merge_ratio,
        "seconds_read": t_read,
        "seconds_extract": t_ext,
    }



def network_from_args(args: argparse.Namespace) -> Network:
    """Return the network named by ``args.source`` (see :func:`add_network_args`).

    A network file is loaded; an image (or the built-in sample when ``source`` is None) is read
    with the image options, reduced to the pore cluster percolating along ``args.axis`` unless
    ``args.keep_isolated``, and extracted with the extraction options (``args.min_radius``,
    ``args.extent``, ``args.merge_ratio``; ``None`` or missing = the default).

    Raises
    ------
    InputError
        Unreadable file, bad image or extraction options, all-solid image, image or extraction
        options with a network file.
    NetworkError
        No pore path along ``args.axis``, or no pore found by the extraction.
    """
    return _network_and_details(args)[0]


def _network_stats(net: Network) -> dict:
    z = net.coordination
    return {
        "n_pores": net.n_pores,
        "n_throats": net.n_throats,
        "mean_coordination": float(z.mean()) if net.n_pores else 0.0,
        "n_isolated_pores": int(np.count_nonzero(z == 0)),
        "mean_pore_radius_m": float(net.pore_radius.mean()) if net.n_pores else 0.0,
        "mean_throat_radius_m": float(net.throat_radius.mean()) if net.n_throats else 0.0,
    }


def _prepare_output(path: str, suffix: str, what: str) -> Path:
    p = Path(path)
    if p.suffix.lower() != suffix:
        raise InputError(f"{what} file {path!r} must end in {suffix}; e.g. {p.with_suffix(suffix).name}")
    if not p.parent.exists():
        raise InputError(f"cannot write {path}: folder {p.parent} does not exist; create it first")
    return p


def run_extract(args: argparse.Namespace) -> int:
    """Run ``porefsi extract``."""
    from porefsi.io.network_vtk import write_network_vtp
    from porefsi.network.convert import save_network, write_statoil

    t0 = time.perf_counter()
    outs = {}
    if args.output:
        outs["network_file"] = _prepare_output(args.output, ".npz", "-o network")
    if args.vtk:
        outs["vtk_file"] = _prepare_output(args.vtk, ".vtp", "--vtk")
    if args.statoil and not Path(args.statoil).parent.exists():
        raise InputError(f"cannot write {args.statoil}_*.dat: folder {Path(args.statoil).parent} does not exist")
    details = _extract_from_image(args, args.image, args.axis, keep_isolated=args.keep_isolated)
    net = details.pop("_network")
    details.pop("_extraction")
    summary = {**details, **_network_stats(net)}
    try:
        if "network_file" in outs:
            save_network(net, outs["network_file"])
        if "vtk_file" in outs:
            write_network_vtp(net, outs["vtk_file"])
        if args.statoil:
            write_statoil(net, args.statoil, args.axis)
            outs["statoil_prefix"] = args.statoil
    except OSError as exc:
        raise InputError(f"cannot write {exc.filename or 'an output file'}: {exc.strerror or exc}") from None
    summary.update({k: str(v) for k, v in outs.items()})
    summary["seconds"] = time.perf_counter() - t0
    emit(summary, args.json)
    return 0


def run_permeability(args: argparse.Namespace) -> int:
    """Run ``porefsi permeability`` (``--method network``, the default, or ``--method voxel``)."""
    if getattr(args, "method", "network") == "voxel":
        return run_voxel_permeability(args, EXTRACT_OPTIONS, _SAMPLE)
    reject_voxel_options(args)
    from porefsi.flow.permeability import absolute_permeability

    t0 = time.perf_counter()
    net, details = _network_and_details(args)
    for k in [k for k in details if k.startswith("_")]:
        details.pop(k)
    res = absolute_permeability(net, args.axis)
    summary = {
        "permeability_m2": res.k_m2,
        "permeability_mD": res.k_mD,
        "axis": res.axis,
        "method": "network",
        **details,
        **_network_stats(net),
        "n_pores_solved": res.n_pores_solved,
        "n_excluded_pores": res.info["n_excluded_pores"],
        "length_m": res.length,
        "area_m2": res.area,
        "solver": res.info["solver"],
        "residual": res.info["residual"],
        "mass_balance_error": res.info["mass_balance_error"],
    }
    summary["seconds"] = time.perf_counter() - t0
    emit(summary, args.json)
    return 0


def register(subparsers) -> None:
    """Add the ``extract`` and ``permeability`` subcommands."""
    p = subparsers.add_parser(
        "extract",
        help="extract the maximal-ball pore network of a segmented image",
        description="Read a segmented image (1 = pore), keep the pore cluster that percolates along "
        "--axis, extract its maximal-ball network (spheres joined by cylinders) and write it.",
    )
    p.add_argument(
        "image",
        nargs="?",
        default=None,
        metavar="IMAGE",
        help="segmented image (.npy .npz .raw+.mhd .raw .tif); default: the built-in Berea sample",
    )
    _add_axis_args(p)
    _add_extraction_args(p)
    p.add_argument(
        "-o",
        "--output",
        default=None,
        metavar="NET.npz",
        help="write the network (OpenPNM-keyed arrays + porefsi extras, readable by numpy.load)",
    )
    p.add_argument(
        "--vtk",
        default=None,
        metavar="NET.vtp",
        help="write a ParaView file: pores as points, throats as lines, with radii",
    )
    p.add_argument(
        "--statoil",
        default=None,
        metavar="PREFIX",
        help="write PREFIX_node1.dat, _node2.dat, _link1.dat, _link2.dat for pnflow "
        "(flow along --axis becomes pnflow's x)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    add_image_args(p)
    p.set_defaults(func=run_extract)

    q = subparsers.add_parser(
        "permeability",
        help="absolute permeability of an image or network",
        description="Single-phase absolute permeability along --axis, in m^2 and mD: by the pore network "
        "(Hagen-Poiseuille conduits, inlet face at dp, outlet at 0; default) or, with --method voxel, by "
        "Stokes flow on the image's pore voxels.",
    )
    add_network_args(q)
    add_voxel_args(q)
    q.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    q.set_defaults(func=run_permeability)
