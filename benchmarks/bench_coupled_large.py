"""The coupled run on the whole 400³ Berea (and crops of it): wall, CPU and peak memory per stage.

Stages of the set-up (image read, crop, percolating cluster, extraction, meshing, solid model,
interface, drainage) are timed one by one, then the exchange steps of the coupled loop (with
the loop's own per-stage timing). Peak memory is the resident set (``VmHWM`` reset at each stage,
Linux) -- the true peak of the stage, with what the process already held.

Run: ``python benchmarks/bench_coupled_large.py [--sizes 120 200 280 400] [--t-end 20] [--cap-gib 9]``
(the image defaults to ``berea_icl_400.npz`` in ``$POREFSI_DATA`` or ``../shared/data``; crops are centred).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _data import data_file  # noqa: E402
from _stages import Stages, cap_memory  # noqa: E402

from porefsi.case import Case  # noqa: E402
from porefsi.case.problem import coupled_options  # noqa: E402
from porefsi.case.resources import estimate_run  # noqa: E402
from porefsi.coupling import CoupledRun  # noqa: E402
from porefsi.coupling.problem import CoupledProblem, build_solid  # noqa: E402
from porefsi.image import crop, percolating_cluster, read_image  # noqa: E402
from porefsi.network.extract import extract_network  # noqa: E402

DEFAULT_IMAGE = str(data_file("berea_icl_400.npz"))


def run(path: str, size: int, t_end: float, solver: str | None, max_steps: int | None) -> dict:
    st = Stages()
    w0, c0 = time.perf_counter(), time.process_time()
    print(f"\n== {size}^3 crop, t_end {t_end} s, solver {solver or '(case default)'} ==")
    print(Stages.header())
    with st("image read"):
        img = read_image(path)
    if size < img.shape[0]:
        with st("crop"):
            lo = [(n - size) // 2 for n in img.shape]
            img = crop(img, lo, [a + size for a in lo])
    case = Case().replace(drainage={"t_end": t_end}, output={"figures": False, "vtk": False})
    if solver:
        case = case.replace(solid={"linear_solver": solver})
    opts = coupled_options(case)
    with st("estimate"):
        est = estimate_run(img, case.solid.coarsen, case.solid.linear_solver)
    print(f"    -- estimate: {est.describe()}, peak ~{est.peak_bytes / 2**30:.2f} GiB "
          f"({', '.join(f'{k} {v / 2**30:.2f}' for k, v in est.bytes_by_part.items())} GiB)")
    with st("percolating cluster"):
        perc = percolating_cluster(img, opts.axis).image
    with st("extraction"):
        ex = extract_network(perc, conductance=opts.network.conductance)
    with st("mesh + solid model"):
        mres, model = build_solid(img, opts.solid)
    with st("interface build"):
        itf = opts.interface.build(ex.network, ex.labels, mres.mesh, voxel_size=img.voxel_size,
                                   origin=img.origin, model=model)
    problem = CoupledProblem(img, ex, mres, itf, model, opts)
    print(f"    -- {ex.network.n_pores} pores, {ex.network.n_throats} throats, {mres.mesh.n_nodes} nodes, "
          f"{mres.mesh.n_tets} tets, {model.n_dofs} free dofs, interface nnz {itf.operator.nnz}")
    with st("drainage + run set-up"):
        run = CoupledRun(problem)
    n = 0
    while run.step_index < run.n_steps:
        n += 1
        with st(f"exchange step {n}"):
            rec = run.advance()
        parts = ", ".join(f"{k} {v:.2f}" for k, v in rec.cpu_seconds.items())
        print(f"      t = {rec.t:g} s; CPU by part: {parts}; max|u| {rec.row['max_displacement_m']:.3e} m, "
              f"sw {rec.row['sw']:.4f}", flush=True)
        if max_steps is not None and n >= max_steps:
            break
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    peak = max(r["peak"] for r in st.rows)
    print(f"  total: wall {wall:.1f} s, CPU {cpu:.1f} s, peak {peak:.2f} GiB (estimated {est.peak_bytes / 2**30:.2f}), "
          f"load {os.getloadavg()[0]:.2f}")
    return {"size": size, "wall": wall, "cpu": cpu, "peak": peak, "estimated_peak": est.peak_bytes / 2**30,
            "n_pores": ex.network.n_pores, "n_tets": mres.mesh.n_tets, "n_dofs": model.n_dofs,
            "linear_solver": model.linear_solver, "stages": st.rows}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--image", default=DEFAULT_IMAGE)
    ap.add_argument("--sizes", type=int, nargs="+", default=[120, 200, 280, 400])
    ap.add_argument("--t-end", type=float, default=20.0)
    ap.add_argument("--solver", default=None, help="solid.linear_solver (default: the case default)")
    ap.add_argument("--max-steps", type=int, default=None)
    ap.add_argument("--cap-gib", type=float, default=9.0, help="address-space cap of this process")
    ap.add_argument("--json", default=None, help="write the per-stage rows of every size to this file")
    args = ap.parse_args()
    cap_memory(args.cap_gib)
    warnings.simplefilter("ignore", DeprecationWarning)
    warnings.showwarning = lambda msg, cat, *a, **k: print(f"    -- {cat.__name__}: {msg}")
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())} ({os.cpu_count()} cores)")
    out = [run(args.image, s, args.t_end, args.solver, args.max_steps) for s in args.sizes]
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
