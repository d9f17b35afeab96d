"""Benchmark: maximal-ball extraction with porefsi vs PoreSpy ``snow2`` vs ``pnextract``.

Every tool runs on the same image in its own subprocess, one after the other, so each peak
memory (``ru_maxrss``) is its own. Reported per tool:

* CPU seconds of the extraction call (``time.process_time`` inside the child: all threads; for
  pnextract, the child's user + sys time from ``getrusage(RUSAGE_CHILDREN)``), and µs per voxel;
* peak resident memory, and bytes per voxel *above the child's baseline* (interpreter, imports
  and the loaded image measured just before the call; pnextract is a C++ binary that reads the
  image itself, so its whole peak counts);
* pore and throat counts, mean coordination.

Usage::

    python benchmarks/bench_extract.py            # built-in 120^3 Berea + the 400^3 Berea when present
    python benchmarks/bench_extract.py --quick    # built-in 120^3 only
    python benchmarks/bench_extract.py --tools porefsi pnextract
    python benchmarks/bench_extract.py --image /data/berea_400.npz   # another large image

Images: the built-in 120^3 Berea crop always; then ``--image`` (npz with keys ``image``, 1 = pore,
and ``voxel_size_m``), by default ``<repo>/../shared/data/berea_icl_400.npz``; a missing file is
skipped with a message. ``--quick`` runs the built-in crop only.

Peers: PoreSpy runs under ``--peers-python``, by default this interpreter when ``porespy`` imports
in it (``pip install "porefsi[peers]"``, as ``tox -e bench`` does), else the older separate venv
``/tmp/peers-venv/bin/python`` if it exists; otherwise snow2 is skipped with the reason printed.
``pnextract`` (PyPI 0.0.3, an sdist that compiles its C++ on install in about 2 minutes on one
core; needs a C++ compiler and make; Linux only) is the ``pnextract`` executable next to that
interpreter, next to this one, or on ``PATH``; get it with ``pip install pnextract`` (it is in the
``peers`` extra). A tool that is missing is reported and skipped; the others still run.
The machine the numbers in ``docs/extraction.md`` came from was shared and noisy.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
BUILTIN = REPO / "porefsi" / "data" / "berea_icl_120_paper.npz"
#: The 400^3 Berea the performance target is stated on, next to the checkout (``../shared/data``).
LARGE = REPO.parent / "shared" / "data" / "berea_icl_400.npz"
#: Where an earlier setup kept the peers (porespy, pnextract) in their own virtualenv.
OLD_PEERS_PYTHON = Path("/tmp/peers-venv/bin/python")


def default_peers_python() -> tuple[str | None, str]:
    """The interpreter to run PoreSpy with, and why it was chosen (or why there is none)."""
    if importlib.util.find_spec("porespy") is not None:
        return sys.executable, "porespy imports in the running interpreter"
    if OLD_PEERS_PYTHON.exists():
        return str(OLD_PEERS_PYTHON), f"porespy is not installed in {sys.executable}; using the old peers venv"
    return None, (
        f"porespy is not installed in {sys.executable} and {OLD_PEERS_PYTHON} does not exist; "
        "pip install 'porefsi[peers]' (or porespy) or pass --peers-python PYTHON"
    )

PORESFI_CHILD = r"""
import json, resource, sys, time
import numpy as np
from porefsi.image.synthetic import sphere_lattice
from porefsi.image.voxel_image import VoxelImage
from porefsi.network.extract import extract_network
extract_network(sphere_lattice(n=(2, 1, 1)).image)  # load (or compile) the numba kernels
d = np.load(sys.argv[1])
img = VoxelImage(d["image"], float(d["voxel_size_m"]))
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = time.process_time()
ext = extract_network(img)
cpu = time.process_time() - t
net = ext.network
print(json.dumps(dict(cpu=cpu, base_kb=base, peak_kb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
    n_pores=net.n_pores, n_throats=net.n_throats, z=float(net.coordination.mean()),
    stages={k: round(v, 3) for k, v in ext.info.seconds.items()})))
"""

SNOW2_CHILD = r"""
import json, resource, sys, time, warnings
import numpy as np
warnings.filterwarnings("ignore")
import porespy as ps
d = np.load(sys.argv[1])
im = d["image"].astype(bool)
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = time.process_time()
# boundary_width=0: no added boundary pores, so the count is the image's own pores
snow = ps.networks.snow2(im, voxel_size=float(d["voxel_size_m"]), boundary_width=0)
cpu = time.process_time() - t
net = snow.network
n_p = len(net["pore.coords"])
conns = np.asarray(net["throat.conns"])
print(json.dumps(dict(cpu=cpu, base_kb=base, peak_kb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
    n_pores=n_p, n_throats=len(conns), z=2 * len(conns) / n_p)))
"""


def _run_python(python, code, image, env=None):
    t = time.perf_counter()
    out = subprocess.run([python, "-c", code, str(image)], capture_output=True, text=True, env=env)
    if out.returncode != 0:
        raise RuntimeError(out.stderr.strip().splitlines()[-1] if out.stderr.strip() else "failed")
    res = json.loads(out.stdout.strip().splitlines()[-1])
    res["wall"] = time.perf_counter() - t
    return res


def run_porefsi(image, args):
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    return _run_python(sys.executable, PORESFI_CHILD, image, env)


def run_snow2(image, args):
    if args.peers_python is None:
        raise RuntimeError(args.peers_reason)
    if not Path(args.peers_python).exists():
        raise RuntimeError(f"--peers-python {args.peers_python} not found")
    return _run_python(args.peers_python, SNOW2_CHILD, image)


def _find_pnextract(args) -> str:
    pythons = [p for p in (args.peers_python, sys.executable) if p is not None]
    for exe in dict.fromkeys(Path(p).parent / "pnextract" for p in pythons):
        if exe.exists():
            return str(exe)
    exe = shutil.which("pnextract")
    if exe is None:
        where = " or ".join(str(Path(p).parent) for p in dict.fromkeys(pythons))
        raise RuntimeError(
            f"pnextract not found in {where} nor on PATH; pip install pnextract (compiles C++, about 2 min) "
            "or pip install 'porefsi[peers]'"
        )
    return exe


def run_pnextract(image, args):
    exe = _find_pnextract(args)
    d = np.load(image)
    im = d["image"]
    vs_um = float(d["voxel_size_m"]) * 1e6
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # pnextract reads raw x-fastest with pore = 0 (Imperial College convention)
        (1 - im).astype(np.uint8).transpose(2, 1, 0).tofile(tmp / "img.raw")
        nx, ny, nz = im.shape
        (tmp / "img.mhd").write_text(
            "ObjectType = Image\nNDims = 3\nElementType = MET_UCHAR\n"
            f"DimSize = {nx} {ny} {nz}\nElementSpacing = {vs_um} {vs_um} {vs_um}\nOffset = 0 0 0\n"
            "ElementDataFile = img.raw\n"
        )
        # a fresh Python parent, so RUSAGE_CHILDREN holds pnextract alone
        wrapper = (
            "import json, resource, subprocess, sys, time; t = time.perf_counter(); "
            "r = subprocess.run(sys.argv[1:], capture_output=True, text=True); "
            "u = resource.getrusage(resource.RUSAGE_CHILDREN); "
            "print(json.dumps(dict(rc=r.returncode, out=r.stdout[-4000:], err=r.stderr[-500:], "
            "cpu=u.ru_utime + u.ru_stime, peak_kb=u.ru_maxrss, wall=time.perf_counter() - t)))"
        )
        out = subprocess.run(
            [sys.executable, "-c", wrapper, str(exe), "img.mhd"], cwd=tmp, capture_output=True, text=True
        )
        res = json.loads(out.stdout.strip().splitlines()[-1])
        if res["rc"] != 0:
            raise RuntimeError(res["out"][-300:] + res["err"])
        n_p = int((tmp / "img_node1.dat").read_text().split()[0])
        # link1.dat: count, then one row per throat "id pore1 pore2 ..."; pores -1 and 0 are
        # pnextract's inlet/outlet reservoirs: count the throats between two real pores only
        rows = (tmp / "img_link1.dat").read_text().splitlines()[1:]
        ends = np.array([[int(v) for v in r.split()[1:3]] for r in rows if r.strip()]).reshape(-1, 2)
        n_t = int(np.sum(np.all(ends > 0, axis=1)))
        n_t_boundary = len(ends) - n_t
    return dict(
        cpu=res["cpu"],
        base_kb=0,
        peak_kb=res["peak_kb"],
        n_pores=n_p,
        n_throats=n_t,
        n_boundary_throats=n_t_boundary,
        z=2 * n_t / n_p,
        wall=res["wall"],
    )


TOOLS = {"pnextract": run_pnextract, "porefsi": run_porefsi, "snow2": run_snow2}


def figure(path, image=BUILTIN, k=60):
    """Slice ``z = k`` of the extraction: pore regions, master balls cut by the slice, throats."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sys.path.insert(0, str(REPO))
    from porefsi.image.voxel_image import VoxelImage
    from porefsi.network.extract import extract_network

    d = np.load(image)
    img = VoxelImage(d["image"], float(d["voxel_size_m"]))
    ext = extract_network(img)
    net, vs = ext.network, img.voxel_size
    lab = ext.labels[:, :, k].astype(float)
    palette = [c for i, c in enumerate(plt.get_cmap("tab20").colors) if i not in (14, 15)]  # no greys
    colours = np.random.default_rng(0).integers(0, len(palette), net.n_pores)
    show = np.where(lab >= 0, colours[np.maximum(lab, 0).astype(int)], np.nan)
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    ax.imshow(np.ones_like(lab).T, cmap="Greys", vmin=0, vmax=3, origin="lower")  # solid: light grey
    ax.imshow(
        show.T,
        cmap=matplotlib.colors.ListedColormap(palette),
        vmin=-0.5,
        vmax=len(palette) - 0.5,
        origin="lower",
        interpolation="nearest",
    )
    c = net.pore_coords / vs - 0.5
    for p in np.flatnonzero(np.abs(c[:, 2] - k) < net.pore_radius / vs):
        rr = np.sqrt((net.pore_radius[p] / vs) ** 2 - (c[p, 2] - k) ** 2)  # ball cut by the slice
        ax.add_patch(plt.Circle(c[p, :2], rr, fill=False, lw=0.8, color="k"))
        ax.plot(*c[p, :2], "k.", ms=2)
    for t in range(net.n_throats):
        a, b = net.throat_conns[t]
        if abs(c[a, 2] - k) < 3 and abs(c[b, 2] - k) < 3:
            ax.plot(c[[a, b], 0], c[[a, b], 1], "w-", lw=0.6)
    ax.set(
        title=f"Berea 120^3, slice z={k}: {net.n_pores} pores, {net.n_throats} throats",
        xlabel="x (voxel)",
        ylabel="y (voxel)",
    )
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    print(f"wrote {path}")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="built-in 120^3 image only")
    p.add_argument("--tools", nargs="+", default=list(TOOLS), choices=list(TOOLS))
    p.add_argument(
        "--image", nargs="+", type=Path, default=[LARGE], metavar="NPZ",
        help="large image(s) to run after the built-in 120^3 crop (npz, keys image and voxel_size_m); "
        f"default {LARGE}; a missing file is skipped with a message",
    )
    p.add_argument(
        "--peers-python", default=None, metavar="PYTHON",
        help="interpreter with porespy for snow2 (and where pnextract is looked for first); default: this "
        f"interpreter if porespy imports here, else {OLD_PEERS_PYTHON} if it exists, else snow2 is skipped",
    )
    p.add_argument("--json", type=Path, help="also write the results here")
    p.add_argument("--figure", type=Path, help="only draw a labelled slice of the built-in sample here")
    args = p.parse_args(argv)
    if args.figure:
        figure(args.figure)
        return 0
    if args.peers_python is None:
        args.peers_python, args.peers_reason = default_peers_python()
    else:
        args.peers_reason = "given with --peers-python"
    if "snow2" in args.tools:
        print(f"peers python: {args.peers_python or 'none'} ({args.peers_reason})")
    images = [BUILTIN]
    for image in [] if args.quick else args.image:
        if image.exists():
            images.append(image)
        else:
            print(f"skipped {image}: file not found; pass --image PATH to an npz image (keys image, voxel_size_m)")
    results = []
    for image in images:
        n_vox = int(np.prod(np.load(image)["image"].shape))
        print(f"\n== {image.name}: {n_vox:,} voxels ==")
        row = {}
        for tool in [t for t in TOOLS if t in args.tools]:
            try:
                r = TOOLS[tool](image, args)
            except Exception as err:  # a missing peer must not stop the others
                print(f"{tool:10s} skipped: {err}")
                continue
            r["us_per_voxel"] = 1e6 * r["cpu"] / n_vox
            r["peak_mb"] = r["peak_kb"] / 1024
            r["bytes_per_voxel"] = (r["peak_kb"] - r["base_kb"]) * 1024 / n_vox
            row[tool] = r
            print(
                f"{tool:10s} cpu {r['cpu']:8.2f} s ({r['us_per_voxel']:.3f} us/voxel)  wall {r['wall']:7.1f} s  "
                f"peak {r['peak_mb']:7.0f} MB ({r['bytes_per_voxel']:.1f} B/voxel above baseline)  "
                f"pores {r['n_pores']:7d}  throats {r['n_throats']:7d}  Z {r['z']:.2f}"
            )
            if "n_boundary_throats" in r:
                print(f"{'':10s} (+ {r['n_boundary_throats']} throats to its inlet/outlet reservoirs, not counted)")
            if "stages" in r:
                print(f"{'':10s} stages (wall s): {r['stages']}")
        if "porefsi" in row:
            me = row["porefsi"]
            for peer in ("snow2", "pnextract"):
                if peer in row:
                    o = row[peer]
                    print(
                        f"porefsi vs {peer:9s}: {o['cpu'] / me['cpu']:6.1f}x less CPU, "
                        f"{o['bytes_per_voxel'] / me['bytes_per_voxel']:5.1f}x less memory per voxel, "
                        f"pore count ratio {me['n_pores'] / o['n_pores']:.2f}"
                    )
        results.append({"image": str(image), "n_voxels": n_vox, "tools": row})
    if args.json:
        args.json.write_text(json.dumps(results, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
