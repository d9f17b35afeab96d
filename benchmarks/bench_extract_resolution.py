"""Benchmark: extraction cost and network under upsampling (the same rock at 1x, 2x, 3x).

Each rock is upsampled by repeating every voxel ``f^3`` times at ``1/f`` the voxel size: the
geometry is the same, only the pore radii in voxels grow. For every rock and factor, porefsi,
PoreSpy ``snow2`` and ``pnextract`` run on the same image, each in its own subprocess (the
runners of ``bench_extract.py``), and the script prints per tool:

* CPU seconds of the extraction call and µs per voxel, and the ratio to the same tool's µs per
  voxel on the native (1x) image: the issue's target is porefsi <= 1.5 at 2x and 3x;
* pore and throat counts and the pore count's ratio to the native one (target 0.85-1.15);
* for porefsi, with the default noise floor (``min_radius="auto"``, a fraction of the image's
  hydraulic radius: ``porefsi.network.floor``; its value in voxels is printed), the network
  permeability (mean of x, y, z, shape-factor model) and its ratio to the native one (target
  0.9-1.1); then pores and k with the old fixed floor ``min_radius = 2`` voxels ("2 vox"), and
  with the floor held at the native image's in length by knowing ``f`` ("held",
  ``min_radius = 1.5 f + 0.5`` voxels: a ball whose surface distance ``sqrt(dt2) - 0.5``
  reaches 1.5 native voxels, as ``min_radius = 2`` asks at 1x). CPU, memory and stage times are
  the default extraction's.

Each rock is also upsampled *smoothly* (``upsample_smooth``: the trilinear signed distance,
thresholded; porefsi only unless ``--smooth`` names peers): nearest-neighbour upsampling turns
the staircase of the voxels into real geometry, which has a lower permeability (voxel Stokes
on a 60^3 corner of the sample: -13 to -22 % at 2x, ``docs/stokes.md``), so only the smooth
variant is the same rock seen by a finer scan.

Rocks: the built-in 120^3 Berea sample; crops of the 400^3 Berea (``--data``, default
``../shared/data`` next to the checkout; skipped when absent), so the upsampled crop (133^3 x 3
= 399^3) has the 400^3 image's size and its per-voxel cost can be compared at equal size too;
a Gaussian-blob medium and a sphere pack (the seeded generators of
``bench_network_accuracy.py``); ``--rocks blob-scales``: 240^3 blob media whose pores are 1x, 2x,
3x wider in voxels (the generator's sigma), porefsi only: the radius effect at one image size.

``--decompose`` (porefsi only, in this process): separates what carries the change of k between
the native and the upsampled network, by running the extraction's stages of one grid on the
other grid's partition (stage functions of ``porefsi.network.extract`` swapped for the run, a
diagnosis, not an API): k of the native partition (regions and centres) measured on the
upsampled image ("measure"), of the native pore centres flooded and measured on the upsampled
image ("flood"), of the upsampled image's own network ("own"), and of the upsampled partition
coarsened to the native grid (the most frequent label of each ``f^3`` block) measured on the native
image ("coarse"); each / the native network's k.

Usage::

    python benchmarks/bench_extract_resolution.py                       # every rock, 1x 2x 3x, all tools
    python benchmarks/bench_extract_resolution.py --rocks sample --tools porefsi
    python benchmarks/bench_extract_resolution.py --factors 1 3 --json out.json
    python benchmarks/bench_extract_resolution.py --rocks sample berea --decompose

Peers as in ``bench_extract.py`` (``--peers-python``; a missing peer is skipped with the reason).
Timings on a shared machine are noisy: the load average is printed before and after.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_extract as be  # noqa: E402
from bench_network_accuracy import blobs, sphere_pack  # noqa: E402

REPO = HERE.parent
DATA = REPO.parent / "shared" / "data"

PORESFI_CHILD = r"""
import json, resource, sys, time
import numpy as np
from porefsi.errors import NetworkError
from porefsi.image.synthetic import sphere_lattice
from porefsi.image.voxel_image import VoxelImage
from porefsi.network.extract import extract_network
from porefsi.flow.permeability import absolute_permeability
extract_network(sphere_lattice(n=(2, 1, 1)).image)  # load (or compile) the numba kernels
d = np.load(sys.argv[1])
f = int(d["factor"])
img = VoxelImage(d["image"], float(d["voxel_size_m"]))

def k_mean(net):
    ks = []
    for ax in "xyz":
        try:
            ks.append(absolute_permeability(net, ax).k_mD)
        except NetworkError:
            ks.append(float("nan"))
    return float(np.nanmean(ks)) if np.isfinite(ks).any() else float("nan"), ks

base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = time.process_time()
ext = extract_network(img)  # the default noise floor, min_radius="auto"
cpu = time.process_time() - t
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
net = ext.network
k, ks = k_mean(net)
floor = 1.5 * f + 0.5
ext2 = extract_network(img, min_radius=floor)
k2, _ = k_mean(ext2.network)
ext3 = extract_network(img, min_radius=2.0)
k3, _ = k_mean(ext3.network)
print(json.dumps(dict(cpu=cpu, base_kb=base, peak_kb=peak,
    n_pores=net.n_pores, n_throats=net.n_throats, z=float(net.coordination.mean()), k_mD=k, k_axes=ks,
    n_balls=ext.info.n_maximal_balls, n_scanned=ext.info.n_scanned_balls, auto_floor=ext.info.min_radius,
    floor=floor, n_pores_floor=ext2.network.n_pores, k_floor=k2, n_pores_2vox=ext3.network.n_pores, k_2vox=k3,
    stages={s: round(v, 3) for s, v in ext.info.seconds.items()})))
"""


def run_porefsi(path, args):
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    return be._run_python(sys.executable, PORESFI_CHILD, path, env)


TOOLS = {"porefsi": run_porefsi, "pnextract": be.run_pnextract, "snow2": be.run_snow2}


def upsample(pore: np.ndarray, f: int) -> np.ndarray:
    """Every voxel repeated ``f`` times along each axis (the same staircase at ``1/f`` the voxel)."""
    for ax in range(3):
        pore = np.repeat(pore, f, axis=ax)
    return np.ascontiguousarray(pore)


def upsample_smooth(pore: np.ndarray, f: int) -> np.ndarray:
    """The image's smooth surface sampled ``f`` times finer (what a finer scan of the rock would see).

    The signed distance (distance to the solid minus distance to the pore, at voxel centres) is
    interpolated trilinearly at the fine voxel centres and thresholded at 0: the surface is the
    same continuous level set at every ``f`` (porosity kept to ~0.5 %), without the staircase
    that :func:`upsample` makes real.
    """
    from scipy import ndimage

    p = pore.astype(bool)
    sd = (ndimage.distance_transform_edt(p) - ndimage.distance_transform_edt(~p)).astype(np.float32)
    if f == 1:
        return pore.astype(np.uint8)
    axes = [(np.arange(n * f) + 0.5) / f - 0.5 for n in pore.shape]
    out = np.empty(tuple(n * f for n in pore.shape), np.uint8)
    jj, kk = np.meshgrid(axes[1], axes[2], indexing="ij")
    for i, x in enumerate(axes[0]):
        pts = [np.full(jj.size, x), jj.ravel(), kk.ravel()]
        out[i] = (ndimage.map_coordinates(sd, pts, order=1, mode="nearest") > 0).reshape(jj.shape)
    return out


def rocks(names, data: Path, crop: int):
    """(name, pore uint8 array, voxel size m) of each rock asked for that exists."""
    if "sample" in names:
        d = np.load(be.BUILTIN)
        yield "Berea 120^3 sample", d["image"].astype(np.uint8), float(d["voxel_size_m"])
    if "berea" in names:
        p = data / "berea_icl_400.npz"
        if not p.exists():
            print(f"skipped Berea crops: {p} not found (--data DIR)")
        else:
            d = np.load(p)
            a, vs = d["image"], float(d["voxel_size_m"])
            for o in (0,):
                yield f"Berea {crop}^3 at {o}", np.ascontiguousarray(a[o : o + crop, o : o + crop, o : o + crop]), vs
            # the same sizes at the native resolution: per-voxel cost at equal image size (cache
            # effects make a 2 M-voxel image cheaper per voxel than a 60 M-voxel one)
            for m in (3,):
                n = min(crop * m, a.shape[0])
                yield f"Berea {n}^3 at 0 (native, {m}x size)", np.ascontiguousarray(a[:n, :n, :n]), vs
    if "blobs" in names:
        yield "blobs 80^3, porosity 0.30", blobs(n=80, porosity=0.3).astype(np.uint8), 5.345e-6
    if "spheres" in names:
        yield "sphere pack 80^3, porosity 0.35", sphere_pack(n=80, porosity=0.35).astype(np.uint8), 5.345e-6
    if "blob-scales" in names:
        # one image size, pore radii x1, x2, x3 in voxels: the radius effect without the size effect
        for sigma in (4.0, 8.0, 12.0):
            yield (
                f"blobs 240^3 sigma {sigma:g} (native, radii x{sigma / 4:g})",
                blobs(n=240, porosity=0.3, sigma=sigma).astype(np.uint8),
                5.345e-6,
            )


@contextlib.contextmanager
def _stages(centres=None, labels=None):
    """Extraction stages swapped: given pore centres (flat indices) and, optionally, given regions.

    ``centres`` replaces the maximal balls and their hierarchy; with ``labels`` (int32, -1 off the
    pores) the flood too, and no pores merge (the partition is taken as it is).
    """
    import porefsi.network.extract as ex

    saved = ex._pore_centres, ex._flood_regions, ex.merge_shallow
    lab0 = labels

    def pore_centres(dt2, *_):
        lab = np.full(dt2.shape, -1, np.int32) if lab0 is None else lab0.copy()
        return centres, lab, {"candidates": 0, "balls": 0, "scanned": 0}

    ex._pore_centres = pore_centres
    if labels is not None:
        ex._flood_regions = lambda *_: 0
    ex.merge_shallow = lambda centre, r, *_: (np.arange(r.size), np.arange(r.size))
    try:
        yield
    finally:
        ex._pore_centres, ex._flood_regions, ex.merge_shallow = saved


def _fine_centres(dt2_native_centres: np.ndarray, fine_pore: np.ndarray, f: int) -> np.ndarray:
    """Flat indices on the fine grid of the widest fine voxel in each native centre's ``f^3`` block."""
    from scipy import ndimage

    dt = ndimage.distance_transform_edt(fine_pore)
    out = np.empty(len(dt2_native_centres), np.int64)
    for i, c in enumerate(dt2_native_centres):
        blk = dt[c[0] * f : (c[0] + 1) * f, c[1] * f : (c[1] + 1) * f, c[2] * f : (c[2] + 1) * f]
        o = np.unravel_index(int(np.argmax(blk)), blk.shape)
        out[i] = np.ravel_multi_index(tuple(c * f + np.array(o)), fine_pore.shape)
    return out


def decompose(pore: np.ndarray, vs: float, f: int) -> dict:
    """k (mean of x, y, z, mD) of the native network and of the cross-grid networks (module docstring)."""
    from porefsi.image.voxel_image import VoxelImage
    from porefsi.network.extract import extract_network

    def k(net):
        from porefsi.flow.permeability import absolute_permeability

        return float(np.mean([absolute_permeability(net, a).k_mD for a in "xyz"]))

    e1 = extract_network(VoxelImage(pore, vs))
    n1 = e1.network
    fine = upsample(pore, f)
    ef = extract_network(VoxelImage(fine, vs / f))
    c1 = np.round((n1.pore_coords - n1.origin) / vs - 0.5).astype(int)
    cf = _fine_centres(c1, fine.astype(bool), f)
    out = {"native": k(n1), "own": k(ef.network), "pores": (n1.n_pores, ef.network.n_pores)}
    with _stages(cf, upsample(e1.labels.astype(np.int32), f)):
        out["measure"] = k(extract_network(VoxelImage(fine, vs / f)).network)
    with _stages(cf):
        out["flood"] = k(extract_network(VoxelImage(fine, vs / f)).network)
    n = pore.shape
    blocks = ef.labels.astype(np.int64).reshape(n[0], f, n[1], f, n[2], f).transpose(0, 2, 4, 1, 3, 5)
    blocks = blocks.reshape(-1, f**3)
    lab = blocks[:, 0].astype(np.int32)  # uniform blocks; the mixed ones take their most frequent label
    for i in np.flatnonzero((blocks != blocks[:, :1]).any(axis=1)):
        b = blocks[i][blocks[i] >= 0]
        lab[i] = np.bincount(b).argmax() if b.size else -1
    lab = np.where(pore.reshape(-1) > 0, lab, -1).reshape(n)
    nf = ef.network
    cc = np.floor((nf.pore_coords - nf.origin) / nf.voxel_size - 0.5 + 1e-9).astype(int) // f
    with _stages(np.ravel_multi_index(tuple(cc.T), n), lab):
        out["coarse"] = k(extract_network(VoxelImage(pore, vs)).network)
    return out


def _decompose_rows(args) -> list:
    rows = []
    for rock, pore, vs in rocks(args.rocks, args.data, args.crop):
        if "native" in rock:
            continue
        for f in sorted(set(args.factors) - {1}):
            r = decompose(pore, vs, f)
            k1 = r["native"]
            print(
                f"{rock:32s} {f}x native {k1:7.0f} mD | /native: measure {r['measure'] / k1:.3f} flood "
                f"{r['flood'] / k1:.3f} own {r['own'] / k1:.3f} coarse {r['coarse'] / k1:.3f} | pores {r['pores']}",
                flush=True,
            )
            rows.append(dict(rock=rock, factor=f, **r))
    return rows


def _row(rock, f, tool, r, native):
    n = r.get("n_vox")
    us = r["cpu"] / n * 1e6
    nat = native.get(tool)

    def ratio(key):
        return r[key] / nat[key] if nat and nat.get(key) else float("nan")

    line = (
        f"{rock:32s} {f}x {tool:9s} {r['cpu']:8.2f} {us:7.3f} {us / (nat['us'] if nat else us):6.2f} "
        f"{r['n_pores']:7d} {ratio('n_pores'):6.2f} {r['n_throats']:7d}"
    )
    if tool == "porefsi":
        line += (
            f" {r['k_mD']:8.0f} {ratio('k_mD'):6.2f} (auto floor {r['auto_floor']:.2f})"
            f" | 2 vox: {r['n_pores_2vox']:6d} {ratio('n_pores_2vox'):5.2f}"
            f" {r['k_2vox']:7.0f} {ratio('k_2vox'):5.2f}"
            f" | held {r['floor']:.1f}: {r['n_pores_floor']:6d} "
            f"{ratio('n_pores_floor'):5.2f} {r['k_floor']:7.0f} {ratio('k_floor'):5.2f}"
            f" | balls {r['n_balls']} scanned {r['n_scanned']}"
        )
    return line


def _rock_rows(rock, pore, vs, up, tools, args, tmp: Path, factors) -> list:
    native: dict = {}
    out = []
    for f in sorted(factors):
        path = tmp / "img.npz"
        img = up(pore, f)
        np.savez(path, image=img, voxel_size_m=vs / f, factor=f)
        n_vox = int(img.size)
        del img
        for tool in tools:
            if tool != "porefsi" and f not in args.peer_factors:
                continue
            try:
                r = TOOLS[tool](path, args)
            except Exception as exc:  # a missing or failing peer is reported, the rest run
                print(f"{rock:32s} {f}x {tool:9s} skipped: {exc}")
                continue
            r["n_vox"] = n_vox
            r["us"] = r["cpu"] / n_vox * 1e6
            native.setdefault(tool, r)
            print(_row(rock, f, tool, r, native), flush=True)
            out.append(dict(rock=rock, factor=f, tool=tool, **r))
    return out


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--rocks",
        nargs="+",
        default=["sample", "berea", "blobs", "spheres"],
        choices=["sample", "berea", "blobs", "spheres", "blob-scales"],
    )
    p.add_argument("--factors", nargs="+", type=int, default=[1, 2, 3])
    p.add_argument("--tools", nargs="+", default=list(TOOLS), choices=list(TOOLS))
    p.add_argument(
        "--peer-factors",
        nargs="+",
        type=int,
        default=[1, 3],
        help="factors the peers run at (porefsi runs every --factors); default 1 3",
    )
    p.add_argument("--data", type=Path, default=DATA, help="folder holding berea_icl_400.npz")
    p.add_argument("--crop", type=int, default=133, help="Berea crop side, voxels (default 133: 133 x 3 = 399)")
    p.add_argument(
        "--smooth",
        nargs="*",
        default=["porefsi"],
        choices=list(TOOLS),
        help="tools also run on the smooth upsampling (upsample_smooth); default porefsi",
    )
    p.add_argument("--peers-python", default=None)
    p.add_argument("--json", default=None, help="also write every result to this file")
    p.add_argument("--decompose", action="store_true", help="cross-grid decomposition of k only (module docstring)")
    args = p.parse_args(argv)
    if args.decompose:
        print(f"load average before: {open('/proc/loadavg').read().split()[:3]}")
        rows = _decompose_rows(args)
        if args.json:
            Path(args.json).write_text(json.dumps(rows, indent=1))
        return {"results": rows}
    if args.peers_python is None:
        args.peers_python, args.peers_reason = be.default_peers_python()
    else:
        args.peers_reason = ""
    print(f"load average before: {open('/proc/loadavg').read().split()[:3]}")
    print(
        f"{'rock':32s} f  {'tool':9s} {'CPU s':>8s} {'us/vox':>7s} {'/1x':>6s} {'pores':>7s} {'/1x':>6s} "
        f"{'throats':>7s} {'k mD':>8s} {'/1x':>6s}"
    )
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for rock0, pore, vs in rocks(args.rocks, args.data, args.crop):
            if "native" in rock0:  # factor 1 only, porefsi (its per-voxel cost at the upsampled size)
                if "porefsi" in args.tools:
                    results += _rock_rows(rock0, pore, vs, upsample, ["porefsi"], args, Path(tmp), [1])
                continue
            for kind, up, tools in (("", upsample, args.tools), (" smooth", upsample_smooth, args.smooth)):
                if tools:
                    results += _rock_rows(rock0 + kind, pore, vs, up, tools, args, Path(tmp), args.factors)
    print(f"load average after: {open('/proc/loadavg').read().split()[:3]}")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return {"results": results}


if __name__ == "__main__":
    main()
