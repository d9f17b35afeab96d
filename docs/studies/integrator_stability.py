"""Stability study of the time integrators (makes docs/figures/integrators_*.png).

1. Spectral radius vs omega*dt, measured on the implementations (porefsi.integrators.spectral).
2. Energy vs time on a stiff multi-dof system with a rock-like spectrum: a 1-D elastic bar
   (E = 20 GPa, rho = 2650 kg/m^3, 100 P1 elements of 5 um, fixed at x = 0), lumped mass,
   wave speed c = sqrt(E/rho) = 2747 m/s, omega_max ~ 2c/h = 1.1e9 rad/s. Free vibration from a
   rough initial velocity (all modes excited), at time steps from 10x the explicit limit up to a
   coupling-sized 1e-3 s (omega_max*dt ~ 1e6).

Run: python docs/studies/integrator_stability.py   (about 10 s)
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
