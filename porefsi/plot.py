"""Figures: matplotlib curves and pyvista off-screen 3-D scenes, saved as PNG.

Everything here consumes plain arrays (no physics) and imports matplotlib / pyvista lazily,
so ``import porefsi`` stays cheap and headless machines work (Agg backend, off-screen VTK).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from porefsi.units import MILLIDARCY

__all__ = ["plot_timeseries", "plot_psd", "plot_pc_s", "plot_drainage_pc_s", "render_network", "render_solid", "Style",
           "si_scale"]

_PREFIXES = ((1e-12, "p"), (1e-9, "n"), (1e-6, "µ"), (1e-3, "m"), (1.0, ""), (1e3, "k"), (1e6, "M"), (1e9, "G"))


def si_scale(values, unit: str) -> tuple[float, str]:
    """The SI prefix that puts the largest magnitude of ``values`` between 1 and 1000.

    Parameters
    ----------
    values : array_like
        Values in the base unit (e.g. metres, pascals); NaN and inf are ignored.
    unit : str
        The base unit's symbol (``"m"``, ``"Pa"``, ``"N"``).

    Returns
    -------
    scale : float
        Multiply ``values`` by this to express them in the returned unit.
    unit : str
        Prefixed unit, e.g. ``"pm"`` for displacements of a few 1e-12 m; the base unit when every
        value is zero or not finite.

    Examples
    --------
    >>> si_scale([6.9e-12, 1e-13], "m")
    (1000000000000.0, 'pm')
    >>> si_scale([2734.6], "Pa")
    (0.001, 'kPa')
    """
    v = np.abs(np.asarray(values, float))
    v = v[np.isfinite(v)]
    top = float(v.max()) if v.size else 0.0
    if top == 0.0:
        return 1.0, unit
    factor, prefix = _PREFIXES[0]
    for f, pre in _PREFIXES:
        if top >= f * (1 - 1e-9):
            factor, prefix = f, pre
    return 1.0 / factor, prefix + unit


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def plot_timeseries(ts: Mapping[str, Sequence[float]], path: str | Path, *, title: str = "") -> Path:
    """Panels of the coupled run over time: saturation, pressures, forces, deformation, stress, k.

    Parameters
    ----------
    ts : mapping of column name -> sequence
        Needs ``time_s``; plots whichever of ``sw``, ``inlet_pressure_Pa``, ``capillary_pressure_Pa``,
        ``total_pore_force_N``, ``max_displacement_m``, ``max_von_mises_Pa``, ``permeability_m2``
        are present.
    path : str or Path
        PNG file to write.
    """
    plt = _plt()
    t = np.asarray(ts["time_s"], float)
    panels = [
        ("sw", "wetting saturation", 1.0),
        ("inlet_pressure_Pa", "inlet pressure (kPa)", 1e-3),
        ("capillary_pressure_Pa", "capillary pressure (kPa)", 1e-3),
        ("total_pore_force_N", "total pore force", "N"),
        ("max_displacement_m", "max displacement", "m"),
        ("max_von_mises_Pa", "max von Mises", "Pa"),
        ("permeability_m2", "permeability (mD)", 1.0 / MILLIDARCY),
    ]
    panels = [p for p in panels if p[0] in ts]
    for i, (key, label, scale) in enumerate(panels):  # a unit the run's own magnitudes read well in
        if isinstance(scale, str):
            factor, unit = si_scale(ts[key], scale)
            panels[i] = (key, f"{label} ({unit})", factor)
    ncol = 2
    nrow = max(1, (len(panels) + 1) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(10, 2.6 * nrow), squeeze=False, sharex=True)
    for ax, (key, label, scale) in zip(axes.ravel(), panels, strict=False):
        y = np.asarray(ts[key], float) * scale
        if key == "permeability_m2":
            y, label = _relative_change(y)
        ax.plot(t, y, "-", lw=1.5)
        ax.set_ylabel(label)
        ax.ticklabel_format(axis="y", useOffset=False)  # tiny changes (e.g. k over a run) stay readable
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(panels):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _relative_change(k_mD: np.ndarray) -> tuple[np.ndarray, str]:
    """Permeability as its change from the first value (%, or ppm when below 0.01 %), and the label.

    A run's permeability moves by parts per million to a few per cent: plotted in mD, a 1e-8 change
    shows as an axis of seven-digit labels.
    """
    k0 = k_mD[np.isfinite(k_mD)][0] if np.isfinite(k_mD).any() else np.nan
    if not np.isfinite(k0) or k0 == 0:
        return k_mD, "permeability (mD)"
    rel = k_mD / k0 - 1.0
    big = np.nanmax(np.abs(rel)) >= 1e-4
    return rel * (1e2 if big else 1e6), f"permeability change ({'%' if big else 'ppm'} of {k0:.4g} mD)"


def plot_psd(radii_at: Sequence[tuple[float, np.ndarray]], path: str | Path, *, bins: int = 25) -> Path:
    """Pore-size distribution at several times (paper fig. 13): counts vs pore radius (µm)."""
    plt = _plt()
    allr = np.concatenate([np.asarray(r, float) for _, r in radii_at]) * 1e6
    edges = np.linspace(allr.min(), allr.max(), bins + 1) if allr.size else np.linspace(0, 1, bins + 1)
    fig, ax = plt.subplots(figsize=(6, 4))
    for t, r in radii_at:
        h, _ = np.histogram(np.asarray(r, float) * 1e6, bins=edges)
        ax.plot(0.5 * (edges[1:] + edges[:-1]), h, "-o", ms=3, label=f"t = {t:g} s")
    ax.set_xlabel("pore radius (µm)")
    ax.set_ylabel("number of pores")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def plot_pc_s(curves: Mapping[str, tuple[np.ndarray, np.ndarray]], path: str | Path) -> Path:
    """Capillary pressure (kPa) vs wetting saturation for several labelled curves."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, (sw, pc) in curves.items():
        ax.plot(np.asarray(sw), np.asarray(pc) * 1e-3, "-", lw=1.5, label=label)
    ax.set_xlabel("wetting saturation")
    ax.set_ylabel("capillary pressure (kPa)")
    ax.set_xlim(0, 1)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def plot_drainage_pc_s(dynamic: tuple[Sequence[float], Sequence[float]],
                       quasi_static: tuple[Sequence[float], Sequence[float]], path: str | Path, *,
                       breakthrough_sw: float | None = None, title: str = "") -> Path:
    """Dynamic Pc–S curve of a drainage next to the quasi-static (invasion percolation) one.

    Parameters
    ----------
    dynamic : (sw, pc) pair of sequences of float
        Wetting saturation and capillary pressure (inlet minus outlet), Pa, one entry per event
        (e.g. ``history['sw']``, ``history['capillary_pressure_pa']``); NaN pressures (skipped
        solves) leave gaps.
    quasi_static : (sw, pc) pair of sequences of float
        Wetting saturation and capillary pressure, Pa, after each invasion step (e.g.
        ``InvasionResult.pc_curve()``); drawn as a staircase (the pressure holds until the next step).
    path : str or Path
        PNG file to write.
    breakthrough_sw : float, optional
        Wetting saturation at breakthrough of the dynamic run: a vertical marker.
    title : str
        Figure title.

    Returns
    -------
    Path
        ``path``.
    """
    plt = _plt()
    sw_d, pc_d = (np.asarray(v, float) for v in dynamic)
    sw_q, pc_q = (np.asarray(v, float) for v in quasi_static)
    fig, ax = plt.subplots(figsize=(6, 4))
    if sw_q.size:
        # start the staircase at Sw = 1 with the first step's pressure (nothing invaded before it)
        ax.step(np.concatenate([[1.0], sw_q]), np.concatenate([pc_q[:1], pc_q]) * 1e-3, where="pre", lw=1.5,
                color="0.3", label="quasi-static (invasion percolation with trapping)")
    ax.plot(sw_d, pc_d * 1e-3, "-", lw=1.0, color="C0", label="dynamic (inlet minus outlet pressure)")
    if breakthrough_sw is not None and np.isfinite(breakthrough_sw):
        ax.axvline(breakthrough_sw, color="C3", ls="--", lw=1.0, label=f"breakthrough, Sw = {breakthrough_sw:.3f}")
    ax.set_xlabel("wetting saturation")
    ax.set_ylabel("capillary pressure (kPa)")
    ax.set_xlim(0, 1)
    if title:
        ax.set_title(title)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def _pv():
    os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")
    import pyvista as pv

    try:  # headless machines: VTK warns that there is no X server, then renders off-screen anyway
        from vtkmodules.vtkCommonCore import vtkLogger

        vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    except ImportError:  # pragma: no cover - older VTK layouts
        pass
    pv.OFF_SCREEN = True
    return pv


def _bar(label: str) -> dict:
    """Scalar-bar options: vertical at the right edge, title above, three significant digits.

    VTK's default font has no µ: it is written ``u`` (as in the axes' ``um``).
    """
    return {"title": label.replace("µ", "u") + "\n", "vertical": True, "position_x": 0.86, "position_y": 0.15,
            "width": 0.05, "height": 0.6, "fmt": "%.3g", "title_font_size": 14, "label_font_size": 12, "n_labels": 5}


def _frame(p) -> None:
    """Bounding-box axes in µm on the box's outer edges (not through the scene)."""
    p.show_bounds(xtitle="x (um)", ytitle="y (um)", ztitle="z (um)", font_size=10, location="outer",
                  n_xlabels=3, n_ylabels=3, n_zlabels=3, fmt="%.0f")


@dataclasses.dataclass(frozen=True)
class Style:
    """How a 3-D scene is coloured and framed (the keyword options of the ``render_*`` functions).

    Attributes
    ----------
    label : str
        Name of the coloured quantity (scalar-bar title).
    cmap : str, optional
        Matplotlib colour map (each scene has its default).
    clim : (float, float), optional
        Colour range (default: the data's).
    window_size : (int, int)
        Image size, pixels.
    """

    label: str = ""
    cmap: str | None = None
    clim: tuple | None = None
    window_size: tuple = (900, 700)


def render_network(coords, radii, conns, values, path: str | Path, *, fade_above: float | None = None,
                   **style) -> Path:
    """Pores as spheres (true radius) and throats as lines, coloured by a per-pore value.

    Parameters
    ----------
    coords : ndarray, shape (Np, 3)
        Pore centres, m (drawn in µm).
    radii : ndarray, shape (Np,)
        Pore radii, m.
    conns : ndarray of int, shape (Nt, 2)
    values : ndarray, shape (Np,)
        Colour per pore (e.g. wetting saturation with the default map: red = wetting (water),
        blue = non-wetting (oil), as in the paper's figure 5).
    fade_above : float, optional
        Draw pores whose value is above this threshold translucent (e.g. 0.999 for wetting
        saturation), so the few invaded pores of an early drainage stand out in the cloud.
    **style
        :class:`Style` options (``label``, ``cmap`` default ``"coolwarm"``, ``clim``, ``window_size``).
    """
    st = Style(**style)
    label, cmap, clim = st.label, st.cmap or "coolwarm", st.clim
    pv = _pv()
    c = np.asarray(coords, float) * 1e6
    vals = np.asarray(values, float)
    rad = np.asarray(radii, float) * 1e6
    sphere = pv.Sphere(radius=1.0, theta_resolution=12, phi_resolution=12)
    faded = np.zeros(len(vals), bool) if fade_above is None else vals > fade_above

    def spheres(mask):
        sub = pv.PolyData(c[mask])
        sub["radius"] = rad[mask]
        sub[label or "value"] = vals[mask]
        return sub.glyph(geom=sphere, scale="radius", orient=False)

    conns = np.asarray(conns, np.int64)
    lines = pv.PolyData(c)
    if conns.size:
        lines.lines = np.hstack([np.full((len(conns), 1), 2), conns]).ravel()
    p = pv.Plotter(off_screen=True, window_size=st.window_size)
    p.add_mesh(lines, color="grey", line_width=1)
    if faded.any():
        clim = clim if clim is not None else (float(np.nanmin(vals)), float(np.nanmax(vals)))
        p.add_mesh(spheres(faded), scalars=label or "value", cmap=cmap, clim=clim, opacity=0.15,
                   show_scalar_bar=faded.all(), scalar_bar_args=_bar(label))
    if not faded.all():
        p.add_mesh(spheres(~faded), scalars=label or "value", cmap=cmap, clim=clim,
                   scalar_bar_args=_bar(label))
    _frame(p)
    p.camera_position = "iso"
    p.screenshot(str(path))
    p.close()
    return Path(path)


def render_solid(points, tets, values, path: str | Path, *, displacement=None, scale: float = 0.0,
                 cut: str | None = None, **style) -> Path:
    """Surface of the tetrahedral solid coloured by a nodal value, optionally warped.

    Parameters
    ----------
    points : ndarray, shape (Nn, 3)
        Node coordinates, m (drawn in µm).
    tets : ndarray of int, shape (Ne, 4)
    values : ndarray, shape (Nn,) or (Ne,)
        Nodal or element values to colour by.
    displacement : ndarray, shape (Nn, 3), optional
        Warp the surface by ``scale * displacement`` (displacements are far below a voxel: pick a
        visible scale, and say so in the caption).
    cut : {'x', 'y', 'z'}, optional
        Remove the half of the sample above the mid-plane normal to this axis, to show the
        interior (box faces are held by the loading frame, so the outside shows little).
    **style
        :class:`Style` options (``label``, ``cmap`` default ``"viridis"``, ``clim``, ``window_size``).
    """
    st = Style(**style)
    label = st.label
    pv = _pv()
    x = np.asarray(points, float)
    if displacement is not None and scale:
        x = x + scale * np.asarray(displacement, float)
    tets = np.asarray(tets, np.int64)
    cells = np.hstack([np.full((len(tets), 1), 4), tets]).ravel()
    grid = pv.UnstructuredGrid(cells, np.full(len(tets), 10, np.uint8), x * 1e6)
    v = np.asarray(values, float)
    name = label or "value"
    if v.shape[0] == len(tets):
        grid.cell_data[name] = v
    else:
        grid.point_data[name] = v
    if cut is not None:
        normal = np.eye(3)["xyz".index(cut)]
        grid = grid.clip(normal=normal, origin=grid.center, invert=True)
    try:
        surf = grid.extract_surface(algorithm="dataset_surface")
    except TypeError:  # pyvista < 0.47 has no `algorithm`
        surf = grid.extract_surface()
    p = pv.Plotter(off_screen=True, window_size=st.window_size)
    p.add_mesh(surf, scalars=name, cmap=st.cmap or "viridis", clim=st.clim, scalar_bar_args=_bar(label))
    _frame(p)
    p.camera_position = "iso"
    p.screenshot(str(path))
    p.close()
    return Path(path)
