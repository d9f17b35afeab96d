"""Diagnosis: which network quantities change when the same rock is seen at a finer voxel.

Each rock is upsampled by nearest neighbour (every voxel -> f^3 voxels at 1/f the voxel size, the
same staircase geometry, as the converged voxel reference refines it). The upsampled network's
pores are matched to the native ones (the native pore whose region holds the fine pore centre) and
its throats to the native throat joining the two matched pores; for every matched throat the
script prints the median ratio fine / native of each quantity in metres (inscribed radius, section
area, shape factor, conduit length, throat-duct share, entry radius) and, per image, the pore count,
the labelled porosity, the median pore radius and the permeability (mean of x, y, z).

``--bins``: per matched conduit, each ingredient of its conductance in metres (throat radius,
section area, shape factor, the duct law per length, throat-duct length L_t, pore-duct lengths,
conduit length, throat and pore-duct resistances, conduit conductance), ratio fine / native as a
geometric mean weighted by the native network's conduit dissipation (summed over x, y, z), binned
by the native throat radius in native voxels (``docs/extraction.md``, "Constriction length with
the section's own law").

Usage::

    python benchmarks/bench_resolution_geometry.py [--rocks sample berea blobs spheres] [--factors 1 2 3]
        [--crop 100] [--floor auto|voxels|length] [--bins]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_extract_resolution import rocks, upsample  # noqa: E402

from porefsi.errors import NetworkError  # noqa: E402
from porefsi.flow.permeability import absolute_permeability, flow_field  # noqa: E402
from porefsi.image.voxel_image import VoxelImage  # noqa: E402
from porefsi.network.extract import extract_network  # noqa: E402
from porefsi.network.geometry import duct_conductance_factor, duct_lengths, resistance_factors  # noqa: E402

DATA = HERE.parent.parent / "shared" / "data"


def k_mean(net):
    ks = []
    for ax in "xyz":
        try:
            ks.append(absolute_permeability(net, ax).k_mD)
        except NetworkError:
            ks.append(np.nan)
    return float(np.nanmean(ks)), ks


def throat_table(ext):
    net, s = ext.network, ext.sections
    L = net.throat_length + net.throat_pore_length.sum(axis=1)
    return {
        "r_t": net.throat_radius,
        "A": s["area"],
        "A_faces": s["face_area"],
        "G": net.throat_shape_factor,
        "P_wall": s["wall_perimeter"],
        "L": L,
        "f_throat": net.throat_duct_fraction[:, 1],
        "r_over_sqrtA": net.throat_radius / np.sqrt(s["area"]),
    }


def conduit_table(ext):
    """Each conduit's ingredients in metres (keys as printed by :func:`print_bins`)."""
    net = ext.network
    L, h = duct_lengths(net), resistance_factors(net)
    return {
        "r_t": net.throat_radius, "A": ext.sections["area"], "G": net.throat_shape_factor,
        "g_law": duct_conductance_factor(net.throat_radius, net.throat_shape_factor),
        "L_t": L[:, 1], "L_p": L[:, 0] + L[:, 2], "L": L.sum(axis=1), "h_t": h[:, 1], "h_p": h[:, 0] + h[:, 2],
        "g": 1.0 / h.sum(axis=1),
    }


def dissipation(net):
    """Each conduit's share of the network's dissipation, summed over the x, y, z solves."""
    w = np.zeros(net.n_throats)
    for ax in "xyz":
        r = absolute_permeability(net, ax)
        dp = r.pressure[net.throat_conns[:, 0]] - r.pressure[net.throat_conns[:, 1]]
        d = np.nan_to_num(np.abs(flow_field(net, r.pressure) * dp))
        w += d / d.sum()
    return w


def print_bins(ext1, extf, pairs):
    """Dissipation-weighted geometric mean of fine / native per ingredient, by native throat radius."""
    t1, tf = conduit_table(ext1), conduit_table(extf)
    w = dissipation(ext1.network)[pairs[:, 0]]
    rnat = t1["r_t"][pairs[:, 0]] / ext1.network.voxel_size
    print("   r_t bin (native vox)  conduits share  " + " ".join(f"{k:>6s}" for k in t1))
    for lo, hi in ((0, 1), (1, 1.5), (1.5, 2), (2, 3), (3, 99), (0, 99)):
        s = (rnat >= lo) & (rnat < hi)
        if not s.any():
            continue
        gm = [np.exp(np.average(np.log(tf[k][pairs[s, 1]] / t1[k][pairs[s, 0]]), weights=w[s])) for k in t1]
        print(f"   [{lo:g}, {hi:g}){'':12s} {int(s.sum()):5d} {w[s].sum() / w.sum():5.2f}  "
              + " ".join(f"{v:6.3f}" for v in gm))


def match(ext1, extf, f):
    """(native throat index, fine throat index) pairs of matched throats."""
    lab1 = ext1.labels
    netf = extf.network
    cf = (netf.pore_coords - netf.origin) / netf.voxel_size - 0.5  # fine voxel coords
    c1 = np.floor(cf / f + 1e-9).astype(int)
    c1 = np.clip(c1, 0, np.array(lab1.shape) - 1)
    pmap = lab1[c1[:, 0], c1[:, 1], c1[:, 2]]
    key1 = {tuple(sorted(c)): t for t, c in enumerate(ext1.network.throat_conns.tolist())}
    pairs = []
    seen = set()
    for t, (a, b) in enumerate(netf.throat_conns.tolist()):
        pa, pb = pmap[a], pmap[b]
        if pa < 0 or pb < 0 or pa == pb:
            continue
        k = key1.get(tuple(sorted((int(pa), int(pb)))))
        if k is None or k in seen:
            continue
        seen.add(k)
        pairs.append((k, t))
    return np.array(pairs, dtype=int).reshape(-1, 2)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rocks", nargs="+", default=["sample", "berea"])
    ap.add_argument("--factors", nargs="+", type=int, default=[1, 2, 3])
    ap.add_argument("--crop", type=int, default=100)
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument(
        "--floor",
        choices=["auto", "voxels", "length"],
        default="auto",
        help="noise floor: auto (the default, from the image), voxels (min_radius = 2) or "
        "length (min_radius = 1.5 f + 0.5 voxels, held at the native length by knowing f)",
    )
    ap.add_argument("--floor-length", action="store_true", help="same as --floor length")
    ap.add_argument("--bins", action="store_true", help="per-ingredient ratios by throat radius (module docstring)")
    args = ap.parse_args(argv)
    print(f"load {open('/proc/loadavg').read().split()[:3]}")
    for name, pore, vs in rocks(args.rocks, args.data, args.crop):
        if "native" in name:
            continue
        base = None
        for f in args.factors:
            img = VoxelImage(upsample(pore, f), vs / f)
            t = time.process_time()
            rule = "length" if args.floor_length else args.floor
            mr = {"auto": "auto", "voxels": 2.0, "length": 1.5 * f + 0.5}[rule]
            ext = extract_network(img, min_radius=mr)
            cpu = time.process_time() - t
            net = ext.network
            k, ks = k_mean(net)
            row = dict(
                pores=net.n_pores,
                throats=net.n_throats,
                phi=ext.porosity,
                k=k,
                Rp_med=np.median(net.pore_radius) / vs,
                rt_med=np.median(net.throat_radius) / vs,
            )
            line = (
                f"{name[:24]:24s} {f}x floor {ext.info.min_radius:5.2f} cpu {cpu:6.1f}s "
                f"pores {row['pores']:5d} throats {row['throats']:5d} "
                f"phi_lab {row['phi']:.4f} Rp_med {row['Rp_med']:.3f} rt_med {row['rt_med']:.3f} (native vox) "
                f"k {k:7.0f} ({', '.join(f'{x:.0f}' for x in ks)})"
            )
            if base is None:
                base = (ext, row)
                print(line)
                continue
            ext1, row1 = base
            line += f" | /1x pores {row['pores'] / row1['pores']:.2f} k {k / row1['k']:.2f}"
            print(line)
            pairs = match(ext1, ext, f)
            t1, tf = throat_table(ext1), throat_table(ext)
            parts = [f"   matched {len(pairs)}/{ext1.network.n_throats}"]
            for q in t1:
                ratio = tf[q][pairs[:, 1]] / t1[q][pairs[:, 0]]
                parts.append(f"{q} {np.median(ratio):.3f}")
            d1 = (t1["r_t"][pairs[:, 0]] - tf["r_t"][pairs[:, 1]]) / vs
            parts.append(f"r_t(1x)-r_t(fx) median {np.median(d1):+.3f} native vox")
            print(" ".join(parts))
            if args.bins:
                print_bins(ext1, ext, pairs)


if __name__ == "__main__":
    main()
