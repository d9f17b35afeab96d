"""``porefsi solid``: uniaxial compression of the rock frame of an image (quasi-static Newton)."""

from __future__ import annotations

import time

import numpy as np

from porefsi.cli._common import add_image_args, emit, image_from_args, positive_float

__all__ = ["register", "run"]


def register(subparsers) -> None:
    """Add the ``solid`` subcommand."""
    p = subparsers.add_parser(
        "solid",
        help="uniaxial compression of the solid frame (tetrahedral FE, nonlinear elasticity)",
        description="Mesh the solid of IMAGE with tetrahedra and compress it along an axis with the paper's "
        "boundary conditions: fixed min face, displaced max face, rollers on the lateral faces. "
        "Writes the deformed mesh with displacement and von Mises stress (.vtu).",
    )
    p.add_argument("image", nargs="?", default=None, metavar="IMAGE",
                   help="segmented image (1 = pore); default: the built-in 120^3 Berea sample")
    add_image_args(p)
    p.add_argument("--coarsen", type=int, default=5, metavar="N",
                   help="block size before meshing (default 5: ~57k tets on the 120^3 sample, the paper's size)")
    p.add_argument("--strain", type=positive_float, default=1e-3, metavar="E",
                   help="nominal compressive strain (default 1e-3)")
    p.add_argument("--axis", default="z", choices=("x", "y", "z"), help="loading axis (default z)")
    p.add_argument("--material", default="svk", choices=("svk", "neo-hookean"),
                   help="St Venant-Kirchhoff (the paper's) or compressible neo-Hookean")
    p.add_argument("--youngs-modulus", type=positive_float, default=20e9, metavar="PA",
                   help="grain Young's modulus, Pa (default 20e9, the paper's)")
    p.add_argument("--poisson", type=float, default=0.28, help="grain Poisson ratio (default 0.28)")
    p.add_argument("--steps", type=int, default=1, help="load increments (default 1)")
    p.add_argument("--order", type=int, default=1, choices=(1, 2), help="element order (default 1)")
    p.add_argument("-o", "--output", default=None, metavar="DIR", help="write solid.vtu and summary.json here")
    p.add_argument("--overwrite", action="store_true",
                   help="replace solid.vtu and summary.json of an earlier run in DIR (refused without it)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run)


def _refuse_existing(out, overwrite: bool) -> None:
    """Refuse to replace the results of an earlier run in ``out`` unless ``overwrite``."""
    from porefsi.errors import InputError

    if out is None or overwrite or not out.is_dir():
        return
    held = [n for n in ("solid.vtu", "summary.json", "checkpoint.npz") if (out / n).is_file()]
    if held:
        raise InputError(f"output folder {out} already holds results ({', '.join(held)}): pass --overwrite to replace "
                         "them, or pass another -o DIR")


def run(args) -> int:
    """Mesh, compress, write, summarise."""
    from porefsi.io import rundir
    from porefsi.solid.materials import make_material
    from porefsi.solid.mesh import mesh_solid, tet_volumes
    from porefsi.solid.static import uniaxial_compression

    t0 = time.perf_counter()
    out = rundir.check_output_dir(args.output) if args.output else None  # before any work
    _refuse_existing(out, args.overwrite)
    image = image_from_args(args, args.image)
    material = make_material(args.material, E=args.youngs_modulus, nu=args.poisson)
    mres = mesh_solid(image, coarsen=args.coarsen, support_axis=args.axis)
    mesh = mres.mesh
    res = uniaxial_compression(mesh, material, args.strain, axis=args.axis, n_steps=args.steps, order=args.order)
    summary = {
        "n_nodes": mesh.n_nodes,
        "n_tets": mesh.n_tets,
        "coarsen": args.coarsen,
        "material": material.name,
        "removed_solid_fraction": mres.removed_solid_fraction,
        "strain": args.strain,
        "axis": args.axis,
        "effective_modulus_Pa": res.effective_modulus,
        "axial_reaction_N": float(res.reaction["xyz".index(args.axis)]),
        "max_displacement_m": float(np.linalg.norm(res.u, axis=1).max()),
        "max_von_mises_Pa": float(res.von_mises_element.max()),
        "mean_von_mises_Pa": float(np.average(res.von_mises_element, weights=tet_volumes(mesh.points, mesh.tets))),
        "newton_iterations": [i.iterations for i in res.newton],
    }
    if out is not None:  # one run at a time; solid.vtu and summary.json written atomically
        from porefsi.io.results import write_json

        summary["vtu"] = str(out / "solid.vtu")
        with rundir.lock(out), rundir.output_errors(out):
            _refuse_existing(out, args.overwrite)
            mesh.write_vtu(
                out / "solid.vtu",
                point_data={"displacement": res.u, "von_mises_nodal": res.von_mises_nodal},
                cell_data={"von_mises": res.von_mises_element, "cauchy_stress": res.sigma.reshape(-1, 9)},
            )
            summary["seconds"] = time.perf_counter() - t0
            write_json(out / "summary.json", summary)
    summary["seconds"] = time.perf_counter() - t0
    emit(summary, args.json)
    return 0
