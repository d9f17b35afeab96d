"""Drainage entry pressure of voxelised straight ducts: porefsi and PoreSpy against closed forms.

A straight duct of a known cross-section, voxelised at a random sub-voxel offset and rotation
(a voxel is pore when its centre lies inside the section), drained along its axis at
sigma = 0.03 N/m, theta = 0. The exact piston-like entry pressure of a prismatic duct with the
wetting fluid left in its corners (Mayer & Stowe 1965, Princen 1969; the form of Valvatne &
Blunt 2004) at theta = 0 is

* circular tube of radius R: ``2 sigma / R`` (Young-Laplace);
* square of inscribed radius a: ``sigma (1 + sqrt(pi)/2) / a`` (G = 1/16);
* equilateral triangle of inscribed radius r: ``sigma (1 + 2 sqrt(pi G)) / r``, G = sqrt(3)/36;
* slit: a 2h x 16 rectangle (h the half-aperture): the MSP rectangle, ``sigma / R`` with R the
  root of ``(4 - pi) R^2 - 2(2h + 16) R + 32 h = 0`` (``sigma / h`` for infinite plates).

Methods compared, each on the same voxel image:

* porefsi: :func:`porefsi.network.extract.extract_network` then invasion percolation with trapping
  (:func:`porefsi.flow.invasion.invasion_percolation`) along the duct, per conduit model;
* PoreSpy (peers env): ``porespy.simulations.drainage``, image-based sphere insertion with
  ``pc = 2 sigma / (dt vs)``, dt the Euclidean distance transform of the pore voxels (to the
  nearest solid voxel centre), every distinct pc value as a step, inlet and outlet the end slices.

Printed per shape and size: the breakthrough pressure of each method over the closed form, mean
and range over the offsets. Run in the peers env (``/work/peers/bin/python``, PoreSpy 3.2);
without PoreSpy only porefsi's rows are printed.

Usage::

    python benchmarks/bench_pc_closed_forms.py [--offsets 8] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import warnings

import numpy as np

from porefsi.flow.fluids import Fluids
from porefsi.flow.invasion import invasion_percolation
from porefsi.image.voxel_image import VoxelImage
from porefsi.network.extract import extract_network

SIGMA = 0.03
VOXEL = 1.0e-6
DUCT_LENGTH = 12
#: Long side of the slit (a 2h x SLIT_WIDTH rectangle), voxels
SLIT_WIDTH = 16.0

#: shape -> sizes (inscribed radius, or half-aperture for slits), voxels
SIZES = {
    "circle": (1.5, 2.0, 2.5, 3.0, 4.0, 6.0),
    "square": (1.5, 2.0, 3.0, 4.0, 6.0),
    "triangle": (2.0, 3.0, 4.0, 6.0),
    "slit": (1.5, 2.0, 3.0, 4.0, 6.0),
}
TRIANGLE_G = math.sqrt(3.0) / 36.0


def closed_form(shape: str, r: float) -> float:
    """Exact entry pressure (Pa) of the continuum duct, r in voxels, theta = 0."""
    rm = r * VOXEL
    if shape == "circle":
        return 2.0 * SIGMA / rm
    if shape == "square":
        return SIGMA * (1.0 + math.sqrt(math.pi) / 2.0) / rm
    if shape == "triangle":
        return SIGMA * (1.0 + 2.0 * math.sqrt(math.pi * TRIANGLE_G)) / rm
    if shape == "slit":
        return SIGMA / rectangle_meniscus_radius(2.0 * r, SLIT_WIDTH) / VOXEL
    raise ValueError(shape)


def rectangle_meniscus_radius(a: float, b: float) -> float:
    r"""Meniscus radius R = sigma / Pc at piston entry into an a x b rectangle, theta = 0 (MSP).

    Pc A_eff = sigma L_eff with four corner menisci of radius R: A_eff = ab - (4 - pi) R^2,
    L_eff = 2(a + b) - (8 - 2 pi) R, so :math:`(4-\pi)R^2 - 2(a+b)R + ab = 0` (smaller root). A
    square of side 2a gives R = 2a / (2 + sqrt(pi)), the MSP square; b -> infinity gives a / 2.
    """
    p, area, c = 2.0 * (a + b), a * b, 4.0 - math.pi
    return (p - math.sqrt(p * p - 4.0 * c * area)) / (2.0 * c)


def section(shape: str, r: float, w: int, rng: np.random.Generator) -> np.ndarray:
    """Cross-section (bool, (w, w)) centred at a random sub-voxel offset, random rotation."""
    c = (w - 1) / 2.0 + rng.uniform(-0.5, 0.5, 2)
    y, z = np.meshgrid(np.arange(w) - c[0], np.arange(w) - c[1], indexing="ij")
    if shape == "circle":
        return y * y + z * z < r * r
    if shape == "slit":
        return (np.abs(z) < r) & (np.abs(y) < SLIT_WIDTH / 2.0)
    n_sides = {"square": 4, "triangle": 3}[shape]
    phi = rng.uniform(0, 2 * math.pi)
    sec = np.ones_like(y, bool)
    for i in range(n_sides):
        a = phi + 2 * math.pi * i / n_sides
        sec &= y * math.cos(a) + z * math.sin(a) < r
    return sec


def duct(shape: str, r: float, rng: np.random.Generator) -> np.ndarray:
    """Pore (bool) of chamber - duct - chamber along axis 0 inside a solid shell.

    Two cubic chambers of side ``C`` (inscribed radius C/2, well above the duct's) at the ends,
    joined by a straight duct of length ``DUCT_LENGTH`` and the given section, so the duct is the
    one constriction an invasion from the first slice to the last must pass.
    """
    reach = {"square": r * math.sqrt(2.0), "triangle": 2.0 * r, "slit": SLIT_WIDTH / 2.0}.get(shape, r)
    side = int(math.ceil(2 * reach)) + 8
    w = side + 4
    lo = (w - side) // 2
    pore = np.zeros((2 * side + DUCT_LENGTH, w, w), bool)
    pore[:side, lo:lo + side, lo:lo + side] = True
    pore[side + DUCT_LENGTH:, lo:lo + side, lo:lo + side] = True
    pore[side:side + DUCT_LENGTH] = section(shape, r, w, rng)
    return pore


def porefsi_entry(pore: np.ndarray, model: str) -> float:
    """Breakthrough capillary pressure (Pa) of porefsi's network invasion percolation along x."""
    net = extract_network(VoxelImage(pore.astype(np.uint8), voxel_size=VOXEL), conductance=model).network
    ip = invasion_percolation(net, Fluids(sigma=SIGMA), "x")
    return float(ip.capillary_pressure[ip.breakthrough_step])


def porespy_entry(pore: np.ndarray) -> float:
    """Breakthrough capillary pressure (Pa) of PoreSpy's morphological drainage along x."""
    import porespy as ps  # noqa: PLC0415 - peers env only
    from edt import edt  # noqa: PLC0415 - PoreSpy's own dependency

    ps.settings.tqdm["disable"] = True
    dt = edt(pore)
    pc = np.full(pore.shape, np.inf)
    pc[pore] = 2.0 * SIGMA / (dt[pore] * VOXEL)
    inlets = np.zeros_like(pore)
    inlets[0] = pore[0]
    outlets = np.zeros_like(pore)
    outlets[-1] = pore[-1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = ps.simulations.drainage(im=pore, pc=pc, dt=dt, inlets=inlets, outlets=outlets, steps=None)
    reached = res.im_pc[-1][pore[-1]]
    return float(reached.min())


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--offsets", type=int, default=8)
    ap.add_argument("--json")
    ap.add_argument("--shapes", default=",".join(SIZES))
    a = ap.parse_args(argv)
    try:
        import porespy  # noqa: F401, PLC0415
        methods = ("paper", "shape_factor", "porespy")
    except ImportError:
        methods = ("paper", "shape_factor")
    rng = np.random.default_rng(12)
    out: dict = {}
    for shape in a.shapes.split(","):
        for r in SIZES[shape]:
            exact = closed_form(shape, r)
            ratios: dict = {m: [] for m in methods}
            for _ in range(a.offsets):
                pore = duct(shape, r, rng)
                for m in methods:
                    pe = porespy_entry(pore) if m == "porespy" else porefsi_entry(pore, m)
                    ratios[m].append(pe / exact)
            out[f"{shape}_{r:g}"] = {m: v for m, v in ratios.items()}
            cells = "  ".join(f"{m} {np.mean(v):.3f} [{min(v):.2f}, {max(v):.2f}]" for m, v in ratios.items())
            print(f"{shape:8s} r={r:4.1f}  exact {exact:8.0f} Pa  {cells}", flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)
    return out


if __name__ == "__main__":
    main()
