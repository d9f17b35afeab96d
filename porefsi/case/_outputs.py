"""The files of a run directory besides the checkpoint (private; :func:`porefsi.case.run.run_case`).

Per exchange step the pore arrays and the pore-size table (``pores/``); at the snapshot times the
ParaView files (``vtk/``, ``*.pvd``); at the end the PNG figures (``figures/``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from porefsi.case.config import Case
from porefsi.coupling.loop import CoupledRun
from porefsi.coupling.records import ExchangeRecord
from porefsi.io import results
from porefsi.io.network_vtk import write_network_vtp

__all__ = ["PSD_BINS", "PSD_SPAN", "psd_edges", "write_pores", "snapshot_due", "write_snapshot", "figures",
           "snapshot", "SNAP_KEYS"]

#: Number of pore-size bins of ``pores/psd_NNNN.csv``.
PSD_BINS = 30
#: The bins span [0, PSD_SPAN x the largest pore radius of the reference network].
PSD_SPAN = 1.5


def psd_edges(net) -> np.ndarray:
    r_max = float(np.max(net.pore_radius)) if net.n_pores else 1.0
    return np.linspace(0.0, PSD_SPAN * r_max, PSD_BINS + 1)


def write_pores(out: Path, rec: ExchangeRecord, edges: np.ndarray) -> None:
    """``pores/step_NNNN.npz`` (per-pore arrays) and ``pores/psd_NNNN.csv`` of one exchange step."""
    net, f = rec.network, rec.flow
    results.write_npz(out / "pores" / f"step_{rec.step:04d}.npz", {
        "step": np.int64(rec.step), "time_s": np.float64(rec.t),
        "pore_pressure_Pa": np.asarray(f.fluid_pressure, float), "nw_saturation": np.asarray(f.nw_saturation, float),
        "pore_radius_m": net.pore_radius, "pore_volume_m3": net.pore_volume, "pore_coords_m": net.pore_coords})
    r = np.minimum(net.pore_radius, edges[-1])  # larger pores are counted in the last bin
    count, _ = np.histogram(r, bins=edges)
    vol, _ = np.histogram(r, bins=edges, weights=net.pore_volume)
    n = len(count)
    results.write_csv(out / "pores" / f"psd_{rec.step:04d}.csv", {
        "step": [rec.step] * n, "time_s": [rec.t] * n, "radius_lo_m": edges[:-1].tolist(),
        "radius_hi_m": edges[1:].tolist(), "n_pores": count.tolist(), "pore_volume_m3": vol.tolist()})


def snapshot_due(case: Case, t0: float, t1: float, last: bool) -> bool:
    return last or any(t0 < s <= t1 + 1e-12 for s in case.output.snapshot_times)


def write_snapshot(out: Path, rec: ExchangeRecord, run: CoupledRun, series: dict) -> None:
    vtk = out / "vtk"
    vtk.mkdir(exist_ok=True)
    mesh = run.problem.mesh
    solid_file = vtk / f"solid_{rec.step:04d}.vtu"
    mesh.write_vtu(solid_file, point_data={
        "displacement": rec.displacement, "von_mises": rec.von_mises, "pore_force": rec.nodal_force})
    net = rec.network
    f = rec.flow
    net_file = vtk / f"network_{rec.step:04d}.vtp"
    write_network_vtp(net, net_file, point_data={
        "pressure": np.nan_to_num(f.fluid_pressure), "nw_saturation": f.nw_saturation,
        "pore_state": f.pore_state.astype(float)})
    series["solid"].add(rec.t, solid_file)
    series["network"].add(rec.t, net_file)


def figures(out: Path, ts: dict, snapshots: list, run: CoupledRun, title: str) -> list[str]:
    from porefsi import plot

    fig = out / "figures"
    fig.mkdir(exist_ok=True)
    made = [plot.plot_timeseries(ts, fig / "timeseries.png", title=title)]
    made.append(plot.plot_psd([(s["t"], s["radius"]) for s in snapshots], fig / "pore_size_distribution.png"))
    net0 = run.problem.network
    for s in snapshots:
        tag = f"t{s['t']:07.3f}s".replace(".", "_")
        made.append(plot.render_network(s["coords"], s["radius"], net0.throat_conns, 1.0 - s["nw_saturation"],
                                        fig / f"drainage_{tag}.png", label="wetting saturation", clim=(0, 1),
                                        fade_above=0.999))
        # Magnitudes (VTK's font has no '|'). Colour scales stop at the 99th percentile: the extremes sit
        # at a few nodes next to loaded pores.
        fn = np.linalg.norm(s["force"], axis=1)
        for name, vals, what, unit, cmap in (
                ("displacement", np.linalg.norm(s["displacement"], axis=1), "displacement", "m", "viridis"),
                ("pore_force", fn, "pore force", "N", "inferno"),
                ("von_mises", s["von_mises"], "von Mises", "Pa", "magma")):
            shown = vals[vals > 0] if name == "pore_force" else vals
            top = float(np.percentile(shown, 99)) if shown.size else 0.0
            factor, u = plot.si_scale([top], unit)
            made.append(plot.render_solid(run.problem.mesh.points, run.problem.mesh.tets, vals * factor,
                                          fig / f"{name}_{tag}.png", label=f"{what} ({u})", cmap=cmap, cut="y",
                                          clim=(0.0, max(top * factor, 1e-30))))
    return [str(p.relative_to(out)) for p in made]


def snapshot(rec: ExchangeRecord) -> dict:
    return {"t": rec.t, "step": rec.step, "coords": rec.network.pore_coords.copy(),
            "radius": rec.network.pore_radius.copy(), "nw_saturation": np.asarray(rec.flow.nw_saturation).copy(),
            "displacement": rec.displacement, "von_mises": rec.von_mises, "force": rec.nodal_force}


SNAP_KEYS = ("coords", "radius", "nw_saturation", "displacement", "von_mises", "force")
