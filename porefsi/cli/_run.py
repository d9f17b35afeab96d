"""``porefsi run``: the main job (interim: extraction + permeability of the built-in sample).

Until the coupled simulation lands (it replaces this module), ``porefsi run`` extracts the
maximal-ball network of the built-in 120³ Berea sample (all pore clusters), computes its absolute
permeability along x, y and z, prints a summary and writes ``DIR/network.npz``,
``DIR/network.vtp`` (with the pressure field of each axis) and ``DIR/summary.json``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from porefsi.cli._common import emit, to_jsonable
from porefsi.errors import InputError

__all__ = ["register", "run"]

DEFAULT_OUT = "porefsi-out"


def run(args: argparse.Namespace) -> int:
    """Run the interim main job; see the module docstring."""
    from porefsi.flow.permeability import absolute_permeability
    from porefsi.image import load_sample
    from porefsi.io.network_vtk import write_network_vtp
    from porefsi.network.convert import save_network
    from porefsi.network.extract import extract_network

    if args.case is not None:
        raise InputError(
            f"case files ({args.case}) arrive with the coupled simulation; for now run 'porefsi run' "
            "without a CASE (built-in sample), or 'porefsi extract IMAGE' / 'porefsi permeability IMAGE'"
        )
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise InputError(f"output {out} exists and is not a folder; pass another -o DIR")
    t0 = time.perf_counter()
    image = load_sample()
    ext = extract_network(image)
    net = ext.network
    t_ext = time.perf_counter() - t0
    z = net.coordination
    summary: dict = {
        "sample": "berea120",
        "shape": list(image.shape),
        "voxel_size_m": image.voxel_size,
        "porosity": image.porosity,
        "n_pores": net.n_pores,
        "n_throats": net.n_throats,
        "mean_coordination": float(z.mean()),
        "seconds_extract": t_ext,
    }
    pressure = {}
    for ax in "xyz":
        res = absolute_permeability(net, ax)
        summary[f"permeability_{ax}_m2"] = res.k_m2
        summary[f"permeability_{ax}_mD"] = res.k_mD
        summary[f"n_excluded_pores_{ax}"] = res.info["n_excluded_pores"]
        pressure[f"pressure_{ax}"] = res.pressure
    try:
        out.mkdir(parents=True, exist_ok=True)
        files = {
            "network_file": save_network(net, out / "network.npz"),
            "vtk_file": write_network_vtp(net, out / "network.vtp", point_data=pressure),
            "summary_file": out / "summary.json",
        }
        summary.update({k: str(v) for k, v in files.items()})
        summary["seconds"] = time.perf_counter() - t0
        files["summary_file"].write_text(json.dumps(to_jsonable(summary), indent=2) + "\n")
    except OSError as exc:
        raise InputError(f"cannot write the outputs to {out}: {exc.strerror or exc}; pass another -o DIR") from None
    emit(summary, args.json)
    return 0


def register(subparsers) -> None:
    """Add the ``run`` subcommand."""
    p = subparsers.add_parser(
        "run",
        help="run the main job (for now: network + permeability of the built-in sample)",
        description="Without CASE: extract the pore network of the built-in 120^3 Berea sample, compute "
        "its permeability along x, y, z, print a summary and write DIR/network.npz, DIR/network.vtp "
        "and DIR/summary.json.",
    )
    p.add_argument("case", nargs="?", default=None, metavar="CASE",
                   help="case file (arrives with the coupled simulation)")
    p.add_argument("-o", "--output", default=DEFAULT_OUT, metavar="DIR",
                   help=f"output folder (default {DEFAULT_OUT})")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run)
