"""Case ``speed_accuracy``, permeability part: what each second buys against the rock (issue 12).

The coupled-run study (``run.py``) measures porefsi against a finer porefsi run. This part puts the
rock on the chart: the single-phase permeability of Berea images by

- the pore network (``porefsi.network.extract_network`` once per image, then
  ``porefsi.flow.absolute_permeability`` along x, y and z) with each conduit model,
  ``"shape_factor"`` (the default) and ``"paper"``;
- the voxel Stokes solver (``porefsi.stokes.voxel_permeability``) on the image coarsened 1, 2, 3,
  4 times (``porefsi.image.downsample``), with each tangential wall closure asked for (``--walls``:
  ``channel``, the default, and/or ``ghost``, the earlier reflection scheme);

each against its CPU time (``time.process_time`` of this process, BLAS and numba on one thread,
numba compiled beforehand; network: one extraction plus three solves; voxel: coarsening plus
three solves). k is the mean over the three axes.

The truth each point is measured against, named in ``results.json`` (``truth_kind``):

- ``"published DNS"``: the whole 400^3 Berea (``--image``), against the published voxel-scale
  simulation, mean 1286 mD (kx, ky, kz = 1360, 1304, 1193; which array axis is the published x is
  uncertain, so only the mean is compared). This is accuracy.
- ``"finest voxel solve"``: the built-in 120^3 sample and the 200^3 centre crop of the 400^3
  Berea have no published value: their points are measured against porefsi's own voxel solve
  at full resolution. This checks convergence (and the network against the voxel solver), not
  accuracy against the rock.

The full-resolution 400^3 solve takes ~6 GiB and about an hour of CPU per axis: it is read from
``reference/berea400_voxel.json`` (written from ``benchmarks/bench_stokes.py --cases full``, with
its commit and date) unless ``--full-resolution`` runs it here.

The 400^3 Berea (the source of ``crop200`` and ``berea400``) is the npz given by ``--berea PATH``
(``--image`` is the same option); a ``--berea`` file that does not exist is an error before anything
runs. Without ``--berea`` the script looks for ``shared/data/berea_icl_400.npz`` one and two folders
above the repository and says which file it uses; when there is none, it prints that
``crop200`` and ``berea400`` are SKIPPED, records them under ``"skipped"`` in ``results.json``,
and their earlier points (each study with its own commit and date) stay in the chart and table
unchanged.

Outputs: ``figures/permeability_speed_accuracy.png`` and the ``"permeability"`` entry of
``results.json`` (the coupled study's entries are kept).

Usage: ``python cases/speed_accuracy/permeability.py [--smoke] [--out DIR] [--berea BEREA400.npz]
[--images sample crop200 berea400] [--walls channel ghost] [--networks-only] [--full-resolution]``.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):  # numba: see cases/_common.py
    os.environ.setdefault(_v, "1")  # before numpy/numba load: single-thread CPU time is comparable

import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from porefsi import InputError, PorefsiError  # noqa: E402
from porefsi.flow import absolute_permeability  # noqa: E402
from porefsi.image import VoxelImage, downsample, load_sample  # noqa: E402
from porefsi.network import extract_network  # noqa: E402
from porefsi.stokes import voxel_permeability  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # cases/: the shared helpers
from _common import git_head, loadavg, output_dir, parse_args, pyplot, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
FULL_FILE = HERE / "reference" / "berea400_voxel.json"
REPO = HERE.parents[1]
#: Where the 400^3 Berea is looked for when ``--berea`` is not given (next to the repository, or one up).
BEREA400 = [REPO.parent / "shared" / "data" / "berea_icl_400.npz",
            REPO.parent.parent / "shared" / "data" / "berea_icl_400.npz"]
#: The images made from the 400^3 Berea (skipped without it).
FROM_BEREA = ("crop200", "berea400")
#: Published voxel-scale simulation of the 400^3 Berea, mD (axis mapping uncertain: compare means).
DNS_MD = {"x": 1360.0, "y": 1304.0, "z": 1193.0}
DNS_MEAN_MD = float(np.mean(list(DNS_MD.values())))
MODELS = ("shape_factor", "paper")
#: Tangential wall closures of the voxel solver (porefsi.stokes.StokesOptions.wall); the first is the truth
#: of the "finest voxel solve" images.
WALLS = ("channel", "ghost")
AXES3 = ("x", "y", "z")


# ---------------------------------------------------------------------------------------------
# the study design
# ---------------------------------------------------------------------------------------------
def images(smoke: bool, which, berea400: Path | None):
    """``(name, VoxelImage, truth_kind, coarsenings)`` of the images studied.

    Smoke: a 32^3 corner of the built-in sample at coarsening 1 and 2 (seconds).
    """
    if smoke:
        s = load_sample()
        yield "sample32", VoxelImage(s.phases[:32, :32, :32].copy(), s.voxel_size), "finest voxel solve", (1, 2)
        return
    if "sample" in which:
        yield "sample120", load_sample(), "finest voxel solve", (1, 2, 3, 4)
    if berea400 is None:  # locate_berea said so and recorded the skip
        return
    if set(FROM_BEREA) & set(which):
        with np.load(berea400) as d:
            big = VoxelImage(d["image"].astype(bool), float(d["voxel_size_m"]))
        if "crop200" in which:
            yield "crop200", VoxelImage(big.phases[100:300, 100:300, 100:300].copy(), big.voxel_size), \
                "finest voxel solve", (1, 2, 3, 4)
        if "berea400" in which:
            yield "berea400", big, "published DNS", (1, 2, 3, 4)


def locate_berea(given: Path | None, which, smoke: bool = False) -> tuple[Path | None, list[str]]:
    """The 400^3 Berea npz to use, and the images skipped for want of it.

    Parameters
    ----------
    given : Path or None
        ``--berea``: must exist (``InputError`` otherwise, before any output is touched).
    which : iterable of str
        The images asked for (``--images``).
    smoke : bool
        Smoke runs use the built-in sample only: nothing is looked for or skipped.

    Returns
    -------
    path : Path or None
        The file (None: not needed, or not found).
    skipped : list of str
        The images of ``FROM_BEREA`` asked for but not run (no file found); a SKIPPED line says so.
    """
    wanted = [n for n in FROM_BEREA if n in which]
    if smoke or not wanted:
        return None, []
    if given is not None:
        if not given.is_file():
            raise InputError(f"--berea {given}: no such file; pass the 400^3 Berea npz "
                             "(berea_icl_400.npz, the Imperial College Berea) or leave out crop200 and berea400 "
                             "(--images)")
        return given, []
    found = next((p for p in BEREA400 if p.is_file()), None)
    if found is not None:
        print(f"400^3 Berea: using {found} (found next to the repository; --berea PATH chooses the file)", flush=True)
        return found, []
    print(f"SKIPPED {', '.join(wanted)}: the 400^3 Berea npz was not found (looked for "
          f"{' and '.join(str(p) for p in BEREA400)}); pass --berea PATH. Their earlier points in results.json "
          "are kept, each study with its own commit and date.", flush=True)
    return None, wanted


def voxel_point(image: VoxelImage, factor: int, wall: str = WALLS[0]) -> dict:
    """Voxel-solver permeability of ``image`` coarsened ``factor`` times, x, y, z, with its CPU time.

    ``wall`` is the tangential wall closure; it is the row's ``model``.
    """
    c0, t0 = time.process_time(), time.perf_counter()
    work = downsample(image, factor) if factor > 1 else image
    k, its, conv = {}, {}, True
    for ax in AXES3:
        r = voxel_permeability(work, ax, wall=wall)
        k[ax], its[ax], conv = r.k_mD, r.iterations, conv and r.converged
    return {"method": "voxel", "model": wall, "coarsen": factor, "voxel_size_m": work.voxel_size,
            "shape": list(work.shape), "k_mD": k, "iterations": its, "converged": conv,
            "cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - t0}


def network_points(image: VoxelImage) -> list[dict]:
    """Network permeability of ``image`` by each conduit model, x, y, z, with CPU time.

    Each model is its own extraction (``extract_network(image, conductance=model)``): the paper's
    model measures its throats with the open box, the default with the box faces as walls, so
    one model's network re-labelled with the other's conduits (``Network.with_conductance``)
    would be neither. The extraction is on the whole image: clusters that do not span an axis
    carry no flow in ``absolute_permeability`` (they are left out of its solve). Each model's CPU
    time is its extraction's plus its own three solves.
    """
    rows = []
    for model in MODELS:
        c0, t0 = time.process_time(), time.perf_counter()
        net = extract_network(image, conductance=model).network
        c_ext = time.process_time() - c0
        k = {ax: absolute_permeability(net, ax).k_mD for ax in AXES3}
        rows.append({"method": "network", "model": model, "coarsen": 1, "voxel_size_m": image.voxel_size,
                     "shape": list(image.shape), "k_mD": k, "n_pores": int(net.n_pores),
                     "cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - t0,
                     "cpu_extract_s": c_ext})
    return rows


def cached_full_resolution(path: Path = FULL_FILE) -> dict | None:
    """The full-resolution 400^3 voxel point from ``reference/berea400_voxel.json``, or None."""
    if not path.is_file():
        return None
    d = json.loads(path.read_text())
    if set(d.get("k_mD", {})) != set(AXES3):
        print(f"{path}: not all three axes solved ({sorted(d.get('k_mD', {}))}): full resolution left out",
              flush=True)
        return None
    return {"method": "voxel", "model": d.get("wall", "ghost"), "coarsen": 1, **{k: d[k] for k in (
        "voxel_size_m", "shape", "k_mD", "iterations", "converged", "cpu_s", "wall_s")},
        "cached": {k: d.get(k) for k in ("source", "commit", "date_utc", "load")}}


# ---------------------------------------------------------------------------------------------
# errors, chart
# ---------------------------------------------------------------------------------------------
def score(rows: list[dict], truth_kind: str) -> float | None:
    """Add the three-axis mean and the error against the truth to every row of one image; return the truth (mD)."""
    for r in rows:
        r["k_mean_mD"] = float(np.mean([r["k_mD"][ax] for ax in AXES3]))
    if truth_kind == "published DNS":
        truth = DNS_MEAN_MD
    else:
        finest = sorted((r for r in rows if r["method"] == "voxel" and r["coarsen"] == 1),
                        key=lambda r: _wall_rank(r["model"]))
        truth = finest[0]["k_mean_mD"] if finest else None
    for r in rows:
        r["truth_kind"], r["truth_mD"] = truth_kind, truth
        r["error"] = None if truth is None else r["k_mean_mD"] / truth - 1.0
        r["is_truth"] = bool(truth_kind != "published DNS" and finest and r is finest[0])
    return truth


def _wall_rank(wall) -> int:
    """Order of a voxel row's closure (None: a row from before the closures were options, the ghost one)."""
    wall = "ghost" if wall is None else wall
    return WALLS.index(wall) if wall in WALLS else len(WALLS)


def label(r: dict) -> str:
    """Short name of a point: ``voxel /2`` (channel closure), ``ghost /2`` or ``network shape_factor``."""
    if r["method"] == "voxel":
        return f"{'voxel' if r['model'] == WALLS[0] else 'ghost'} /{r['coarsen']}"
    return f"network {r['model']}"


def plot(studies: list[dict], path: Path) -> None:
    """Left: |error| against CPU seconds (log-log); right: the three-axis mean k against CPU seconds
    with each image's truth as a line. One colour per image, one marker per method."""
    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13.0, 5.6))
    marks = {("voxel", "channel"): "o", ("voxel", "ghost"): "D", ("voxel", None): "D", ("network", "shape_factor"): "s",
             ("network", "paper"): "^"}
    colours = ["tab:blue", "tab:orange", "tab:green", "tab:red"]
    floor = 2e-3
    for st, col in zip(studies, colours, strict=False):
        for r in st["points"]:
            mark = "*" if r["is_truth"] else marks[r["method"], r["model"]]
            txt = "truth" if r["is_truth"] else label(r).replace("network ", "")
            bx.scatter(r["cpu_s"], r["k_mean_mD"], marker=mark, s=70, color=col, zorder=3)
            bx.annotate(txt, (r["cpu_s"], r["k_mean_mD"]), fontsize=7, xytext=(4, 3), textcoords="offset points")
            if r["error"] is None or r["is_truth"]:
                continue
            e = max(abs(r["error"]), floor)
            face = col if r["error"] >= 0 else "white"
            ax.scatter(r["cpu_s"], e, marker=mark, s=60, color=face, edgecolor=col, zorder=3)
            ax.annotate(txt, (r["cpu_s"], e), fontsize=7, xytext=(4, 3), textcoords="offset points")
        name = f"{st['image']} ({st['shape'][0]}^3)"
        for wall, ls in (("channel", "-"), ("ghost", ":")):
            vox = sorted((r for r in st["points"] if r["method"] == "voxel" and r["error"] is not None
                          and not r["is_truth"] and (r["model"] or "ghost") == wall), key=lambda r: r["cpu_s"])
            if vox:
                tag = f"{name}, {wall}: vs {st['truth_kind']}"
                ax.plot([r["cpu_s"] for r in vox], [max(abs(r["error"]), floor) for r in vox], color=col, lw=1,
                        ls=ls, label=f"{tag}, {st['truth_mD']:.0f} mD" if st["truth_mD"] else tag)
        if st["truth_mD"]:
            bx.axhline(st["truth_mD"], color=col, ls=":" if st["truth_kind"] != "published DNS" else "--", lw=1,
                       label=f"{name}: {st['truth_kind']} {st['truth_mD']:.0f} mD")
    ax.axhline(0.10, color="grey", ls="--", lw=0.8)
    ax.text(0.02, 0.105, "10 %", fontsize=7, color="grey", transform=ax.get_yaxis_transform())
    for a in (ax, bx):
        a.set_xscale("log")
        a.set_yscale("log")
        a.set_xlabel("CPU time, s (three axes; network: one extraction + three solves)")
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7, loc="best")
    ax.set_ylabel("|k mean / truth - 1|  (filled: above the truth, open: below)")
    bx.set_ylabel("k, mean of x, y, z (mD)")
    ax.set_title("error: network (square shape_factor, triangle paper);\nvoxel Stokes /coarsening (circle: "
                 "channel wall closure, diamond: ghost)", fontsize=9)
    bx.set_title("permeability; dashed: published DNS, dotted: finest voxel solve (a convergence check)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def table(studies: list[dict]) -> str:
    """Markdown table of every point."""
    lines = ["| image | method | voxel (µm) | kx | ky | kz | mean (mD) | truth | error | CPU (s) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for st in studies:
        for r in st["points"]:
            k = r["k_mD"]
            err = "truth" if r["is_truth"] else ("" if r["error"] is None else f"{100 * r['error']:+.0f} %")
            lines.append(f"| {st['image']} | {label(r)} | {1e6 * r['voxel_size_m']:.2f} | {k['x']:.0f} | "
                         f"{k['y']:.0f} | {k['z']:.0f} | {r['k_mean_mD']:.0f} | {st['truth_kind']} | {err} | "
                         f"{r['cpu_s']:.3g} |")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------
# main
# ---------------------------------------------------------------------------------------------
def _warm_up() -> None:
    """Compile (or load) the numba kernels on a tiny image, so no point pays for it."""
    s = load_sample()
    tiny = VoxelImage(s.phases[:16, :16, :16].copy(), s.voxel_size)
    voxel_permeability(tiny, "x")
    try:
        network_points(tiny)
    except PorefsiError:
        pass


def _saved_studies(out: Path) -> dict:
    """The permeability studies of ``out/results.json`` by image name ({} if there are none)."""
    path = out / "results.json"
    saved = json.loads(path.read_text()) if path.is_file() else {}
    return {st["image"]: st for st in saved.get("permeability", {}).get("studies", [])}


def _replot(out: Path) -> int:
    """``--replot``: re-score the saved points (the cached full-resolution 400^3 point refreshed), redraw."""
    saved = json.loads((out / "results.json").read_text())
    studies = saved["permeability"]["studies"]
    for st in studies:
        if st["image"] == "berea400":
            cached = cached_full_resolution()
            if cached is not None:
                st["points"] = [r for r in st["points"] if not (r["method"] == "voxel" and r["coarsen"] == 1
                                                                and (r["model"] or "ghost") == cached["model"])]
                st["points"].append(cached)
        st["truth_mD"] = score(st["points"], st["truth_kind"])
    write_results(out / "results.json", saved)
    (out / "permeability_table.md").write_text(table(studies))
    plot(studies, out / "figures" / "permeability_speed_accuracy.png")
    return 0


def _arguments(p) -> None:
    p.add_argument("--berea", "--image", dest="berea", type=Path, default=None,
                   help="the 400^3 Berea npz, source of crop200 and berea400 (default: shared/data/berea_icl_400.npz "
                        "one or two folders above the repository, if there; otherwise those images are skipped, "
                        "and the run says so)")
    p.add_argument("--images", nargs="+", default=["sample", "crop200", "berea400"],
                   choices=["sample", "crop200", "berea400"], help="which images to study")
    p.add_argument("--walls", nargs="+", default=[WALLS[0]], choices=list(WALLS),
                   help="voxel solver wall closures to chart (default: channel)")
    p.add_argument("--replot", action="store_true",
                   help="no solves: re-read results.json (and reference/berea400_voxel.json for the whole 400^3 "
                        "at full resolution), re-score, redraw the chart and table")
    p.add_argument("--networks-only", action="store_true",
                   help="recompute the network points only; keep the voxel points of results.json (each study "
                        "records the commit its voxel points came from)")
    p.add_argument("--full-resolution", action="store_true",
                   help="solve the whole 400^3 at full resolution here (~6 GiB, hours) instead of reading "
                        "reference/berea400_voxel.json")


def main(argv=None) -> int:
    """Run the permeability study."""
    args = parse_args(__doc__, argv, _arguments, smoke_help="seconds-long version (32^3 corner, coarsening 1, 2)")
    if args.replot:
        return _replot(output_dir(args, HERE))
    berea, skipped = locate_berea(args.berea, args.images, args.smoke)  # before the output folder is touched
    out = output_dir(args, HERE)
    studies = []
    head = git_head()  # the code the points are computed with (HEAD may move during an hour-long run)
    before = _saved_studies(out) if args.networks_only else {}
    _warm_up()
    for name, img, truth_kind, factors in images(args.smoke, args.images, berea):
        points = network_points(img)
        if args.networks_only:
            old = before.get(name, {})
            points += [r for r in old.get("points", []) if r["method"] == "voxel"]
            factors = ()
        for f in factors:
            if name == "berea400" and f == 1 and not args.full_resolution:
                cached = cached_full_resolution()
                if cached is not None:
                    points.append(cached)
                continue
            for wall in args.walls:
                points.append(voxel_point(img, f, wall))
                print(f"{name} voxel {wall} /{f}: {points[-1]['k_mD']} mD, {points[-1]['cpu_s']:.1f} s CPU",
                      flush=True)
        truth = score(points, truth_kind)
        studies.append({"image": name, "shape": list(img.shape), "voxel_size_m": img.voxel_size,
                        "porosity": img.porosity, "truth_kind": truth_kind, "truth_mD": truth, "points": points,
                        "commit": head, "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
                        "load_after": loadavg(),
                        "voxel_commit": before[name].get("voxel_commit", before[name].get("commit"))
                        if name in before else head})
        for r in points:
            err = "" if r["error"] is None else f"{100 * r['error']:+.1f} %"
            print(f"{name:>9} {label(r):<22} mean {r['k_mean_mD']:8.1f} mD  {err:>8}  CPU {r['cpu_s']:8.1f} s",
                  flush=True)
    res_path = out / "results.json"
    saved = json.loads(res_path.read_text()) if res_path.is_file() else {"case": "speed_accuracy"}
    if not args.smoke:  # the images not studied in this run keep their earlier points (each with its commit)
        done = {st["image"] for st in studies}
        kept = [st for st in saved.get("permeability", {}).get("studies", []) if st["image"] not in done]
        order = ["sample120", "crop200", "berea400"]
        studies = sorted(kept + studies, key=lambda st: order.index(st["image"]) if st["image"] in order else 9)
    saved["permeability"] = {"smoke": args.smoke, "dns_mD": DNS_MD, "dns_mean_mD": DNS_MEAN_MD, "studies": studies,
                             "berea400_file": None if berea is None else str(berea),
                             "skipped": {n: "400^3 Berea npz not found (--berea); earlier points kept"
                                         for n in skipped}}
    write_results(res_path, saved)
    (out / "permeability_table.md").write_text(table(studies))
    plot(studies, out / "figures" / "permeability_speed_accuracy.png")
    print(f"outputs in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
