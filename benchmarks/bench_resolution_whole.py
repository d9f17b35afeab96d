"""Benchmark: a whole image upsampled f times (each voxel -> f^3 at 1/f of the voxel size), issue 15.

Extraction cost per voxel, pore count and network permeability on the three axes against the
native image's, in one process per factor (2 numba threads by default)::

    NUMBA_NUM_THREADS=2 python benchmarks/bench_resolution_whole.py --factor 1
    NUMBA_NUM_THREADS=2 python benchmarks/bench_resolution_whole.py --factor 3 --json out.jsonl

The image defaults to ``berea_icl_400.npz`` in ``$POREFSI_DATA`` or ``../shared/data``; f = 3 of the
400³ Berea is 1.7e9 voxels and peaks at ~13 GiB (docs/benchmarks.md, "Extraction at high resolution").
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

import numpy as np  # noqa: E402
from _data import data_file  # noqa: E402
from bench_extract_resolution import upsample  # noqa: E402

import porefsi  # noqa: E402
from porefsi.image import VoxelImage  # noqa: E402


def run(path: str, f: int) -> dict:
    """Upsample, extract, solve; the record (CPU s, µs/voxel, pores, k per axis in mD, peak GiB)."""
    src = porefsi.read_image(path)
    ph = upsample(src.phases, f) if f > 1 else src.phases
    img = VoxelImage(ph, src.voxel_size / f)
    n = int(ph.size)
    del ph
    c0, w0 = time.process_time(), time.perf_counter()
    net = porefsi.extract_network(img).network
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    del img
    k = [porefsi.absolute_permeability(net, a).k_m2 / porefsi.MILLIDARCY for a in "xyz"]
    return dict(image=str(path), f=f, voxels=n, cpu_s=cpu, wall_s=wall, us_per_voxel=cpu / n * 1e6,
                n_pores=int(net.n_pores), n_throats=int(net.n_throats), k_mD=k, k_mean=float(np.mean(k)),
                peak_rss_gib=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20,
                load=open("/proc/loadavg").read().split()[:3] if Path("/proc/loadavg").exists() else None)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--image", default=str(data_file("berea_icl_400.npz")))
    ap.add_argument("--factor", type=int, default=1, help="upsampling factor f (1 = native)")
    ap.add_argument("--json", help="append the record to this file (JSON lines)")
    args = ap.parse_args(argv)
    if not Path(args.image).is_file():
        print(f"bench_resolution_whole: SKIPPED, no image at {args.image}; pass --image or set POREFSI_DATA")
        return 0
    rec = run(args.image, args.factor)
    print(json.dumps(rec), flush=True)
    if args.json:
        with open(args.json, "a") as fh:
            fh.write(json.dumps(rec) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
