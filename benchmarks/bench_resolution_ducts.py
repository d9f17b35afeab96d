"""Voxelised ducts of known section at several resolutions: the extracted throat against exact values.

Each duct (circle, square, equilateral triangle, slit; at sub-voxel offsets) joins two wide
chambers; the throat of the extracted network is compared with

* the section's exact inscribed radius, area and shape factor (of the smooth shape), and
* the exact Stokes flow through the duct's own pixel section (the voxel staircase, the geometry
  the converged voxel reference solves; ``tests/reference/stokes_ref.prism_flow_rate``): the
  ratio of the network's duct conductance ``k G A^2`` to it.

Usage::

    python benchmarks/bench_resolution_ducts.py [--offsets 3]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from porefsi.image.voxel_image import VoxelImage  # noqa: E402
from porefsi.network.extract import extract_network  # noqa: E402
from porefsi.network.geometry import duct_conductance_factor, shape_class  # noqa: E402
from tests.reference.stokes_ref import prism_flow_rate  # noqa: E402


def section(shape, r, off, n):
    """Pixel section (bool, n x n) of a shape of inscribed radius r centred at the middle + off."""
    y, z = np.indices((n, n)).astype(float)
    cy, cz = (n - 1) / 2 + off[0], (n - 1) / 2 + off[1]
    if shape == "circle":
        return (y - cy) ** 2 + (z - cz) ** 2 <= r * r, r, math.pi * r * r, 1 / (4 * math.pi)
    if shape == "square":
        return (abs(y - cy) <= r) & (abs(z - cz) <= r), r, 4 * r * r, 1 / 16
    if shape == "triangle":  # equilateral, inscribed radius r, side 2 sqrt(3) r
        yy, zz = y - cy, z - cz
        sec = (yy >= -r) & (yy <= 2 * r - math.sqrt(3) * abs(zz)) & (yy <= 2 * r)
        return sec, r, 3 * math.sqrt(3) * r * r, math.sqrt(3) / 36
    w = 5 * r  # slit: half-aperture r, width 10 r
    return (abs(y - cy) <= r) & (abs(z - cz) <= w), r, 4 * r * w, 4 * r * w / (4 * r + 4 * w) ** 2


def duct_image(sec, length=10, chamber=None):
    n = sec.shape[0]
    chamber = chamber or n
    pore = np.zeros((2 * chamber + length, n + 4, n + 4), np.uint8)
    pore[:chamber, 2:-2, 2:-2] = 1
    pore[chamber + length:, 2:-2, 2:-2] = 1
    pore[chamber:chamber + length, 2:-2, 2:-2] = sec
    return pore


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--offsets", type=int, default=3)
    a = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    print(f"{'shape':9s} {'r':>4s} | {'r_t/r':>6s} {'A/A_true':>8s} {'G/G_true':>8s} class | "
          "g/q_staircase  (mean over offsets [min-max])")
    for shape in ("circle", "square", "triangle", "slit"):
        for r in (1.5, 2.0, 3.0, 4.0, 6.0):
            rows = []
            for _ in range(a.offsets):
                off = rng.uniform(-0.5, 0.5, 2)
                n = int(2 * (5 * r if shape == "slit" else 2 * r)) + 6
                sec, r0, A0, G0 = section(shape, r, off, n)
                net = extract_network(VoxelImage(duct_image(sec), 1.0), min_radius=1.0).network
                t = int(np.argmin(net.throat_radius))
                rt, G = net.throat_radius[t], net.throat_shape_factor[t]
                q = prism_flow_rate(sec)
                A = rt * rt / (4 * G)
                rows.append((rt / r0, A / A0, G / G0, int(shape_class(G)), duct_conductance_factor(rt, G) / q))
            m = np.array(rows)
            cls = "".join("TSC"[int(c)] for c in m[:, 3])
            print(f"{shape:9s} {r:4.1f} | {m[:, 0].mean():6.3f} {m[:, 1].mean():8.3f} {m[:, 2].mean():8.3f} {cls:5s} | "
                  f"{m[:, 4].mean():5.2f} [{m[:, 4].min():.2f}-{m[:, 4].max():.2f}]")


if __name__ == "__main__":
    main()
