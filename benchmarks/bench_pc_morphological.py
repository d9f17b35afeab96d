"""Quasi-static Pc-Sw: porefsi's invasion percolation against PoreSpy's morphological drainage.

On one image (default: the 400³ Berea, ``--image``), along array axis 0, sigma = 0.03 N/m,
theta = 0, with trapping:

* PoreSpy 3.2 (peers env) ``porespy.simulations.drainage``: image-based sphere insertion,
  ``pc = 2 sigma / (dt vs)`` with dt the Euclidean distance transform (to the nearest solid voxel
  centre), inlet the first slice, outlet the last, at ``--steps`` geometric Pc steps;
* porefsi: extraction then :func:`porefsi.flow.invasion.invasion_percolation` on

  - ``paper``: the paper's network (digital radii, circular entry pressure 2 sigma / r);
  - ``shape_factor``: the default network (sub-voxel radii, Mayer-Stowe-Princen entry pressures
    of the measured sections);
  - ``shape_factor_circle_law``: the default network with every section made a circle, so the
    entry pressure is 2 sigma / r of the same radii: the law sphere insertion itself applies,
    i.e. the like-for-like comparison of the two *methods* (network vs image).

Printed: Pc at Sw = 0.9 and 0.5 of each and its ratio to PoreSpy's. PoreSpy's curve is a
staircase at the distance map's discrete values (dt = sqrt(n) voxels), so its Pc at a given Sw is
only known to the step bracket, which is printed too. Which entry law is right for angular
sections is settled by ``bench_pc_closed_forms.py`` (straight ducts against closed forms), not
here. ``--porespy-json`` reuses a saved PoreSpy curve (``{"pc": [...], "snw": [...]}``).

Usage (peers env for PoreSpy)::

    /work/peers/bin/python benchmarks/bench_pc_morphological.py --image berea_icl_400.npz \\
        [--porespy-json saved.json] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

from porefsi.flow.fluids import Fluids
from porefsi.flow.invasion import invasion_percolation
from porefsi.image.voxel_image import VoxelImage
from porefsi.network.extract import extract_network
from porefsi.network.network import CIRCLE_SHAPE_FACTOR

SIGMA = 0.03
TARGETS = (0.9, 0.5)


def porespy_curve(pore: np.ndarray, vs: float, n_steps: int | None) -> dict:
    """PoreSpy's sphere-insertion drainage along axis 0: Pc steps (Pa) and non-wetting saturation.

    ``n_steps=None`` ("exact"): the steps are the distinct values of PoreSpy's own Pc field,
    2 sigma / (dt vs) with dt = sqrt(n) voxels, so the saturation is evaluated at every pressure
    where it can change and the curve is PoreSpy's exact staircase (no step bracket).
    """
    import porespy as ps  # noqa: PLC0415 - peers env only
    from edt import edt  # noqa: PLC0415 - PoreSpy's own dependency

    ps.settings.tqdm["disable"] = True
    t = time.process_time()
    dt = edt(pore)
    pc = np.full(pore.shape, np.inf)
    pc[pore] = 2.0 * SIGMA / (dt[pore] * vs)
    inlets = np.zeros_like(pore)
    inlets[0] = pore[0]
    outlets = np.zeros_like(pore)
    outlets[-1] = pore[-1]
    lo, hi = np.percentile(pc[pore], [0.01, 99.9])
    if n_steps is None:
        values = np.unique(pc[pore])
        steps = values[(values >= lo * 0.95) & (values <= hi)]
    else:
        steps = np.geomspace(lo * 0.95, hi, n_steps)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = ps.simulations.drainage(im=pore, pc=pc, dt=dt, inlets=inlets, outlets=outlets, steps=steps)
    snw = [float((res.im_pc[pore] <= p).mean()) for p in steps]
    return {"pc": steps.tolist(), "snw": snw, "cpu_s": time.process_time() - t}


def pc_at(sw, pc, target: float) -> float:
    """Smallest Pc (Pa) at which the wetting saturation is ``target`` or below (NaN if never)."""
    hit = np.flatnonzero(np.asarray(sw) <= target)
    return float(np.asarray(pc)[hit[0]]) if hit.size else float("nan")


def bracket(sw, pc, target: float) -> tuple[float, float]:
    """The last Pc step above ``target`` Sw and the first at or below it (Pa)."""
    sw, pc = np.asarray(sw), np.asarray(pc)
    hit = np.flatnonzero(sw <= target)
    if not hit.size:
        return float("nan"), float("nan")
    i = hit[0]
    return float(pc[max(i - 1, 0)]), float(pc[i])


def circle_law(net):
    """The same network with every section a circle: entry pressure 2 sigma / r everywhere."""
    return net.replace(throat_shape_factor=np.full(net.n_throats, CIRCLE_SHAPE_FACTOR),
                       pore_shape_factor=np.full(net.n_pores, CIRCLE_SHAPE_FACTOR))


def porefsi_curves(pore: np.ndarray, vs: float) -> dict:
    """(Sw, Pc) of invasion percolation along x for each porefsi variant."""
    im = VoxelImage(pore.astype(np.uint8), voxel_size=vs)
    out = {}
    for name in ("paper", "shape_factor"):
        net = extract_network(im, conductance=name).network
        nets = {name: net}
        if name == "shape_factor":
            nets["shape_factor_circle_law"] = circle_law(net)
        for key, n in nets.items():
            t = time.process_time()
            ip = invasion_percolation(n, Fluids(sigma=SIGMA), "x")
            out[key] = {"sw": ip.sw.tolist(), "pc": ip.capillary_pressure.tolist(),
                        "breakthrough_Pa": float(ip.capillary_pressure[ip.breakthrough_step]),
                        "cpu_s": time.process_time() - t}
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--image", required=True, help="npz with 'image' (1 = pore) and 'voxel_size_m'")
    ap.add_argument("--porespy-json", help="saved PoreSpy curve to reuse (else computed: peers env)")
    ap.add_argument("--steps", default="60",
                    help="number of geometric Pc steps for PoreSpy, or 'exact': every distinct value of its Pc field")
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    z = np.load(a.image)
    pore, vs = z["image"].astype(bool), float(z["voxel_size_m"])
    print(f"load {open('/proc/loadavg').read().split()[:3]}  image {pore.shape} phi={pore.mean():.4f}", flush=True)
    if a.porespy_json and Path(a.porespy_json).is_file():
        ref = json.loads(Path(a.porespy_json).read_text())
    else:
        ref = porespy_curve(pore, vs, None if a.steps == "exact" else int(a.steps))
        print(f"PoreSpy drainage {ref['cpu_s']:.0f} s CPU", flush=True)
        if a.porespy_json:
            Path(a.porespy_json).write_text(json.dumps(ref))
    ref_sw = 1.0 - np.asarray(ref["snw"])
    first = np.flatnonzero(np.asarray(ref["snw"]) > 0)
    ps_entry = float(np.asarray(ref["pc"])[first[0]]) if first.size else float("nan")
    curves = porefsi_curves(pore, vs)
    out: dict = {"porespy": {"entry_Pa": ps_entry}, "porefsi": {}}
    for t in TARGETS:
        lo, hi = bracket(ref_sw, ref["pc"], t)
        out["porespy"][str(t)] = {"Pa": hi, "bracket_Pa": [lo, hi]}
        print(f"PoreSpy Sw={t}: {hi:7.0f} Pa (step bracket {lo:.0f}-{hi:.0f})")
    print(f"PoreSpy first invasion {ps_entry:.0f} Pa")
    for key, c in curves.items():
        row = {"breakthrough_Pa": c["breakthrough_Pa"]}
        cells = []
        for t in TARGETS:
            mine, theirs = pc_at(c["sw"], c["pc"], t), out["porespy"][str(t)]["Pa"]
            row[str(t)] = {"Pa": mine, "ratio": mine / theirs}
            cells.append(f"Sw={t}: {mine:7.0f} Pa ratio {mine / theirs:.3f}")
        out["porefsi"][key] = row
        print(f"  {key:24s} breakthrough {c['breakthrough_Pa']:7.0f} Pa  " + "  ".join(cells), flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
