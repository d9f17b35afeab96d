"""Run a drainage with pressure samples and compare two runs (used by ``bench_drainage_scheme.py``).

A run goes to breakthrough and on to ``1.25 x`` its breakthrough time (``tail``), reading the
state (inlet pressure from a solve, wetting saturation) at sample times ``k * dt`` (``dt`` =
the invasion-percolation breakthrough volume over ``Q`` divided by ``samples``), so two runs of
the same network and rate are sampled at the same times. Results are plain arrays (``.npz``) and a
JSON summary, so a long exact reference is computed once and reused.

Comparison (``compare``): time is aligned by time itself (same rate, so the same injected volume):

* invasion order: Spearman and Kendall rank correlation of the invasion times of the pores both
  runs invaded, and the numbers of pores only one of them invaded;
* saturation history: ``Sw(t)`` of each run is piecewise linear between its events; both are
  evaluated on one grid of 4000 times over ``[0, min(t_end)]`` (max absolute and max relative
  difference, relative to the reference's ``Sw``);
* inlet pressure at the common sample times: relative differences to the reference (median,
  90th percentile, max) and the max relative difference of 5-sample running means;
* breakthrough time (relative difference) and saturation.
"""

from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np

from porefsi.flow.drainage import DrainageSimulator
from porefsi.flow.invasion import invasion_percolation

__all__ = ["run_sampled", "compare", "save_run", "load_run"]


def _load():
    return [float(v) for v in open("/proc/loadavg").read().split()[:3]] if os.path.exists("/proc/loadavg") else []


def run_sampled(net, fl, rate, scheme, samples=40, tail=1.25, max_cpu=np.inf, max_wall=np.inf, **options):
    """Drain ``net`` at ``rate`` with ``scheme`` to ``tail`` x breakthrough (or until ``max_cpu`` CPU /
    ``max_wall`` wall seconds, checked at the samples); return the run's record (dict)."""
    ip = invasion_percolation(net, fl, axis="x", stop_at_breakthrough=True)
    vol = net.pore_volume
    v_bt = float(vol[ip.pore_sequence >= 0].sum())
    dt = v_bt / rate / samples
    load0 = _load()
    c0, w0 = time.process_time(), time.perf_counter()
    sim = DrainageSimulator(net, fl, rate=rate, scheme=scheme, skip_solves=True, **options)
    ts, pin, sw = [], [], []
    k, done = 0, False
    while not done:
        k += 1
        sim.advance_to(k * dt)
        st = sim.state
        ts.append(st.t)
        pin.append(st.inlet_pressure)
        sw.append(st.sw)
        bt = sim.breakthrough_time
        done = ((np.isfinite(bt) and st.t >= tail * bt) or time.process_time() - c0 > max_cpu
                or time.perf_counter() - w0 > max_wall)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    h = sim.history()
    e = sim._engine
    extra = {k: int(getattr(e, k)) for k in ("n_certified", "n_batches", "n_local", "n_global") if hasattr(e, k)}
    return dict(
        scheme=scheme, rate=rate, cpu_s=cpu, wall_s=wall, load_before=load0, load_after=_load(),
        breakthrough_time=float(sim.breakthrough_time), breakthrough_sw=float(e.sw_breakthrough),
        complete=bool(np.isfinite(sim.breakthrough_time)), counters={**sim.counters, **extra},
        options={k: v for k, v in options.items()},
        arrays=dict(invasion_time=sim.invasion_time(), sample_t=np.array(ts), sample_pin=np.array(pin),
                    sample_sw=np.array(sw), hist_t=h["time_s"], hist_sw=h["sw"], hist_pin=h["inlet_pressure_pa"]))


def save_run(path, rec, meta):
    """``path.npz`` (arrays) and ``path.json`` (the rest and ``meta``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path.with_suffix(".npz"), **rec["arrays"])
    d = {k: v for k, v in rec.items() if k != "arrays"}
    d["meta"] = meta
    path.with_suffix(".json").write_text(json.dumps(d, indent=1, default=float) + "\n")


def load_run(path):
    """The record :func:`save_run` wrote, or None."""
    path = Path(path)
    if not path.with_suffix(".json").exists() or not path.with_suffix(".npz").exists():
        return None
    d = json.loads(path.with_suffix(".json").read_text())
    with np.load(path.with_suffix(".npz")) as z:
        d["arrays"] = {k: z[k] for k in z.files}
    return d


def compare(ref, run):
    """Differences of ``run`` from ``ref`` (records of :func:`run_sampled`), as a dict of numbers."""
    from scipy.stats import kendalltau, spearmanr

    a, b = ref["arrays"], run["arrays"]
    ta, tb = a["invasion_time"], b["invasion_time"]
    both = np.isfinite(ta) & np.isfinite(tb)
    t_end = min(a["hist_t"][-1], b["hist_t"][-1])
    grid = np.linspace(0.0, t_end, 4000)
    swa = np.interp(grid, np.concatenate([[0.0], a["hist_t"]]), np.concatenate([[1.0], a["hist_sw"]]))
    swb = np.interp(grid, np.concatenate([[0.0], b["hist_t"]]), np.concatenate([[1.0], b["hist_sw"]]))
    m = min(a["sample_t"].size, b["sample_t"].size)
    pa, pb = a["sample_pin"][:m], b["sample_pin"][:m]
    ok = np.isfinite(pa) & np.isfinite(pb) & (np.abs(a["sample_t"][:m] - b["sample_t"][:m]) <= 1e-9 * t_end)
    bta, btb = ref["breakthrough_time"], run["breakthrough_time"]
    return dict(
        n_both=int(both.sum()), only_ref=int((np.isfinite(ta) & ~np.isfinite(tb)).sum()),
        only_run=int((~np.isfinite(ta) & np.isfinite(tb)).sum()),
        spearman=float(spearmanr(ta[both], tb[both])[0]) if both.sum() > 2 else np.nan,
        kendall=float(kendalltau(ta[both], tb[both])[0]) if both.sum() > 2 else np.nan,
        sw_max_abs=float(np.max(np.abs(swa - swb))), sw_max_rel=float(np.max(np.abs(swa - swb) / swa)),
        **_pressure_diffs(pa[ok], pb[ok]),
        bt_rel=float(abs(btb - bta) / bta) if np.isfinite(bta) and np.isfinite(btb) else np.nan,
        bt_sw_ref=ref["breakthrough_sw"], bt_sw_run=run["breakthrough_sw"],
        speedup_cpu=ref["cpu_s"] / run["cpu_s"] if run["cpu_s"] > 0 else np.nan)


def _pressure_diffs(pa, pb):
    """Relative inlet-pressure differences at the samples: median, 90th percentile, max, and the max of
    5-sample running means (a sample that falls between the two runs' times of one fill sees the
    Haines jump of that fill; the running mean shows whether the levels agree)."""
    if pa.size == 0:
        return dict(n_p=0, p_rel_median=np.nan, p_rel_p90=np.nan, p_rel_max=np.nan, p_smooth_rel_max=np.nan)
    d = np.abs(pa - pb) / np.abs(pa)
    k = min(5, pa.size)
    ma, mb = (np.convolve(v, np.ones(k) / k, mode="valid") for v in (pa, pb))
    return dict(n_p=int(pa.size), p_rel_median=float(np.median(d)), p_rel_p90=float(np.percentile(d, 90)),
                p_rel_max=float(d.max()), p_smooth_rel_max=float(np.max(np.abs(ma - mb) / np.abs(ma))))


def git_commit():
    """Commit of the checkout this runs from (for the results' provenance), or ''."""
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=Path(__file__).parent, check=False).stdout.strip()
    except OSError:
        return ""
