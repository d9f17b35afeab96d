"""Are the 400³ Berea's 200³ crops lower than the whole? Same method on both, controlled changes.

The default network's permeability is 0.97x the published DNS on the whole 400³ Berea but
0.64-0.70x porefsi's voxel Stokes solve on its four 200³ crops. Two explanations: the crops
differ from the whole (crop faces, finite size, trimming), or the two *references* differ. This
script separates them by never comparing across references:

* network, same model, whole vs crops (full resolution): crops / whole per axis;
* voxel Stokes, same solver, whole vs crops at 2x coarsening (the full-resolution whole needs
  ~6 GiB and hours here; ``--whole`` solves the coarsened whole, else the value measured by
  ``bench_stokes.py --cases coarse``, docs/stokes.md, is used), and each crop's coarse / full
  ratio (full-resolution crop values from ``network_accuracy_reference.json``), which estimates the
  full-resolution voxel k of the whole as coarse whole / mean ratio;
* the network / voxel ratio at 100³ (the eight 100³ sub-crops of the centre crop, ``--sub``).

Usage::

    python benchmarks/bench_network_crops.py --data DIR [--whole] [--sub] [--json out.json]
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

import numpy as np

from porefsi.flow.permeability import absolute_permeability
from porefsi.image import VoxelImage, downsample
from porefsi.network.extract import extract_network
from porefsi.stokes import voxel_permeability

CROPS = {"a": (0, 0, 0), "b": (200, 200, 200), "c": (100, 100, 100), "d": (0, 200, 100)}
#: Voxel Stokes of the whole 400³ Berea coarsened 2x (bench_stokes.py --cases coarse; docs/stokes.md).
WHOLE_COARSE2 = {"x": 2226.0, "y": 2406.0, "z": 2483.0}
REFERENCE = Path(__file__).with_name("network_accuracy_reference.json")


def network_k(img: np.ndarray, vs: float) -> dict:
    """Default-model network k (mD) along x, y, z."""
    net = extract_network(VoxelImage(img.astype(np.uint8), voxel_size=vs)).network
    return {ax: absolute_permeability(net, ax).k_mD for ax in "xyz"}


def voxel_k(img: np.ndarray, vs: float, coarsen: int = 1) -> dict:
    """Voxel Stokes k (mD) along x, y, z, after block coarsening by ``coarsen``.

    Ghost-reflection wall: the crops' refinement factors (docs/verification.md) were measured with it.
    """
    im = VoxelImage(img.astype(np.uint8), voxel_size=vs)
    if coarsen > 1:
        im = downsample(im, coarsen)
    return {ax: voxel_permeability(im, ax, wall="ghost").k_mD for ax in "xyz"}


def _fmt(d: dict) -> str:
    return " ".join(f"{ax}={d[ax]:7.0f}" for ax in "xyz") + f"  mean={np.mean(list(d.values())):7.0f}"


def _ratios(d: dict) -> str:
    return " ".join(f"{ax} {v:.3f}" for ax, v in d.items())


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--whole", action="store_true", help="solve the 2x-coarsened whole (3 x ~2 min CPU)")
    ap.add_argument("--sub", action="store_true", help="network / voxel on the eight 100³ sub-crops of crop c")
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    z = np.load(Path(a.data) / "berea_icl_400.npz")
    img, vs = z["image"].astype(bool), float(z["voxel_size_m"])
    refs = json.loads(REFERENCE.read_text())
    print(f"load {open('/proc/loadavg').read().split()[:3]}", flush=True)
    t = time.process_time()
    out: dict = {"whole": {"network": network_k(img, vs)}}
    out["whole"]["voxel_coarse2"] = voxel_k(img, vs, 2) if a.whole else WHOLE_COARSE2
    print(f"whole    network   {_fmt(out['whole']['network'])}")
    print(f"whole    voxel x2  {_fmt(out['whole']['voxel_coarse2'])}", flush=True)
    ratios = []
    for name, o in CROPS.items():
        crop = img[tuple(slice(s, s + 200) for s in o)]
        row = {"network": network_k(crop, vs), "voxel": refs[f"berea_200_{name}"]}
        row["voxel_coarse2"] = voxel_k(crop, vs, 2)
        row["coarse_over_full"] = {ax: row["voxel_coarse2"][ax] / row["voxel"][ax] for ax in "xyz"}
        ratios.append(np.mean(list(row["coarse_over_full"].values())))
        out[name] = row
        print(f"crop {name}   network   {_fmt(row['network'])}")
        print(f"crop {name}   voxel     {_fmt(row['voxel'])}")
        print(f"crop {name}   voxel x2  {_fmt(row['voxel_coarse2'])}  coarse/full {ratios[-1]:.3f}", flush=True)
    net_mean = {ax: np.mean([out[c]["network"][ax] for c in CROPS]) for ax in "xyz"}
    vox2_mean = {ax: np.mean([out[c]["voxel_coarse2"][ax] for c in CROPS]) for ax in "xyz"}
    est = {ax: out["whole"]["voxel_coarse2"][ax] / np.mean(ratios) for ax in "xyz"}
    whole = out["whole"]
    s = out["summary"] = {
        "network_crops_over_whole": {ax: net_mean[ax] / whole["network"][ax] for ax in "xyz"},
        "voxel2_crops_over_whole": {ax: vox2_mean[ax] / whole["voxel_coarse2"][ax] for ax in "xyz"},
        "coarse_over_full_mean": float(np.mean(ratios)),
        "whole_voxel_full_estimate": est,
        "whole_network_over_estimate": {ax: whole["network"][ax] / est[ax] for ax in "xyz"},
    }
    print("crops / whole, network (full res):   " + _ratios(s["network_crops_over_whole"]))
    print("crops / whole, voxel (coarsened 2x): " + _ratios(s["voxel2_crops_over_whole"]))
    each = ", ".join(f"{r:.3f}" for r in ratios)
    print(f"voxel coarse / full on the crops: {s['coarse_over_full_mean']:.3f} (each {each})")
    print("whole, voxel full-res estimate: " + _fmt(est) + "  (published DNS 1360, 1304, 1193, mean 1286)")
    print("whole, network / voxel estimate: " + _ratios(s["whole_network_over_estimate"]))
    if a.sub:
        sub = []
        for c in itertools.product((0, 1), repeat=3):
            o = [100 + 100 * k for k in c]
            piece = img[tuple(slice(s, s + 100) for s in o)]
            kn, kv = network_k(piece, vs), voxel_k(piece, vs)
            sub.append({"offset": o, "network": kn, "voxel": kv})
            print(f"100³ at {o}: network/voxel " + " ".join(f"{ax} {kn[ax] / kv[ax]:.3f}" for ax in "xyz"), flush=True)
        out["sub100"] = sub
    print(f"CPU {time.process_time() - t:.0f} s")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
