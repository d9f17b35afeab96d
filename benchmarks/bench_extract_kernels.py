"""CPU time of the extraction's largest kernels on one image (for refactoring: time before/after).

Runs the stages of :func:`porefsi.network.extract.extract_network` one kernel at a time on the
same inputs and prints the best-of-``--repeat`` CPU seconds (``time.process_time``) of
``_families``, ``_flood``, ``_interfaces``, ``_sections`` and ``_subvoxel_peaks``, and of
``absolute_permeability`` on the resulting network (3 axes).

Usage::

    python benchmarks/bench_extract_kernels.py [--data DIR] [--crop 200] [--repeat 3]
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from porefsi.flow.permeability import absolute_permeability
from porefsi.image.voxel_image import VoxelImage
from porefsi.network import _kernels as kern
from porefsi.network._mb_conduits import _radius_table
from porefsi.network._mb_sections import _sections, _subvoxel_peaks
from porefsi.network.extract import BALL_CORE, BALL_TEST_REACH, _distance_map, extract_network

DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data"


def best(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t = time.process_time()
        out = fn()
        times.append(time.process_time() - t)
    return min(times), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--crop", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    d = np.load(a.data / "berea_icl_400.npz")
    img = np.ascontiguousarray(d["image"][: a.crop, : a.crop, : a.crop]).astype(np.uint8)
    vs = float(d["voxel_size_m"])
    ext = extract_network(VoxelImage(img, vs))  # compiles everything
    dt2 = _distance_map(img)
    max_d2 = int(dt2.max())
    sqrt_tab = np.sqrt(np.arange(max_d2 + 1, dtype=np.float64))
    labels = np.full(dt2.shape, -1, np.int32)
    offsets = kern.ball_offsets(BALL_TEST_REACH)
    off_class, reach2 = kern.ball_reach_table(offsets, max_d2)
    like = np.empty(0, np.int32)
    balls, _ = kern._maximal_balls(dt2, np.int64(math.ceil(4 - 1e-9)), offsets, off_class, reach2, labels, like)

    def families():
        labels.fill(-1)
        return kern._families(dt2, balls, sqrt_tab, 2.0, 0.9, labels, float(BALL_CORE))

    rows = {}
    rows["_families"], (master, _) = best(families, a.repeat)
    centre_idx = balls[master == np.arange(balls.size, dtype=np.int32)]
    n_pore = int(img.sum())

    def flood():
        labels.fill(-1)
        labels.reshape(-1)[centre_idx] = np.arange(centre_idx.size, dtype=np.int32)
        buf = np.empty(n_pore - int(centre_idx.size), np.int32)
        return kern._flood(dt2, labels, buf, buf)

    rows["_flood"], _ = best(flood, a.repeat)
    lab = np.ascontiguousarray(ext.labels)
    n_p = ext.network.n_pores
    rows["_interfaces"], (conns, _, point, _) = best(lambda: kern._interfaces(lab, dt2, np.int64(n_p)), a.repeat)
    rows["_sections"], _ = best(lambda: _sections(lab, conns, np.int64(n_p)), a.repeat)
    tab = _radius_table(dt2, "wall")
    rows["_subvoxel_peaks"], _ = best(lambda: _subvoxel_peaks(dt2, tab, point), a.repeat)
    net = ext.network
    rows["absolute_permeability x3"], _ = best(lambda: [absolute_permeability(net, ax) for ax in "xyz"], a.repeat)
    load = open("/proc/loadavg").read().split()[:3]
    print(f"Berea {a.crop}^3 crop, {n_p} pores, {net.n_throats} throats; load {load}")
    for k, v in rows.items():
        print(f"  {k:28s} {v:8.4f} s CPU (best of {a.repeat})")


if __name__ == "__main__":
    main()
