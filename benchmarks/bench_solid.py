"""Solid benchmark: meshing, assembly, AMG setup, one Newton step, one TDG step.

Sizes: the paper's (~57k tets: the 120^3 sample at coarsen 5) and ~1M tets (the sample at
coarsen 2, ~0.9M). Peers in the same run: the scikit-fem forms (reference assembly), Jacobi-CG and
(``--direct``) SuperLU against AMG-CG.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_solid.py [--sizes 5,2] [--direct] [--skip-skfem]

Targets (issue 4): one TDG step (two passes) on ~57k tets < 0.5 s; assembly memory < 2 GiB at
1M tets. The machine is shared: timings are noisy; each is the best of ``--repeat`` runs.
"""

import argparse
import os
import resource
import sys
import time
import tracemalloc
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from porefsi.image.voxel_image import VoxelImage  # noqa: E402
from porefsi.solid import forms  # noqa: E402
from porefsi.solid.bc import uniaxial_bcs  # noqa: E402
from porefsi.solid.linsolve import direct_solver_factory, jacobi_solver_factory, pcg  # noqa: E402
from porefsi.solid.materials import StVenantKirchhoff  # noqa: E402
from porefsi.solid.mesh import mesh_solid  # noqa: E402
from porefsi.solid.model import SolidModel  # noqa: E402
from porefsi.solid.static import solve_static  # noqa: E402


def best(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def gib(nbytes):
    return nbytes / 2**30


def run_size(img, coarsen, args):
    print(f"\n--- coarsen {coarsen} ---", flush=True)
    t_mesh, mres = best(lambda: mesh_solid(img, coarsen=coarsen), 1)
    mesh = mres.mesh
    if mesh.n_tets > 200_000:  # one repeat at the large size (minutes per configuration otherwise)
        args = argparse.Namespace(**{**vars(args), "repeat": 1})
    print(f"mesh: {mesh.n_nodes} nodes, {mesh.n_tets} tets, removed {mres.removed_solid_fraction:.2e}, "
          f"{t_mesh:.2f} s")
    mat = StVenantKirchhoff(20e9, 0.28)
    L = float(np.ptp(mesh.points[:, 2]))
    tracemalloc.start()
    t0 = time.perf_counter()
    model = SolidModel(mesh, mat, uniaxial_bcs("z", rate=-1e-3 * L))
    t_build = time.perf_counter() - t0
    u = np.zeros(model.n_dofs)
    K = model.tangent(u, 1.0)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss = gib(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
    print(f"model build (basis, CSR pattern, BCs): {t_build:.2f} s; n_free = {model.n_dofs}; "
          f"peak traced memory build + first assembly: {gib(peak):.2f} GiB; process maxrss {rss:.2f} GiB")
    a = model._p1
    uu = np.zeros((mesh.n_nodes, 3))
    t_f, _ = best(lambda: a.assemble(uu, want_K=False), args.repeat)
    t_fk, _ = best(lambda: a.assemble(uu, want_K=True), args.repeat)
    t_ext, _ = best(lambda: model.tangent(u + 0.0, 1.0 + 1e-9 * np.random.rand()), args.repeat)
    print(f"numba assembly: f_int {t_f:.3f} s, f_int + K {t_fk:.3f} s, free tangent (assembly + "
          f"condensation) {t_ext:.3f} s")
    if not args.skip_skfem and mesh.n_tets < 200_000:
        feb = model.feb
        full = np.zeros(model.n_full)
        t_sk, _ = best(lambda: (forms.internal_force(feb, mat, full), forms.tangent(feb, mat, full)), 1)
        print(f"scikit-fem forms f_int + K: {t_sk:.3f} s  -> numba speed-up x{t_sk / t_fk:.1f}")
    b = model.internal_force(u, 1.0)
    fac = model.solver_factory
    t_setup, _ = best(lambda: fac.setup(K), 1)
    lv = fac.ml.levels
    print(f"AMG setup: {t_setup:.2f} s ({len(lv)} levels, operator complexity {fac.ml.operator_complexity():.2f})")
    t_amg, (x, info) = best(lambda: pcg(K, b, fac.precondition, rtol=1e-8), args.repeat)
    print(f"AMG-CG solve (rtol 1e-8): {t_amg:.3f} s, {info.iterations} iterations")
    d = K.diagonal()
    t_jac, (x2, info2) = best(lambda: pcg(K, b, lambda r: r / d, rtol=1e-8, maxiter=50000), args.repeat)
    print(f"Jacobi-CG solve (rtol 1e-8): {t_jac:.3f} s, {info2.iterations} iterations "
          f"-> AMG/Jacobi time x{t_amg / t_jac:.2f}")
    if args.direct and mesh.n_tets < 200_000:
        t_lu, _ = best(lambda: direct_solver_factory()(K)(b), 1)
        print(f"SuperLU factor + solve: {t_lu:.2f} s -> x{t_lu / t_amg:.0f} AMG-CG")
    # one Newton step = tangent + solve + residual (hierarchy reused)
    def newton_step():
        Kn = model.tangent(u, 1.0 + 1e-9 * np.random.rand())
        du = model.make_solver(Kn)(-model.internal_force(u, 1.0))
        return model.internal_force(u + du, 1.0)
    t_newton, _ = best(newton_step, args.repeat)
    print(f"one Newton step (assembly + AMG-CG reusing the hierarchy + residual): {t_newton:.3f} s")
    t_static, (us, ninfo) = best(lambda: solve_static(model, 1.0), 1)
    print(f"static solve at strain 1e-3: {t_static:.2f} s, {ninfo.iterations} Newton iterations, "
          f"linear its {ninfo.linear_iterations}")
    try:
        from porefsi.integrators.tdg import TDGStepper
    except ImportError:
        print("porefsi.integrators.tdg not available: TDG step skipped")
        return
    factories = [("AMG-CG", model.make_solver), ("Jacobi-CG", jacobi_solver_factory())]
    if mesh.n_tets < 200_000:
        factories.append(("SuperLU (factored once)", direct_solver_factory()))
    for label, factory in factories:
        for dt in (1e-8, 1e-4):
            stepper = TDGStepper(model, dt, n_iter=2, make_solver=factory, tangent="frozen")
            v = np.zeros(model.n_dofs)
            t_first = time.perf_counter()
            stepper.step(us, v, 1.0)  # first step: tangent + solver setup
            t_first = time.perf_counter() - t_first
            t_tdg, _ = best(lambda s=stepper, v=v: s.step(us, v, 1.0), args.repeat)
            print(f"one TDG step (2 passes, {label}, dt={dt:g} s, omega_max dt ~ "
                  f"{dt * np.sqrt(abs(K).max() / model.mass().min()):.1e}): {t_tdg:.3f} s "
                  f"(first step incl. setup {t_first:.2f} s) [target < 0.5 s at ~57k tets]")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--sizes", default="5,2", help="coarsen values on the 120^3 sample (5: ~57k tets, 2: ~0.9M)")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--direct", action="store_true", help="also time SuperLU (slow: ~30 s at 57k tets)")
    p.add_argument("--skip-skfem", action="store_true")
    p.add_argument("--image", type=Path, default=None,
                   help="npz with keys image, voxel_size_m instead of the built-in 120^3 sample (e.g. "
                        "../shared/data/berea_icl_400.npz, to reach >= 1M tets)")
    p.add_argument("--crop", type=int, default=None, help="use the first N^3 voxels of the image")
    args = p.parse_args(argv)
    d = np.load(args.image if args.image else ROOT / "porefsi" / "data" / "berea_icl_120_paper.npz")
    phases = d["image"]
    if args.crop:
        phases = phases[: args.crop, : args.crop, : args.crop]
    img = VoxelImage(np.ascontiguousarray(phases), float(d["voxel_size_m"]))
    print(f"image {img.shape}, voxel {img.voxel_size:.4g} m", flush=True)
    for c in (int(s) for s in args.sizes.split(",")):
        run_size(img, c, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
