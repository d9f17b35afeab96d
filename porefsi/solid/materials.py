"""Hyperelastic materials in total-Lagrangian form: stress and tangent moduli from F.

All functions take the deformation gradient with the 3 x 3 indices first and any trailing
axes (elements, quadrature points): ``F`` of shape (3, 3, ...).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from porefsi._schema import Limits
from porefsi.errors import InputError, MeshError

__all__ = ["Material", "StVenantKirchhoff", "NeoHookean", "make_material", "MATERIALS"]

#: Sandstone grain (quartz) density, kg/m^3.
GRAIN_DENSITY = 2650.0


@dataclasses.dataclass(frozen=True)
class Material:
    """Isotropic hyperelastic material: Young's modulus E (Pa), Poisson ratio nu, density (kg/m^3).

    Raises
    ------
    InputError
        If E <= 0, nu outside (-1, 0.5) or density <= 0.
    """

    E: float = 20e9
    nu: float = 0.28
    density: float = GRAIN_DENSITY

    #: integer code used by the numba kernels
    kind = -1
    name = "material"
    #: Allowed values of each parameter (the case file's bounds are these).
    LIMITS: ClassVar[dict[str, Limits]] = {"E": Limits(0.0, None, lo_open=True),
                                           "nu": Limits(-1.0, 0.5, lo_open=True, hi_open=True),
                                           "density": Limits(0.0, None, lo_open=True)}

    def __post_init__(self):
        E, nu, rho = float(self.E), float(self.nu), float(self.density)
        if not np.isfinite(E) or not self.LIMITS["E"].contains(E):
            raise InputError(f"Young's modulus must be positive (Pa), got E={self.E!r}; rock is ~1e9-1e11 Pa")
        if not np.isfinite(nu) or not self.LIMITS["nu"].contains(nu):
            raise InputError(
                f"Poisson ratio must be in (-1, 0.5), got nu={self.nu!r}; nu >= 0.5 is incompressible "
                "and needs a mixed formulation (sandstone: ~0.1-0.3)"
            )
        if not np.isfinite(rho) or not self.LIMITS["density"].contains(rho):
            raise InputError(f"density must be positive (kg/m^3), got {self.density!r}")
        object.__setattr__(self, "E", E)
        object.__setattr__(self, "nu", nu)
        object.__setattr__(self, "density", rho)

    @property
    def lam(self) -> float:
        """First Lame parameter, Pa: ``E nu / ((1 + nu)(1 - 2 nu))``."""
        return self.E * self.nu / ((1 + self.nu) * (1 - 2 * self.nu))

    @property
    def mu(self) -> float:
        """Shear modulus, Pa: ``E / (2 (1 + nu))``."""
        return self.E / (2 * (1 + self.nu))

    def energy(self, F: np.ndarray) -> np.ndarray:
        """Strain energy density W(F), J/m^3, shape F.shape[2:]."""
        raise NotImplementedError

    def first_pk(self, F: np.ndarray, H: np.ndarray | None = None) -> np.ndarray:
        """First Piola-Kirchhoff stress P = dW/dF, Pa, shape (3, 3, ...).

        ``H`` is the displacement gradient (``F = I + H``), when the caller has it: the stress is
        then formed without ``F^T F - I``-type cancellations, so strains of 1e-7 (pore pressures on
        rock) keep ~15 significant digits instead of ~9.
        """
        raise NotImplementedError

    def moduli(self, F: np.ndarray) -> np.ndarray:
        """First elasticity tensor A_iJkL = d P_iJ / d F_kL, Pa, shape (3, 3, 3, 3, ...)."""
        raise NotImplementedError

    def cauchy(self, F: np.ndarray, H: np.ndarray | None = None) -> np.ndarray:
        """Cauchy stress sigma = P F^T / J, Pa, shape (3, 3, ...) (``H`` as in :meth:`first_pk`)."""
        J = _det(F)
        P = self.first_pk(F, H)
        sigma = np.empty_like(P)
        for i in range(3):
            for k in range(3):
                sigma[i, k] = (P[i, 0] * F[k, 0] + P[i, 1] * F[k, 1] + P[i, 2] * F[k, 2]) / J
        return sigma


def _det(F):
    return (F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1])
            - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
            + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]))


def _eye_like(F):
    return np.eye(3).reshape((3, 3) + (1,) * (F.ndim - 2))


def _grad(F, H):
    """Displacement gradient H = F - I (exact when the caller passes it)."""
    return F - _eye_like(F) if H is None else np.asarray(H)


def _det_minus_one(H):
    """det(I + H) - 1 = tr H + (tr(H)^2 - H:H^T)/2 + det H, without the cancellation of det(F) - 1."""
    tr = np.einsum("ii...->...", H)
    return tr + 0.5 * (tr**2 - np.einsum("ij...,ji...->...", H, H)) + _det(H)


class StVenantKirchhoff(Material):
    r"""St Venant-Kirchhoff: linear S-E law, the paper's material (eq. 2.10-2.12).

    Notes
    -----
    .. math::

        E = \tfrac12 (F^T F - I), \quad S = \lambda\, \mathrm{tr}(E)\, I + 2\mu E, \quad P = F S,

        W = \tfrac{\lambda}{2} (\mathrm{tr}\,E)^2 + \mu\, E:E, \quad
        A_{iJkL} = \delta_{ik} S_{JL} + F_{iM} C_{MJNL} F_{kN},\quad
        C_{MJNL} = \lambda \delta_{MJ}\delta_{NL} + \mu(\delta_{MN}\delta_{JL} + \delta_{ML}\delta_{JN}).

    It is only fit for moderate strains (it softens and loses ellipticity in strong compression);
    strains in rock are ~1e-3, where it is indistinguishable from neo-Hookean.

    References
    ----------
    .. [1] Holzapfel, G. A. (2000). Nonlinear Solid Mechanics, Wiley, sec. 6.5.
    """

    kind = 0
    name = "svk"

    def _green(self, F, H=None):
        H = _grad(F, H)  # E = (H + H^T + H^T H)/2: no cancellation at small strain
        return 0.5 * (H + np.swapaxes(H, 0, 1) + np.einsum("kI...,kJ...->IJ...", H, H))

    def energy(self, F):
        """Strain energy density, J/m^3."""
        E = self._green(F)
        tr = np.einsum("ii...->...", E)
        return 0.5 * self.lam * tr**2 + self.mu * np.einsum("ij...,ij...->...", E, E)

    def second_pk(self, F, H=None):
        """Second Piola-Kirchhoff stress S, Pa, shape (3, 3, ...)."""
        E = self._green(F, H)
        return self.lam * np.einsum("ii...->...", E) * _eye_like(F) + 2 * self.mu * E

    def first_pk(self, F, H=None):
        """First Piola-Kirchhoff stress P = F S, Pa."""
        return np.einsum("iM...,MJ...->iJ...", F, self.second_pk(F, H))

    def moduli(self, F):
        """A_iJkL, Pa."""
        S = self.second_pk(F)
        eye = np.eye(3)
        A = np.einsum("ik,JL...->iJkL...", eye, S)
        FF = np.einsum("iJ...,kL...->iJkL...", F, F)  # F_iJ F_kL
        # lam F_iJ F_kL + mu (F_iL F_kJ + (F F^T)_ik delta_JL)
        A = A + self.lam * FF + self.mu * np.einsum("iLkJ...->iJkL...", FF)
        FFt = np.einsum("iM...,kM...->ik...", F, F)
        A = A + self.mu * np.einsum("ik...,JL->iJkL...", FFt, eye)
        return A


class NeoHookean(Material):
    r"""Compressible neo-Hookean material.

    Notes
    -----
    .. math::

        W = \tfrac{\mu}{2}(\mathrm{tr}\,C - 3) - \mu \ln J + \tfrac{\lambda}{2} (\ln J)^2,\quad
        P = \mu (F - F^{-T}) + \lambda \ln J\, F^{-T},

        A_{iJkL} = \mu\, \delta_{ik}\delta_{JL} + (\mu - \lambda \ln J) F^{-1}_{Jk} F^{-1}_{Li}
                   + \lambda F^{-1}_{Ji} F^{-1}_{Lk}.

    Requires J > 0 everywhere (raises :class:`MeshError` otherwise).

    References
    ----------
    .. [1] Bonet, J. & Wood, R. D. (2008). Nonlinear Continuum Mechanics for Finite Element
       Analysis, 2nd ed., Cambridge, sec. 6.4.3.
    """

    kind = 1
    name = "neo-hookean"

    def _inv(self, F):
        J = _det(F)
        if np.any(J <= 0):
            raise MeshError(
                f"{int(np.count_nonzero(J <= 0))} points have J <= 0 (inverted material); "
                "take a smaller load or time step"
            )
        Fm = np.moveaxis(F, (0, 1), (-2, -1))
        return np.moveaxis(np.linalg.inv(Fm), (-2, -1), (0, 1)), J

    def energy(self, F):
        """Strain energy density, J/m^3."""
        J = _det(F)
        lnJ = np.log(J)
        return 0.5 * self.mu * (np.einsum("ij...,ij...->...", F, F) - 3) - self.mu * lnJ + 0.5 * self.lam * lnJ**2

    def first_pk(self, F, H=None):
        """P, Pa; ``F - F^{-T} = H + (F^{-1} H)^T`` and ``ln J = log1p(det(I + H) - 1)`` avoid cancellation."""
        Fi, J = self._inv(F)
        FiT = np.swapaxes(Fi, 0, 1)
        H = _grad(F, H)
        FiH_T = np.einsum("jM...,Mi...->ij...", Fi, H)  # (F^{-1} H)^T
        return self.mu * (H + FiH_T) + self.lam * np.log1p(_det_minus_one(H)) * FiT

    def moduli(self, F):
        """A_iJkL, Pa."""
        Fi, J = self._inv(F)
        lnJ = np.log(J)
        eye = np.eye(3)
        A = self.mu * np.einsum("ik,JL->iJkL", eye, eye).reshape((3, 3, 3, 3) + (1,) * (F.ndim - 2))
        A = A + (self.mu - self.lam * lnJ) * np.einsum("Jk...,Li...->iJkL...", Fi, Fi)
        A = A + self.lam * np.einsum("Ji...,Lk...->iJkL...", Fi, Fi)
        return A


#: Material names accepted by :func:`make_material` and the CLI.
MATERIALS = {"svk": StVenantKirchhoff, "neo-hookean": NeoHookean}


def make_material(name: str, E: float = 20e9, nu: float = 0.28, density: float = GRAIN_DENSITY) -> Material:
    """Material by name ('svk' or 'neo-hookean'), E in Pa, density in kg/m^3."""
    key = name.lower().replace("_", "-")
    if key in ("neohookean", "neo-hooke"):
        key = "neo-hookean"
    if key not in MATERIALS:
        raise InputError(f"unknown material {name!r}; use one of {sorted(MATERIALS)}")
    return MATERIALS[key](E=E, nu=nu, density=density)
