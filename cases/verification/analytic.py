"""The analytic verification set: closed forms and the studies that compare porefsi with them.

Each ``study_*`` function runs porefsi through its public API on a problem with a known answer and
returns plain numbers (and arrays for the figures); ``run.py`` draws them and
``tests/test_cases_verification.py`` checks the closed forms and small versions of the studies.

- Lamé cavity: a pressurised spherical cavity in a clamped elastic cube, both interface operators
  (hull, traction) against the thick-sphere bounds (Timoshenko & Goodier 1970, section 135).
- Washburn: capillary filling of a tube against an inviscid fluid, l^2 = sigma r cos(theta) t / (2 mu)
  (Washburn 1921), and the two-fluid tube at constant overpressure (Poiseuille in series).
- Invasion-percolation limit: at low capillary number the dynamic drainage order equals invasion
  percolation with trapping (Wilkinson & Willemsen 1983).
- TDG order: free undamped oscillator, error at t = 2 s vs dt; slopes 2 (one Nørsett pass) and 3
  (two passes), Newmark average acceleration 2 for comparison.
"""

from __future__ import annotations

import math
import time

import numpy as np


# ---- closed forms ----------------------------------------------------------------------------
def lame_displacement(r, a: float, b: float, P: float, E: float, nu: float):
    """Radial displacement of a thick sphere (inner radius a under pressure P, u(b) = 0), m.

    .. math:: u(r) = B\\,(1/r^2 - r/b^3),\\quad B = P / (3K/b^3 + 4G/a^3)

    with u = A r + B / r^2, A = -B / b^3 (clamped outer surface) and sigma_rr(a) = -P.
    """
    G, K = E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu))
    B = P / (3 * K / b**3 + 4 * G / a**3)
    r = np.asarray(r, float)
    return B * (1 / r**2 - r / b**3)


def lame_work(a: float, b: float, P: float, E: float, nu: float) -> float:
    """Work of the cavity pressure, P * 4 pi a^2 * u(a), J (equals f·u of the discrete solve)."""
    return float(P * 4 * math.pi * a**2 * lame_displacement(a, a, b, P, E, nu))


def washburn_time(length, radius: float, sigma: float, theta_deg: float, mu: float):
    """Lucas-Washburn time to fill ``length`` of a tube against an inviscid fluid, s."""
    c = math.cos(math.radians(theta_deg))
    return 2.0 * mu * np.asarray(length, float) ** 2 / (sigma * radius * c)


def two_fluid_fill_time(l, L: float, r: float, mu_n: float, mu_w: float, dp_eff: float):
    """Time for the front of the non-wetting fluid to reach ``l`` in a tube of length L at constant
    overpressure ``dp_eff`` above the entry pressure (Poiseuille, the two viscous lengths in series), s."""
    l = np.asarray(l, float)
    return 8.0 / (r * r * dp_eff) * (mu_n * l * l / 2 + mu_w * (L * l - l * l / 2))


def fitted_order(dts, errs) -> float:
    """Slope of log(err) against log(dt) (least squares)."""
    return float(np.polyfit(np.log(dts), np.log(errs), 1)[0])


# ---- studies ---------------------------------------------------------------------------------
def study_lame(n_cells=(16, 20, 24), cavity_fraction: float = 0.2, E: float = 20e9, nu: float = 0.28,
               P: float = 1e6, h: float = 1e-6) -> dict:
    """Cavity of radius ``cavity_fraction * N`` voxels in an N^3 clamped cube, N in ``n_cells``.

    Returns per N: the work f·u of the hull and traction loads, the Lamé works of the inscribed
    (b = L) and circumscribed (b = sqrt(3) L) clamped spheres (a larger clamped domain is more
    compliant, so the cube's work lies between them), the load-balance errors and wall times.
    """
    from porefsi import SolidModel, VoxelImage, make_material, mesh_solid, solve_static
    from porefsi.coupling import (
        boundary_facet_normals,
        facet_pores_from_labels,
        hull_interface,
        traction_interface,
    )
    from porefsi.solid import Fixed

    out = {k: [] for k in ("n", "a_m", "lame_inscribed_J", "lame_circumscribed_J", "hull_J", "traction_J",
                           "hull_resultant", "traction_resultant", "n_tets", "seconds")}
    for n in n_cells:
        t0 = time.perf_counter()
        g = np.arange(n) + 0.5
        X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
        rad = cavity_fraction * n
        cav = (X - n / 2) ** 2 + (Y - n / 2) ** 2 + (Z - n / 2) ** 2 < rad**2
        mesh = mesh_solid(VoxelImage(cav.astype(np.uint8), h), coarsen=1, support_axis=None).mesh
        model = SolidModel(mesh, make_material("svk", E=E, nu=nu),
                           [Fixed(f) for f in ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")])
        facets = mesh.facets_tagged("pore_wall")
        normals, _ = boundary_facet_normals(mesh.points, mesh.tets, facets)
        owner = facet_pores_from_labels(mesh.points, facets, normals, np.where(cav, 0, -1), h)
        trac = traction_interface(mesh.points, mesh.tets, facets, owner, 1)
        wall = np.zeros(mesh.n_nodes, bool)
        wall[mesh.nodes_tagged("pore_wall")] = True
        c = np.full((1, 3), n / 2 * h)
        r_in = float(np.min(np.linalg.norm(mesh.points[wall] - c, axis=1)))  # the maximal (inscribed) ball
        hull = hull_interface(c, [r_in], mesh.points, n_test_points=800, tolerance=h,
                              rng=np.random.default_rng(5), candidates=wall)
        works = {}
        for name, itf in (("hull", hull), ("traction", trac)):
            F = itf.nodal_forces([P])
            u, _ = solve_static(model.with_nodal_forces(F), 0.0)
            works[name] = float(np.sum(F * model.expand(u, 0.0)))
            out[f"{name}_resultant"].append(float(np.linalg.norm(F.sum(axis=0)) / np.linalg.norm(F, axis=1).sum()))
        a = (3 * cav.sum() * h**3 / (4 * np.pi)) ** (1 / 3)  # ball of the voxel cavity's volume
        L = n / 2 * h
        out["n"].append(int(n))
        out["a_m"].append(a)
        out["lame_inscribed_J"].append(lame_work(a, L, P, E, nu))
        out["lame_circumscribed_J"].append(lame_work(a, math.sqrt(3) * L, P, E, nu))
        out["hull_J"].append(works["hull"])
        out["traction_J"].append(works["traction"])
        out["n_tets"].append(int(mesh.n_tets))
        out["seconds"].append(time.perf_counter() - t0)
    return out


def study_washburn(n_pores: int = 25, radius: float = 1e-5, length: float = 2e-3) -> dict:
    """Tube filling: porefsi's pore fill times against Washburn and the two-fluid closed form."""
    from porefsi import DrainageSimulator, Fluids, simulate_drainage
    from porefsi.network import tube_network

    net = tube_network(n_pores, radius, length)
    l = (np.arange(n_pores) + 1) * length / n_pores
    # Washburn: inviscid displaced fluid (1e-12 of the invading viscosity), overpressure = 2 sigma cos / r
    fl = Fluids(mu_w=1e-15, mu_n=1e-3, sigma=0.03, theta_deg=30.0)
    pe = float(fl.capillary_pressure(radius))
    sim = DrainageSimulator(net, fl, inlet_pressure=2 * pe)
    sim.advance_to(1.0)
    t_sim = sim.invasion_time()
    t_lw = washburn_time(l, radius, fl.sigma, fl.theta_deg, fl.mu_n)
    # two fluids (paper viscosities) at 3.7 x the entry pressure
    fl2 = Fluids(mu_w=1e-3, mu_n=1e-2, sigma=0.03, theta_deg=0.0)
    pe2 = float(fl2.capillary_pressure(radius))
    dp = 3.7 * pe2
    res = simulate_drainage(net, fl2, inlet_pressure=dp, t_end=10.0, stop_at_breakthrough=True)
    t2 = two_fluid_fill_time(l, length, radius, fl2.mu_n, fl2.mu_w, dp - pe2)
    return {
        "l_m": l, "t_porefsi_s": t_sim, "t_washburn_s": t_lw,
        "max_rel_error_washburn": float(np.max(np.abs(t_sim / t_lw - 1))),
        "t_porefsi_two_fluid_s": np.asarray(res.invasion_time, float), "t_two_fluid_s": t2,
        "max_rel_error_two_fluid": float(np.max(np.abs(np.asarray(res.invasion_time) / t2 - 1))),
    }


def _ca_rate(net, fluids, ca: float, axis: int = 0) -> float:
    """Rate giving Ca = mu_n u / sigma, u the Darcy velocity over the inlet face."""
    area = float(np.prod(np.delete(net.extent, axis)))
    return ca * fluids.sigma * area / fluids.mu_n


def study_ip_limit(cas=(1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3), shape=(8, 8, 4), seeds=(0, 1, 2),
                   spacing: float = 1e-4) -> dict:
    """Dynamic drainage order vs invasion percolation with trapping, before breakthrough.

    For each Ca and random lattice: the fraction of the IP sequence reproduced as an identical prefix
    by the dynamic run, and the fraction of IP-invaded pores the dynamic run also invades by its own
    breakthrough (set overlap, Jaccard).
    """
    from porefsi import DrainageSimulator, Fluids
    from porefsi.flow import invasion_percolation
    from porefsi.network import lattice_network

    fl = Fluids()
    prefix = np.zeros((len(seeds), len(cas)))
    jacc = np.zeros_like(prefix)
    for i, s in enumerate(seeds):
        net = lattice_network(shape, spacing, np.random.default_rng(s))
        ip = invasion_percolation(net, fl, stop_at_breakthrough=True)
        ip_order = np.argsort(np.where(ip.pore_sequence < 0, 2**62, ip.pore_sequence))[: ip.breakthrough_step + 1]
        for j, ca in enumerate(cas):
            sim = DrainageSimulator(net, fl, rate=_ca_rate(net, fl, ca))
            sim.advance_to(1e12, stop_at_breakthrough=True)
            t = sim.invasion_time()
            n_inv = int(np.isfinite(t).sum())
            order = np.argsort(np.where(np.isnan(t), np.inf, t), kind="stable")[:n_inv]
            m = min(len(order), len(ip_order))
            neq = np.flatnonzero(order[:m] != ip_order[:m])
            prefix[i, j] = (neq[0] if neq.size else m) / len(ip_order)
            a, b = set(order.tolist()), set(ip_order.tolist())
            jacc[i, j] = len(a & b) / len(a | b)
    return {"ca": np.asarray(cas, float), "prefix_fraction": prefix, "jaccard": jacc, "shape": list(shape),
            "seeds": list(seeds)}


def study_tdg_order(dts=(0.1, 0.05, 0.025, 0.0125), omega: float = 3.0, t_end: float = 2.0) -> dict:
    """Error of TDG (1 and 2 Nørsett passes) and Newmark on u'' + omega^2 u = 0 at t_end."""
    from collections import deque

    from porefsi.integrators import LinearSystem, NewmarkStepper, TDGStepper, integrate

    sys_ = LinearSystem(np.array([1.0]), np.array([[omega * omega]]))
    u0, v0 = 1.0, 0.5
    ue = math.cos(omega * t_end) + v0 / omega * math.sin(omega * t_end)
    ve = -omega * math.sin(omega * t_end) + v0 * math.cos(omega * t_end)
    errs = {"TDG 1 pass": [], "TDG 2 passes": [], "Newmark (average acceleration)": []}
    for dt in dts:
        steppers = {"TDG 1 pass": TDGStepper(sys_, dt, n_iter=1), "TDG 2 passes": TDGStepper(sys_, dt, n_iter=2),
                    "Newmark (average acceleration)": NewmarkStepper(sys_, dt)}
        for name, st in steppers.items():
            _, u, v = deque(integrate(st, [u0], [v0], 0.0, t_end), maxlen=1)[0]
            errs[name].append(math.hypot(u[0] - ue, (v[0] - ve) / omega))
    return {"dt": np.asarray(dts, float), "errors": {k: np.asarray(v) for k, v in errs.items()},
            "orders": {k: fitted_order(dts, v) for k, v in errs.items()}}
