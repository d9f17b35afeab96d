"""Where the extraction's time goes: wall and CPU of each stage and sub-stage of ``extract_network``.

The 400^3 Berea (``../shared/data/berea_icl_400.npz``), cropped (``--size`` < 400: the corner
``[:n]^3``) or mirror-tiled (``--size`` > 400: ``numpy.pad(image, (n - 400) // 2,
mode="symmetric")``, as the 1000^3 rows of ``docs/benchmarks.md``; odd excess padded one more at the
end), extracted in this process after a warm-up on a small lattice (numba kernels compiled or
loaded). Each stage function of :mod:`porefsi.network.extract`, :mod:`porefsi.network._mb_conduits`
and :mod:`porefsi.network._mb_section_law` is wrapped to add its wall and CPU seconds
(``time.process_time``: all threads) and call count; nested stages are inside their parents
(``measure_sections`` holds ``section_law_lengths``, which holds ``_law_radii``, ``_law_areas``,
``_side_integrals``). The CLI's cluster filter and file I/O are not included (``porefsi extract``
adds them). Also printed: the whole extraction's wall and CPU, peak RSS (``ru_maxrss``), load.

Usage::

    NUMBA_NUM_THREADS=1 python benchmarks/bench_extract_stages.py --size 400
    flock LOCK bash -c 'ulimit -v 12000000; python benchmarks/bench_extract_stages.py --size 1000'

A 1000^3 run needs ~7.5 GB and ~5 CPU-minutes: run it under the heavy-job lock.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

import porefsi.network._mb_conduits as mc
import porefsi.network._mb_section_law as sl
import porefsi.network.extract as ex
from porefsi.image.synthetic import sphere_lattice
from porefsi.image.voxel_image import VoxelImage

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "berea_icl_400.npz"  # next to the checkout

#: (module, function) pairs timed, in the order printed.
STAGES = [
    (ex, "_distance_map"), (ex, "_pore_centres"), (ex, "_flood_regions"), (ex, "_pores_and_throats"),
    (ex, "subvoxel_radii"), (mc, "_stair_section_peaks"), (ex, "measure_sections"), (mc, "_sections"),
    (mc, "section_law_lengths"), (sl, "_law_radii"), (sl, "_law_areas"), (sl, "_side_integrals"),
    (ex, "face_sections"),
]


def timed(acc: dict, mod, name: str) -> None:
    """Replace ``mod.name`` by a wrapper adding its wall, CPU and calls to ``acc[name]``."""
    fn = getattr(mod, name)

    def wrapper(*a, **k):
        w, c = time.perf_counter(), time.process_time()
        try:
            return fn(*a, **k)
        finally:
            row = acc.setdefault(name, [0.0, 0.0, 0])
            row[0] += time.perf_counter() - w
            row[1] += time.process_time() - c
            row[2] += 1

    setattr(mod, name, wrapper)


def image(path: Path, n: int) -> VoxelImage:
    """The Berea cropped or mirror-tiled to n^3."""
    d = np.load(path)
    im = d["image"]
    if n > im.shape[0]:
        p = n - im.shape[0]
        im = np.pad(im, [(p // 2, p - p // 2)] * 3, mode="symmetric")
    else:
        im = np.ascontiguousarray(im[:n, :n, :n])
    return VoxelImage(im, float(d["voxel_size_m"]))


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=400, help="edge of the cube (crop below 400, mirror tile above)")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--json", type=Path, help="append the result as one JSON line")
    a = ap.parse_args(argv)
    if not a.data.exists():
        sys.exit(f"{a.data} not found; pass --data PATH to berea_icl_400.npz")
    ex.extract_network(sphere_lattice(n=(2, 1, 1)).image)  # compile / load the kernels
    acc: dict = {}
    for mod, name in STAGES:
        timed(acc, mod, name)
    holder = [image(a.data, a.size)]
    w, c = time.perf_counter(), time.process_time()
    out = ex._extract(holder, min_radius="auto", extent=2.0, merge_ratio=0.9, conductance=None)
    wall, cpu = time.perf_counter() - w, time.process_time() - c
    res = {"size": a.size, "threads": os.environ.get("NUMBA_NUM_THREADS", "default"), "wall": wall, "cpu": cpu,
           "peak_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, "load": os.getloadavg()[0],
           "pores": out.network.n_pores, "throats": out.network.n_throats,
           "stages": {k: {"wall": v[0], "cpu": v[1], "calls": v[2]} for k, v in acc.items()}}
    print(f"{a.size}^3, NUMBA_NUM_THREADS={res['threads']}: wall {wall:.1f} s, CPU {cpu:.1f} s, "
          f"peak {res['peak_gib']:.2f} GiB, load {res['load']:.2f}; {res['pores']} pores, {res['throats']} throats")
    print(f"    {'stage':<22} {'wall s':>8} {'CPU s':>8} {'calls':>6}")
    for _, name in STAGES:
        if name in acc:
            print(f"    {name:<22} {acc[name][0]:8.2f} {acc[name][1]:8.2f} {acc[name][2]:6d}")
    if a.json:
        with open(a.json, "a") as f:
            f.write(json.dumps(res) + "\n")
    return res


if __name__ == "__main__":
    main()
