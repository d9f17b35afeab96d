"""Converged/native factor k_inf/k_1 of the voxel Stokes reference on crops of a benchmark image.

The network accuracy benchmark compares the network with the *converged* voxel reference, estimated
as the stored native voxel k times k_inf/k_1 measured on crops of the same image (docs/verification.md,
"Against the rock: the converged voxel reference"). This measures that factor on ``--n``^3 crops
of one of ``bench_network_accuracy.py``'s synthetic images: each crop solved along x at refinement
f = 1, 2, 3 (``voxel_permeability(refine=f)``, ``wall="ghost"`` as the stored native references) and
Richardson-extrapolated (observed order; the p = 2 variant printed too).

Usage::

    python benchmarks/bench_network_refine_factor.py --image spheres_p35 --crops "0,0,0;60,60,60;40,20,70"

Cost: ~1, 13 and 60-85 CPU s per 40^3 crop at f = 1, 2, 3 (measured at load 6-7).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from bench_network_accuracy import BEREA_VOXEL, images

from porefsi.image.voxel_image import VoxelImage
from porefsi.stokes import voxel_permeability
from porefsi.stokes.refine import richardson


def main(argv=None) -> list[float]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--image", default="spheres_p35", help="a synthetic image name of bench_network_accuracy.py")
    ap.add_argument("--crops", default="0,0,0;60,60,60;40,20,70", help="crop corners, voxels")
    ap.add_argument("--n", type=int, default=40)
    a = ap.parse_args(argv)
    pore = next(p for name, p, _, _ in images(None) if name == a.image)
    factors = []
    for corner in a.crops.split(";"):
        o = [int(v) for v in corner.split(",")]
        crop = pore[o[0]:o[0] + a.n, o[1]:o[1] + a.n, o[2]:o[2] + a.n]
        ks = []
        for f in (1, 2, 3):
            t = time.process_time()
            r = voxel_permeability(VoxelImage(crop.astype(np.uint8), voxel_size=BEREA_VOXEL), "x", wall="ghost",
                                   refine=f)
            ks.append(r.k_mD)
            print(f"crop {o} f={f}: k {r.k_mD:.1f} mD, {time.process_time() - t:.0f} CPU s", flush=True)
        e = richardson([1, 2, 3], ks)
        factors.append(e.value / ks[0])
        p2 = 1 - (1 - ks[1] / ks[0]) * (1 + 1 / 3)
        print(f"crop {o}: k2/k1 {ks[1] / ks[0]:.3f}, order {e.order:.2f}, k_inf/k_1 {factors[-1]:.3f} "
              f"(p = 2: {p2:.3f})")
    print(f"{a.image}: mean k_inf/k_1 {np.mean(factors):.3f} over {len(factors)} crops")
    return factors


if __name__ == "__main__":
    main()
