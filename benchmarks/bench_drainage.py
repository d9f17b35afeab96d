"""Benchmark: dynamic drainage to breakthrough at the paper's rate on ~250, 10k, 30k and 100k pores.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_drainage.py [--sizes 250 10000 30000 100000]
[--max-seconds S] [--no-prefetch]``. Prints per network: events, fills, solves, skipped solves,
factorisations (and their seconds), base columns of the low-rank solver (and in how many batched
triangular solves, how many were prefetched), refinement steps and seconds (timings on a shared
machine are noisy). Synthetic 3-D cubic lattices with Berea-like sizes (spacing 40 um, pore radii
6-14 um) at the paper's injection rate 1.25e-13 m^3/s; the capillary number
``Ca = mu_n (Q / A_inlet_face) / sigma`` is printed (it falls as the face grows).

With ``--max-seconds`` a run that has not broken through by then stops and prints its progress
and a projection: the fills needed are estimated by quasi-static invasion percolation with
trapping on the same network (at these capillary numbers it breaks through after the same number
of fills to within a few: 10k lattice 1992 vs 1990), and the projected time assumes the measured
seconds per fill stay constant (the factor of the pressure matrix shrinks as pores fill, so this
errs on the long side).

``--image PATH [--tile NX NY NZ]`` adds the network extracted from a rock image, mirror-tiled
(copies alternate with their mirror image, so the pore space is continuous across the seams), e.g.
``--image ../shared/data/berea_icl_400.npz --tile 2 2 2`` for a 63k-pore network of real
topology (800³ voxels, ~5 GB during the extraction).

Peers (when ``openpnm`` is importable, e.g. ``tox -e bench``): no open tool runs a dynamic
drainage, so the line ends with the cost of the quasi-static reference on the same network,
measured in the same run: porefsi's invasion percolation with trapping to breakthrough and
OpenPNM's ``InvasionPercolation`` (whole network, without trapping) with ``apply_trapping``, and
the ratios of the dynamic run to both (``--no-peers`` leaves them out).
"""

import argparse
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # run from a checkout

from porefsi.flow.drainage import PAPER_RATE, DrainageSimulator  # noqa: E402
from porefsi.flow.fluids import Fluids  # noqa: E402
from porefsi.flow.invasion import invasion_percolation  # noqa: E402
from porefsi.network.lattice import lattice_network  # noqa: E402

SHAPES = {250: (10, 5, 5), 10000: (25, 20, 20), 30000: (40, 28, 27), 100000: (50, 45, 45)}


def main(argv=None):
    """Run the benchmark sizes and print one line per network."""
    p = argparse.ArgumentParser()
    p.add_argument("--sizes", type=int, nargs="+", default=[250, 10000])
    p.add_argument("--solver", default="auto")
    p.add_argument("--max-seconds", type=float, default=np.inf)
    p.add_argument("--no-prefetch", action="store_true", help="compute base columns only when needed")
    p.add_argument("--no-peers", action="store_true", help="skip the quasi-static reference timings")
    p.add_argument("--image", help="also run on the network extracted from this rock image (e.g. "
                   "../shared/data/berea_icl_400.npz), mirror-tiled by --tile")
    p.add_argument("--tile", type=int, nargs=3, default=(1, 1, 1), metavar=("NX", "NY", "NZ"),
                   help="mirror copies of --image along x, y, z (continuous across the seams)")
    args = p.parse_args(argv)
    fl = Fluids()
    # warm the numba caches outside the timing
    warm = lattice_network((3, 3, 2), 4e-5, np.random.default_rng(0))
    DrainageSimulator(warm, fl).advance_to(1e3, True)
    if not args.no_peers:  # and OpenPNM's (imports, numba compilation)
        invasion_percolation(warm, fl, axis="x", stop_at_breakthrough=True)
        _openpnm_ip(warm, fl)
    nets = [lattice_network(SHAPES[n], 4e-5, np.random.default_rng(7)) for n in args.sizes]
    if args.image:
        nets.append(_rock_network(args.image, args.tile))
    for net in nets:
        ca = fl.capillary_number(PAPER_RATE, float(np.prod(net.extent[1:])))
        t0 = time.perf_counter()
        sim = DrainageSimulator(net, fl, rate=PAPER_RATE, solver=args.solver, skip_solves=True)
        e = sim._engine
        e.solver.prefetch = not args.no_prefetch
        done = True
        while np.isnan(e.t_breakthrough):
            e.step(np.inf)
            if time.perf_counter() - t0 > args.max_seconds:
                done = False
                break
        dt = time.perf_counter() - t0
        c = sim.counters
        so = e.solver
        st = sim.state
        head = "breakthrough" if done else f"STOPPED after {args.max_seconds:g} s"
        print(f"{net.n_pores:>7d} pores  Ca={ca:.2e}  {head}: events={c['n_events']:>7d}"
              f"  fills={c['n_fills']:>6d}  "
              f"solves={c['n_solves']:>6d}  skipped={c['n_skipped_solves']:>6d}"
              f"  factorisations={c['n_solver_setups']} ({so.seconds_setup:.1f} s)"
              f"  columns={so.n_columns} in {so.n_column_batches} batches ({so.n_prefetched} prefetched)"
              f"  refinements={c['cg_iterations']}  "
              f"t={e.t:.4g} s  Sw={st.sw:.3f}  mass_err={st.mass_balance_error:.1e}  seconds={dt:.2f}  "
              f"events/s={c['n_events'] / dt:.1f}", flush=True)
        dpn = dt
        if not done and c["n_fills"] > 0:
            need = invasion_percolation(net, fl, axis="x", stop_at_breakthrough=True).breakthrough_step + 1
            per_fill = dt / c["n_fills"]
            dpn = need * per_fill
            print(f"{'':>7s}        projection: ~{need} fills to breakthrough (invasion percolation), "
                  f"{per_fill:.3f} s per fill so far -> ~{dpn / 3600:.1f} h", flush=True)
        if not args.no_peers:
            _peers(net, fl, dpn if done or c["n_fills"] > 0 else np.nan, projected=not done)


def _rock_network(path, tile):
    """The network of a rock image mirror-tiled ``tile`` times (a, flip(a), a, ... along each axis)."""
    from porefsi.image.io import read_image
    from porefsi.image.voxel_image import VoxelImage
    from porefsi.network.extract import extract_network

    img = read_image(path)
    a = np.asarray(img.phases)
    for ax, r in enumerate(tile):
        a = np.concatenate([a if i % 2 == 0 else np.flip(a, ax) for i in range(r)], axis=ax)
    t0 = time.perf_counter()
    net = extract_network(VoxelImage(a, img.voxel_size)).network
    print(f"{path} tiled {tuple(tile)} ({'x'.join(map(str, a.shape))} voxels): {net.n_pores} pores, "
          f"{net.n_throats} throats, extracted in {time.perf_counter() - t0:.1f} s", flush=True)
    return net


def _peers(net, fl, dpn_seconds, projected=False):
    """Print the quasi-static references' seconds (porefsi IP, OpenPNM IP) and the DPN's ratios to them."""
    t0 = time.perf_counter()
    ip = invasion_percolation(net, fl, axis="x", stop_at_breakthrough=True)
    t_ip = time.perf_counter() - t0
    line = (f"{'':>7s}        quasi-static: porefsi IP+trapping to breakthrough {t_ip:.2f} s "
            f"({ip.breakthrough_step + 1} fills)")
    t_op, version = _openpnm_ip(net, fl)
    if t_op is None:
        print(line + "; openpnm not installed", flush=True)
        return
    dpn = "projected DPN" if projected else "DPN"
    print(line + f"; OpenPNM {version} InvasionPercolation + apply_trapping (whole network) "
          f"{t_op:.2f} s; {dpn} / porefsi IP = {dpn_seconds / t_ip:.0f}x, {dpn} / OpenPNM IP = "
          f"{dpn_seconds / t_op:.1f}x, porefsi IP / OpenPNM IP = {t_ip / t_op:.2f}", flush=True)


def _openpnm_ip(net, fl):
    """Seconds of OpenPNM's IP + apply_trapping with porefsi's thresholds and a virtual inlet pore."""
    try:
        import openpnm as op
    except ImportError:
        return None, None
    n = net.n_pores
    inlet = np.flatnonzero(net.inlet("x"))
    c = net.throat_conns
    pcb = fl.capillary_pressure(net.pore_radius)
    thr = np.maximum(fl.capillary_pressure(net.throat_radius), np.maximum(pcb[c[:, 0]], pcb[c[:, 1]]))
    t0 = time.perf_counter()
    pn = op.network.Network(coords=np.vstack([net.pore_coords, [[-1.0, 0.0, 0.0]]]),
                            conns=np.vstack([c, np.column_stack([np.full(inlet.size, n), inlet])]))
    phase = op.phase.Phase(network=pn)
    phase["throat.entry_pressure"] = np.concatenate([thr, pcb[inlet]])
    alg = op.algorithms.InvasionPercolation(network=pn, phase=phase)
    alg.set_inlet_BC(pores=[n])
    alg.set_outlet_BC(pores=np.flatnonzero(net.outlet("x")))
    alg.run()
    alg.apply_trapping()
    return time.perf_counter() - t0, op.__version__


if __name__ == "__main__":
    main()
