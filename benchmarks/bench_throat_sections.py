"""Throat sections solved exactly: how far porefsi's (r, G) duct law is from each throat's own section.

Diagnosis for the r 9 sphere pack (network / converged voxel Stokes = 1.49, docs/verification.md).
For every throat of the default (``shape_factor``) network:

1. the throat point (the interface face of largest inscribed radius, recomputed with the
   extraction's own kernel from ``Extraction.labels``) and the pore-to-pore direction d;
2. the planar section of the pore space through the throat point **normal to d** (not the nearest
   axis plane): sampled on a square grid of spacing ``H`` voxels by nearest-voxel look-up, kept
   where the voxel is pore and carries one of the throat's two pore labels, and reduced to the
   4-connected component holding the throat point;
3. its exact duct conductance g·mu = ∫ w dA of ∇²w = -1, w = 0 on the wall: 5-point finite
   differences, the wall at the pixel faces (ghost reflection, w_ghost = -w), scipy sparse direct
   solve; the section's area A_exact and inscribed radius r_exact (distance from the deepest pixel
   centre to the nearest outside pixel centre, minus H/2);
4. the network's law for the same throat, :func:`porefsi.network.geometry.duct_conductance_factor`
   of its ``throat_radius`` and ``throat_shape_factor``, and its area r²/(4G).

Throats whose point lies nearer than their radius to a box face are reported apart. Before
2026-12-02 (commit ad39595) the extraction's distance map had no solid outside the box, so those
radii ignored the box face, which the voxel reference makes a no-slip wall (its four side faces)
and this section makes a wall too; ``--face-test`` re-solves the network k per axis with those
throats (side faces only) narrowed to their section's inscribed radius (a sensitivity). The
extraction now walls the box faces itself (throat points on the walled map, recovered here the
same way), so the face-cut class is empty but for throats whose section plane is oblique, and
the face test should move k by ~0.

The 2-D solver is checked first against closed forms (circle pi R^4/8, square series, equilateral
triangle sqrt(3) a^4/320) at several resolutions (``--check``). Voxel units throughout.

Run: ``python benchmarks/bench_throat_sections.py --data /work/shared/data [--face-test] [--json out.json]``
(about 30 s CPU for the four images).
Uses private helpers of the extraction (``_distance_map``, ``_mb_sections._walled_points`` with
``_mb_conduits.BOX_WALLS``) to recover the throat points, which
:class:`~porefsi.network.extract.Extraction` does not expose.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse.linalg import spsolve

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _data import data_file  # noqa: E402
from bench_network_accuracy import BEREA_VOXEL, blobs, sphere_pack  # noqa: E402

from porefsi.image.voxel_image import VoxelImage  # noqa: E402
from porefsi.network._mb_conduits import BOX_WALLS  # noqa: E402
from porefsi.network._mb_sections import _walled_points  # noqa: E402
from porefsi.network.extract import _distance_map, extract_network  # noqa: E402
from porefsi.network.geometry import TRIANGLE_MAX_G, duct_conductance_factor  # noqa: E402

H = 0.25  # section grid spacing, voxels
FACE_TEST = False  # --face-test
LABELS = True  # keep only the throat's two pore labels (False: every pore voxel, --all-labels)
G_BINS = (0.0, 0.025, 0.035, TRIANGLE_MAX_G, 0.0625, 0.08)


def poisson_conductance(mask: np.ndarray, h: float = 1.0, wall: str = "face") -> float:
    """∫ w dA of ∇²w = -1 on the True pixels of ``mask`` (spacing h), w = 0 at the wall.

    ``wall='face'``: the wall on the pixel faces (ghost value -w, a missing neighbour adds 2 to
    the diagonal); ``wall='centre'``: w = 0 at the centres of the outside pixels (adds 1).
    """
    m = np.pad(np.asarray(mask, bool), 1)
    idx = -np.ones(m.shape, np.int64)
    n = int(m.sum())
    idx[m] = np.arange(n)
    diag = np.zeros(n)
    rows, cols = [], []
    miss = 2.0 if wall == "face" else 1.0
    for sh in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        nb = np.roll(idx, sh, axis=(0, 1))
        here = idx[m]
        other = nb[m]
        inside = other >= 0
        rows.append(here[inside])
        cols.append(other[inside])
        diag += np.where(inside, 1.0, miss)
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    ii = np.arange(n)
    a = sparse.coo_matrix((np.r_[diag, -np.ones(r.size)], (np.r_[ii, r], np.r_[ii, c])), shape=(n, n))
    w = spsolve(a.tocsc(), np.full(n, h * h))
    return float(w.sum() * h * h)


def _square_exact(a: float) -> float:
    """Square duct of side a, series solution (independent of porefsi's rectangle formula)."""
    s = sum(np.tanh(k * np.pi / 2) / k**5 for k in range(1, 200, 2))
    return a**4 / 12.0 * (1.0 - 192.0 / np.pi**5 * s)


def _circle(R: float, h: float) -> np.ndarray:
    n = int(np.ceil(R / h)) + 1
    y, x = np.mgrid[-n : n + 1, -n : n + 1] * h
    return x * x + y * y <= R * R


def _square(a: float, h: float) -> np.ndarray:
    n = int(round(a / h))
    return np.ones((n, n), bool)


def _triangle(a: float, h: float) -> np.ndarray:
    hgt = a * np.sqrt(3) / 2
    n = int(np.ceil(a / h)) + 2
    y, x = (np.mgrid[0:n, -n:n] + 0.5) * h
    return (y <= hgt) & (np.abs(x) <= (hgt - y) / np.sqrt(3))


def solver_check() -> list[dict]:
    """Relative error of :func:`poisson_conductance` on closed-form ducts pixelised at h = 1, 1/2, 1/4.

    Sizes in voxels (circle radius, square side, triangle side); h in voxels.
    """
    cases = (
        ("circle", _circle, lambda R: np.pi * R**4 / 8, (1.5, 2.0, 2.5, 3.0, 5.0)),
        ("square", _square, _square_exact, (3.0, 4.0, 6.0, 10.0)),
        ("triangle", _triangle, lambda a: np.sqrt(3) * a**4 / 320, (5.0, 6.0, 8.0, 12.0)),
    )
    out = []
    for shape, make, exact, sizes in cases:
        for s in sizes:
            err = {h: poisson_conductance(make(s, h), h) / exact(s) - 1 for h in (1.0, 0.5, 0.25)}
            out.append({"shape": shape, "size": s, "err": err})
    return out


def section(pore, labels, p, d, pair, half: float) -> np.ndarray:
    """Pixels (bool, spacing H) of the section normal to d through p, labels in pair, connected to p."""
    d = d / np.linalg.norm(d)
    e1 = np.cross(d, [1.0, 0, 0] if abs(d[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    n = int(np.ceil(half / H))
    u = np.arange(-n, n + 1) * H
    uu, vv = np.meshgrid(u, u, indexing="ij")
    pts = p[None, None, :] + uu[..., None] * e1 + vv[..., None] * e2
    ijk = np.rint(pts).astype(np.int64)
    ok = np.all((ijk >= 0) & (ijk < np.array(pore.shape)), axis=-1)
    ijk = np.where(ok[..., None], ijk, 0)
    lab = labels[ijk[..., 0], ijk[..., 1], ijk[..., 2]]
    m = ok & ((lab == pair[0]) | (lab == pair[1])) if LABELS else ok & pore[ijk[..., 0], ijk[..., 1], ijk[..., 2]]
    comp, _ = ndimage.label(m)
    c = comp[n, n]
    if c == 0:  # the face centre rounds onto the other voxel; take the nearest kept pixel
        near = comp[n - 2 : n + 3, n - 2 : n + 3]
        c = near.max()
        if c == 0:
            return np.zeros((1, 1), bool)
    return comp == c


def inscribed(mask: np.ndarray) -> float:
    """Inscribed radius (voxels) of a pixel section: deepest pixel centre to the wall (faces)."""
    return float(ndimage.distance_transform_edt(np.pad(mask, 1)).max() * H - H / 2)


def analyse(name: str, pore: np.ndarray, vs: float) -> dict:
    """Per-throat law / exact statistics for one image."""
    t0 = time.process_time()
    ext = extract_network(VoxelImage(pore.astype(np.uint8), voxel_size=vs))
    net = ext.network
    dt2 = _distance_map(np.ascontiguousarray(pore))
    conns = net.throat_conns
    _, point = _walled_points(np.ascontiguousarray(ext.labels), dt2, conns, np.int64(net.n_pores),
                              np.array(BOX_WALLS, np.int64))
    t_ext = time.process_time() - t0
    centre = net.pore_coords / vs - 0.5
    r_t = net.throat_radius / vs
    G = net.throat_shape_factor
    law = duct_conductance_factor(r_t, G)
    A_law = r_t**2 / (4 * G)
    # distance (voxels) from the throat point to the nearest image face (faces at -0.5 and n - 0.5):
    # a throat nearer than its radius is cut by the box, which the distance map does not see
    face_gap = np.min(np.minimum(point + 0.5, np.array(pore.shape) - 0.5 - point), axis=1)
    rows = []
    for t, (i, j) in enumerate(net.throat_conns):
        d = centre[j] - centre[i]
        half = min(3.0 * max(net.pore_radius[i], net.pore_radius[j]) / vs + 2.0, 30.0)
        m = section(pore, ext.labels, point[t], d, (i, j), half)
        if m.sum() < 2:
            continue
        g = poisson_conductance(m, H)
        # sensitivity: the narrowest of the parallel planes 1 voxel either side
        dh = d / np.linalg.norm(d)
        g_side = [poisson_conductance(ms, H) for ms in (section(pore, ext.labels, point[t] + s * dh, d, (i, j), half)
                                                       for s in (-1.0, 1.0)) if ms.sum() >= 2]
        cos_ax = float(np.max(np.abs(d)) / np.linalg.norm(d))
        edge = bool(m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any())
        rows.append((t, g, m.sum() * H * H, inscribed(m), cos_ax, edge, min([g, *g_side])))
    if FACE_TEST:
        r_ex = np.full(net.n_throats, np.inf)
        r_ex[[r[0] for r in rows]] = [r[3] for r in rows]
        face_test(name, net, point, r_ex, pore.shape)
    t_all = time.process_time() - t0
    t_idx = np.array([r[0] for r in rows])
    ex = np.array([[r[1], r[2], r[3], r[4], r[5], r[6]] for r in rows])
    res = {
        "name": name, "n_throats": int(net.n_throats), "n_solved": len(rows),
        "cpu_s_extract": t_ext, "cpu_s_total": t_all,
        "ratio_g": law[t_idx] / ex[:, 0], "ratio_A": A_law[t_idx] / ex[:, 1], "ratio_r": r_t[t_idx] / ex[:, 2],
        "G": G[t_idx], "r": r_t[t_idx], "g_exact": ex[:, 0], "g_law": law[t_idx], "clipped": ex[:, 4] > 0,
        "ratio_g_min3": law[t_idx] / ex[:, 5], "cos_axis": ex[:, 3],
        "face": face_gap[t_idx] < r_t[t_idx],
    }
    return res


def face_test(name: str, net, point: np.ndarray, r_exact: np.ndarray, shape) -> None:
    """Network k per axis, as extracted and with the side-face throats narrowed (a sensitivity).

    For flow along axis a, a throat whose point lies nearer than its radius to a box face parallel
    to a (where the voxel reference has no-slip walls) gets radius min(r, r_exact) and shape
    factor G (r'/r)² (same area); every other field unchanged.
    """
    from porefsi.flow.permeability import absolute_permeability

    vs = net.voxel_size
    r = net.throat_radius / vs
    lo, hi = point + 0.5, np.array(shape) - 0.5 - point
    out = []
    for a, ax in enumerate("xyz"):
        side = [b for b in range(3) if b != a]
        gap = np.min(np.minimum(lo[:, side], hi[:, side]), axis=1)
        cut = (gap < r) & np.isfinite(r_exact)
        r_new = np.where(cut, np.minimum(r, np.maximum(r_exact, 0.5)), r)
        g_new = net.throat_shape_factor * (r_new / r) ** 2
        net2 = dataclasses.replace(net, throat_radius=r_new * vs, throat_shape_factor=g_new)
        k0 = absolute_permeability(net, ax).k_mD
        k1 = absolute_permeability(net2, ax).k_mD
        out.append(f"{ax} {k0:.0f} -> {k1:.0f} mD ({k1 / k0:.2f}, {int(cut.sum())} throats)")
    print(f"  face test {name}: " + "; ".join(out))


def quart(x) -> str:
    """median [q25, q75] of x."""
    q = np.nanpercentile(x, [50, 25, 75])
    return f"{q[0]:.2f} [{q[1]:.2f}, {q[2]:.2f}]"


def weighted_median(x, w) -> float:
    """Median of x weighted by w."""
    o = np.argsort(x)
    c = np.cumsum(w[o])
    return float(x[o][np.searchsorted(c, 0.5 * c[-1])])


def report(res: dict) -> None:
    """Print the per-image table rows."""
    keep = ~res["clipped"]
    print(f"\n## {res['name']}: {res['n_throats']} throats, {res['n_solved']} solved, "
          f"{int((~keep).sum())} clipped by the window; CPU {res['cpu_s_total']:.0f} s "
          f"(extraction {res['cpu_s_extract']:.0f} s)")
    rg, ra, rr = res["ratio_g"][keep], res["ratio_A"][keep], res["ratio_r"][keep]
    w = res["g_law"][keep]
    print(f"  law/exact g: {quart(rg)}   conductance-weighted median {weighted_median(rg, w):.2f}"
          f"   sum(law)/sum(exact) {w.sum() / res['g_exact'][keep].sum():.2f}")
    print(f"  A_law/A_exact: {quart(ra)}   r/r_exact: {quart(rr)}")
    print(f"  law / narrowest of 3 planes (-1, 0, +1 voxel along d): {quart(res['ratio_g_min3'][keep])}")
    face = res["face"][keep]
    for lab, s in (("interior", ~face), ("cut by an image face", face)):
        print(f"  {lab}: n {int(s.sum())}, share of law g {w[s].sum() / w.sum():.2f}, law/exact g {quart(rg[s])}"
              f", sum(law)/sum(exact) {w[s].sum() / res['g_exact'][keep][s].sum():.2f}, r/r_exact {quart(rr[s])}")
    G = res["G"][keep]
    for lo, hi in zip(G_BINS[:-1], G_BINS[1:], strict=True):
        s = (G >= lo) & (G < hi)
        if s.sum():
            print(f"  G in [{lo:.4f}, {hi:.4f}): n {int(s.sum()):4d}  share of law g {w[s].sum() / w.sum():.2f}"
                  f"  g {quart(rg[s])}  A {quart(ra[s])}  r {quart(rr[s])}")
    r = res["r"][keep]
    for lo, hi in ((0.0, 1.5), (1.5, 2.5), (2.5, 4.0), (4.0, 99.0)):
        s = (r >= lo) & (r < hi)
        if s.sum():
            print(f"  r in [{lo:.1f}, {hi:.1f}) vox: n {int(s.sum()):4d}  share of law g {w[s].sum() / w.sum():.2f}"
                  f"  g {quart(rg[s])}  A {quart(ra[s])}  r {quart(rr[s])}")


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(data_file("")))
    ap.add_argument("--json", default=None)
    ap.add_argument("--only", default=None, help="comma-separated image names")
    ap.add_argument("--all-labels", action="store_true", help="section of every pore voxel, not the two labels")
    ap.add_argument("--face-test", action="store_true", help="network k with the side-face throats narrowed")
    args = ap.parse_args(argv)
    global LABELS, FACE_TEST
    LABELS = not args.all_labels
    FACE_TEST = args.face_test
    chk = solver_check()
    print("2-D solver vs closed forms, relative error at h = 1, 1/2, 1/4 voxel:")
    for c in chk:
        e = c["err"]
        print(f"  {c['shape']:8s} size {c['size']:4.1f} vox: {e[1.0]:+.3f} {e[0.5]:+.3f} {e[0.25]:+.3f}")
    bad = [c for c in chk if c["size"] >= 3 and abs(c["err"][0.25]) > 0.08]
    if bad:
        raise RuntimeError(f"2-D solver off its closed forms at h = 1/4 (> 8 %): {bad}")
    imgs = {
        "spheres_p35_r9": lambda: sphere_pack(n=120, porosity=0.35, r_mean=9.0, seed=1),
        "spheres_p30_r6": lambda: sphere_pack(porosity=0.30, r_mean=6.0, seed=3),
        "blobs_p30": lambda: blobs(porosity=0.30),
        "berea_120crop": lambda: np.load(Path(args.data) / "berea_icl_400.npz")["image"][:120, :120, :120].astype(bool),
    }
    only = args.only.split(",") if args.only else list(imgs)
    out = {"check": [{**c, "err": {str(k): v for k, v in c["err"].items()}} for c in chk]}
    for name in only:
        res = analyse(name, imgs[name](), BEREA_VOXEL)
        report(res)
        out[name] = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in res.items()}
    if args.json:
        Path(args.json).write_text(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
