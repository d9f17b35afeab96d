"""Stability study of the time integrators (makes docs/figures/integrators_*.png).

1. Spectral radius vs omega*dt, measured on the implementations (porefsi.integrators.spectral).
2. Energy vs time on a stiff multi-dof system with a rock-like spectrum: a 1-D elastic bar
   (E = 20 GPa, rho = 2650 kg/m^3, 100 P1 elements of 5 um, fixed at x = 0), lumped mass,
   wave speed c = sqrt(E/rho) = 2747 m/s, omega_max ~ 2c/h = 1.1e9 rad/s. Free vibration from a
   rough initial velocity (all modes excited), at time steps from 10x the explicit limit up to a
   coupling-sized 1e-3 s (omega_max*dt ~ 1e6).
3. The same on the real 3-D rock: the built-in 120^3 Berea sample meshed at coarsen 10 (7,500
   tets), the paper's frame (fixed zmin, platen held at zmax, lateral rollers), P1, lumped mass,
   E = 20 GPa, nu = 0.28, rho = 2650 kg/m^3, linearised at the reference state. The extreme
   eigenvalues of K x = omega^2 M x (scipy eigsh: largest directly, smallest by shift-invert) place
   the mesh's whole spectrum on the omega*dt axis; the amplification of its lowest and highest
   modes is measured by stepping the 3-D system from those mode shapes, and energy vs time is run
   for TDG, Newmark, generalized-alpha and central difference at 0.9 and 1.1 times the explicit
   limit and at a coupling-sized step (omega_max*dt = 1e6).

Run: python docs/studies/integrator_stability.py   (1-1.5 min on 2 shared cores)
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import scipy.sparse as sp

os.environ.setdefault("MPLBACKEND", "Agg")
import matplotlib.pyplot as plt  # noqa: E402

from porefsi.errors import InputError  # noqa: E402
from porefsi.integrators import (  # noqa: E402
    CentralDifferenceStepper,
    GeneralizedAlphaStepper,
    LinearSystem,
    NewmarkStepper,
    TDGExactStepper,
    TDGStepper,
    critical_time_step,
    max_frequency,
    spectral_radius,
)

FIG = Path(__file__).resolve().parents[1] / "figures"

#: Rock study: coarsening of the built-in sample (10 -> 7,500 tets, 4,990 free dofs; seconds to run).
ROCK_COARSEN = 10
#: Grain properties: the paper's E and nu, quartz grain density.
ROCK_E, ROCK_NU, ROCK_RHO = 20e9, 0.28, 2650.0
#: Steps as fractions of the explicit limit 2 / omega_max: just stable, just unstable.
CD_FRACTIONS = (0.9, 1.1)
#: Coupling-sized step: omega_max dt = 1e6 (the issue's upper end; the default exchange step of 1 s
#: is larger still).
COUPLING_OMEGA_DT = 1e6
#: Steps per energy run.
N_STEPS = 40
#: Energy ratio below which a run counts as annihilated (30 orders of magnitude down).
ENERGY_FLOOR = 1e-30
#: The four methods of the rock study: label, spectral scheme name, options, colour.
ROCK_METHODS = [
    ("TDG, 2 passes", "tdg", {}, "C0"),
    ("Newmark avg. acc.", "newmark", {}, "C1"),
    (r"gen.-$\alpha$ $\rho_\infty$=0.5", "generalized_alpha", {"rho_inf": 0.5}, "C2"),
    ("central difference", "central_difference", {}, "C3"),
]


def spectral_figure():
    """Spectral radius vs omega*dt of every scheme -> integrators_spectral_radius.png."""
    w = np.logspace(-3, 6, 181)
    curves = [
        ("TDG, 2 passes (porefsi)", "tdg", {"n_iter": 2}, "C0", "-"),
        ("TDG, 1 pass (SDIRK2)", "tdg", {"n_iter": 1}, "C0", "--"),
        ("exact TDG (1,2)-Pade", "tdg_exact", {}, "k", ":"),
        ("Newmark avg. acceleration", "newmark", {}, "C1", "-"),
        (r"generalized-$\alpha$, $\rho_\infty=0.5$", "generalized_alpha", {"rho_inf": 0.5}, "C2", "-"),
        ("central difference", "central_difference", {}, "C3", "-"),
    ]
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    out = {}
    for label, scheme, opts, col, ls in curves:
        ww = w[w <= 1e3] if scheme == "central_difference" else w
        rho = spectral_radius(scheme, ww, **opts)
        out[label] = (ww, rho)
        ax.loglog(ww, rho, color=col, ls=ls, label=label)
    ax.axhline(1.0, color="0.6", lw=0.8)
    ax.axvline(2.0, color="C3", lw=0.6, ls=":")
    ax.set_ylim(1e-7, 1e3)
    ax.set_xlabel(r"$\omega\,\Delta t$")
    ax.set_ylabel(r"spectral radius $\rho$")
    ax.set_title("Spectral radius of the amplification matrix (measured on the code)")
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(FIG / "integrators_spectral_radius.png", dpi=130)
    plt.close(fig)
    return out


def bar_system(n_el=100, h=5e-6, E=20e9, rho=2650.0, area=1.0):
    """P1 bar fixed at x=0 (node 0 removed), lumped mass; returns M (n,), K (n, n) sparse."""
    n = n_el
    k = E * area / h
    main = np.full(n, 2 * k)
    main[-1] = k
    K = sp.diags([main, -k * np.ones(n - 1), -k * np.ones(n - 1)], [0, 1, -1]).tocsr()
    m = rho * area * h
    M = np.full(n, m)
    M[-1] = 0.5 * m
    return M, K


def energy(M, K, u, v):
    """Total energy v.Mv/2 + u.Ku/2, J."""
    return 0.5 * float(v @ (M * v)) + 0.5 * float(u @ (K @ u))


def modal_energies(M, K, u, v, Phi, w):
    """Energy per eigenmode (Phi M-orthonormal): 0.5 (qdot^2 + w^2 q^2)."""
    q, p = Phi.T @ (M * u), Phi.T @ (M * v)
    return 0.5 * (p * p + (w * q) ** 2)


def energy_figure():
    """Modal energy vs step on the stiff bar -> integrators_energy_bar.png."""
    M, K = bar_system()
    sys = LinearSystem(M, K)
    wmax = max_frequency(sys)
    dtc = critical_time_step(sys)
    d = 1 / np.sqrt(M)
    lam, Q = np.linalg.eigh(d[:, None] * K.toarray() * d[None, :])
    w, Phi = np.sqrt(lam), d[:, None] * Q
    rng = np.random.default_rng(7)
    x = np.arange(1, 101) / 100.0
    u0 = 1e-10 * np.sin(0.5 * math.pi * x)  # smooth, resolved fundamental
    v0 = 2e-3 * rng.standard_normal(100)  # rough: excites the whole spectrum
    cases = [
        (1e-8, "resolved modes ($\\omega\\Delta t<1$)", lambda dt: w * dt < 1),
        (1e-8, "unresolved modes ($\\omega\\Delta t\\geq 1$)", lambda dt: w * dt >= 1),
        (1e-3, "all modes (all unresolved)", lambda dt: np.ones_like(w, bool)),
    ]
    methods = [
        ("TDG, 2 passes", lambda d: TDGStepper(sys, d), "C0"),
        ("exact TDG", lambda d: TDGExactStepper(sys, d), "k"),
        ("Newmark avg. acc.", lambda d: NewmarkStepper(sys, d), "C1"),
        (r"gen.-$\alpha$ $\rho_\infty$=0.5", lambda d: GeneralizedAlphaStepper(sys, d, rho_inf=0.5), "C2"),
        ("central difference", lambda d: CentralDifferenceStepper(sys, d), "C3"),
    ]
    n_steps = 40
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.4), sharey=True)
    summary = {}
    for ax, (dt, title, select) in zip(axes, cases, strict=True):
        sel = select(dt)
        E0 = modal_energies(M, K, u0, v0, Phi, w)[sel].sum()
        for label, make, col in methods:
            st = make(dt)
            u, v, Es = u0.copy(), v0.copy(), [1.0]
            for k in range(n_steps):
                try:
                    with np.errstate(over="ignore", invalid="ignore"):
                        u, v, _ = st.step(u, v, k * dt)
                        e = modal_energies(M, K, u, v, Phi, w)[sel].sum() / E0
                except InputError:
                    break
                if not np.isfinite(e) or e > 1e200:
                    break
                Es.append(max(e, 1e-300))
            done = len(Es) == n_steps + 1
            summary[(label, dt, title)] = Es[-1] if done else f"blew up at step {len(Es)}"
            ax.semilogy(np.arange(len(Es)), Es, color=col, marker=".", ms=3, label=label)
        ax.set_title(f"{title}\n$\\Delta t$={dt:.0e} s, $\\omega_{{max}}\\Delta t$={wmax * dt:.1e}", fontsize=9)
        ax.set_xlabel("step")
        ax.axhline(1.0, color="0.6", lw=0.8)
    axes[0].set_ylabel("modal energy / initial")
    axes[0].set_ylim(1e-30, 1e60)
    axes[2].legend(fontsize=8, loc="upper right")
    fig.suptitle(
        f"Elastic bar, 100 x 5 um P1, E=20 GPa, rho=2650 kg/m3: omega_max={wmax:.2e} rad/s, "
        f"explicit limit {dtc:.2e} s", fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(FIG / "integrators_energy_bar.png", dpi=130)
    plt.close(fig)
    return wmax, dtc, summary


def rock_system(coarsen: int = ROCK_COARSEN):
    """Linearised rock frame: (mesh, lumped M (n,), K (n, n) CSR) on the free dofs of the paper's BCs."""
    from porefsi.image import load_sample
    from porefsi.solid import StVenantKirchhoff, mesh_solid, uniaxial_bcs
    from porefsi.solid.model import SolidModel

    mesh = mesh_solid(load_sample(), coarsen=coarsen).mesh
    model = SolidModel(mesh, StVenantKirchhoff(ROCK_E, ROCK_NU, ROCK_RHO), uniaxial_bcs("z"))
    return mesh, model.mass(), model.tangent(np.zeros(model.n_dofs), 0.0).tocsr()


def extreme_modes(M, K):
    """Lowest and highest (omega (rad/s), M-orthonormal mode (n,)) of K x = omega^2 M x (lumped M)."""
    import scipy.sparse.linalg as spla

    d = 1.0 / np.sqrt(M)
    S = (sp.diags(d) @ K @ sp.diags(d)).tocsc()
    lmax, vmax = spla.eigsh(S, k=1, which="LA")
    lmin, vmin = spla.eigsh(S, k=1, sigma=0.0, which="LM")  # shift-invert about 0: the lowest mode
    return (math.sqrt(lmin[0]), d * vmin[:, 0]), (math.sqrt(lmax[0]), d * vmax[:, 0])


def _stepper(scheme, system, dt, opts):
    from porefsi.integrators.spectral import SCHEMES

    return SCHEMES[scheme][0](system, dt, **opts)


def modal_spectral_radius(scheme, system, M, phi, dt, opts):
    """Spectral radius of one step of ``scheme`` on mode ``phi`` of the 3-D system, measured.

    :func:`porefsi.integrators.spectral.modal_amplification_matrix`, projected with the lumped M.
    """
    from porefsi.integrators.spectral import modal_amplification_matrix

    A = modal_amplification_matrix(scheme, system, dt, phi, M, **opts)
    return float(np.max(np.abs(np.linalg.eigvals(A))))


def rock_study():
    """Spectral radius on the rock's spectrum and energy vs time -> integrators_*_rock.png."""
    mesh, M, K = rock_system()
    sys_ = LinearSystem(M, K)
    (w_lo, phi_lo), (w_hi, phi_hi) = extreme_modes(M, K)
    dt_cr = 2.0 / w_hi
    dts = [f * dt_cr for f in CD_FRACTIONS] + [COUPLING_OMEGA_DT / w_hi]
    names = [f"{f:g} x explicit limit" for f in CD_FRACTIONS] + ["coupling-sized"]
    measured = {}
    for label, scheme, opts, _ in ROCK_METHODS:
        for dt in dts:
            for which, w, phi in (("lowest", w_lo, phi_lo), ("highest", w_hi, phi_hi)):
                rho3d = modal_spectral_radius(scheme, sys_, M, phi, dt, opts)
                rho1 = float(spectral_radius(scheme, w * dt, **opts))
                measured[(label, dt, which)] = (w * dt, rho3d, rho1)

    # --- spectral radius with the rock's spectrum marked
    wdt = np.logspace(-2, 6.3, 167)
    fig, ax = plt.subplots(figsize=(8, 5))
    for label, scheme, opts, col in ROCK_METHODS:
        ax.loglog(wdt, spectral_radius(scheme, wdt, **opts), color=col, label=label + " (1 dof)")
        for dt in dts:
            for which, mk in (("lowest", "o"), ("highest", "s")):
                x, r3, _ = measured[(label, dt, which)]
                ax.loglog([x], [r3], mk, color=col, mfc="none", ms=7)
    label_heights = (1e11, 1e8, 1e11)  # staggered: the two near-critical bands overlap
    for dt, name, shade, y in zip(dts, names, ("0.85", "0.75", "0.65"), label_heights, strict=True):
        ax.axvspan(w_lo * dt, w_hi * dt, color=shade, alpha=0.35, lw=0)
        ax.text(math.sqrt(w_lo * w_hi) * dt, y, rf"rock, $\Delta t$ = {dt:.2g} s" + f"\n({name})",
                ha="center", fontsize=7)
    ax.axhline(1.0, color="0.5", lw=0.8)
    ax.plot([], [], "ko", mfc="none", label="3-D rock, lowest mode (measured)")
    ax.plot([], [], "ks", mfc="none", label="3-D rock, highest mode (measured)")
    ax.set_ylim(1e-10, 1e13)
    ax.set_xlabel(r"$\omega\,\Delta t$")
    ax.set_ylabel(r"spectral radius $\rho$")
    ax.set_title(rf"Rock mesh (coarsen {ROCK_COARSEN}, {mesh.n_tets} tets): $\omega$ = {w_lo:.3g} to {w_hi:.3g} rad/s "
                 "(grey bands)", fontsize=9)
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(FIG / "integrators_spectral_radius_rock.png", dpi=130)
    plt.close(fig)

    # --- energy vs time from the lowest mode plus a rough velocity (every mode excited)
    rng = np.random.default_rng(7)
    u0 = 1e-9 * phi_lo / np.abs(phi_lo).max()  # m: the lowest mode, resolved at the small steps
    e_mode = 0.5 * w_lo**2 * float(phi_lo @ (M * u0)) ** 2
    v0 = rng.standard_normal(len(M))
    v0 *= math.sqrt(2 * e_mode / float(v0 @ (M * v0)))  # as much kinetic energy as the mode has
    E0 = energy(M, K, u0, v0)
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.4))
    energies = {}
    for ax, dt, name in zip(axes, dts, names, strict=True):
        for label, scheme, opts, col in ROCK_METHODS:
            st = _stepper(scheme, sys_, dt, opts)
            u, v, Es = u0.copy(), v0.copy(), [1.0]
            for k in range(N_STEPS):
                with np.errstate(over="ignore", invalid="ignore"):
                    u, v, _ = st.step(u, v, k * dt)
                    e = energy(M, K, u, v) / E0
                if not np.isfinite(e) or e > 1e200:
                    break
                Es.append(max(e, 1e-300))
            done = len(Es) == N_STEPS + 1
            below = [k for k, e in enumerate(Es) if e < ENERGY_FLOOR]
            energies[(label, dt)] = ((Es[-1] if done else f"overflow at step {len(Es)}"),
                                     below[0] if below else None)
            ax.semilogy(dt * np.arange(len(Es)), Es, color=col, marker=".", ms=3, label=label)
        ax.set_title(rf"{name}: $\Delta t$ = {dt:.3g} s" + "\n"
                     + rf"$\omega\Delta t$ = {w_lo * dt:.3g} to {w_hi * dt:.3g}", fontsize=9)
        ax.set_xlabel("time (s)")
        ax.axhline(1.0, color="0.6", lw=0.8)
    axes[0].set_ylabel("energy / initial")
    axes[2].set_ylim(ENERGY_FLOOR, 1e60)
    axes[2].legend(fontsize=8, loc="upper right")
    fig.suptitle(f"3-D rock, Berea sample at coarsen {ROCK_COARSEN} ({mesh.n_tets} tets, {len(M)} dofs), "
                 f"E = 20 GPa: explicit limit {dt_cr:.3g} s", fontsize=10)
    fig.tight_layout()
    fig.savefig(FIG / "integrators_energy_rock.png", dpi=130)
    plt.close(fig)
    return dict(mesh=mesh, n_dofs=len(M), w_lo=w_lo, w_hi=w_hi, dt_cr=dt_cr, dts=dts, names=names,
                measured=measured, energies=energies)


if __name__ == "__main__":
    FIG.mkdir(parents=True, exist_ok=True)
    curves = spectral_figure()
    for label, (w, rho) in curves.items():
        sel = [np.argmin(abs(w - x)) for x in (1.0, 10.0, 100.0)]
        print(f"{label:40s} rho(1, 10, 100) = " + ", ".join(f"{rho[i]:.4g}" for i in sel))
    wmax, dtc, summary = energy_figure()
    print(f"bar: omega_max = {wmax:.4e} rad/s, critical step = {dtc:.4e} s")
    for (label, dt, title), e in summary.items():
        val = e if isinstance(e, str) else f"{e:.3e}"
        print(f"  dt={dt:.0e} {title[:22]:22s} {label:28s} E_end/E0 = {val}")
    rock = rock_study()
    print(f"rock: {rock['mesh'].n_tets} tets, {rock['n_dofs']} dofs, omega {rock['w_lo']:.4e} to "
          f"{rock['w_hi']:.4e} rad/s, explicit limit {rock['dt_cr']:.4e} s")
    for (label, dt, which), (x, r3, r1) in rock["measured"].items():
        print(f"  dt={dt:.3e} {label:28s} {which:7s} omega dt={x:.3e}  rho 3-D {r3:.4g}  1-dof {r1:.4g}")
    dev = max(abs(r3 / r1 - 1) for _, r3, r1 in rock["measured"].values())
    print(f"  largest relative difference 3-D mode vs 1-dof: {dev:.2e}")
    for (label, dt), (e, k) in rock["energies"].items():
        val = e if isinstance(e, str) else f"{e:.3e}"
        dead = "" if k is None else f" (below {ENERGY_FLOOR:g} from step {k})"
        print(f"  dt={dt:.3e} {label:28s} E_end/E0 = {val}{dead}")
