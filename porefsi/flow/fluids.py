"""The two immiscible, incompressible fluids of a drainage and their wettability."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from porefsi.errors import InputError

__all__ = ["Fluids", "PAPER_FLUIDS"]


@dataclasses.dataclass(frozen=True)
class Fluids:
    r"""Wetting (displaced) and non-wetting (injected) fluid of a primary drainage, SI units.

    Parameters
    ----------
    mu_w : float
        Dynamic viscosity of the wetting fluid, Pa·s, > 0. Default 1e-3 (1 cP, the paper's value).
    mu_n : float
        Dynamic viscosity of the non-wetting (injected) fluid, Pa·s, > 0. Default 1e-2 (10 cP).
    sigma : float
        Interfacial tension, N/m, > 0. Default 0.03 N/m: the paper does not state it; 0.02-0.05 N/m
        is the usual range for refined oil/brine pairs, and 0.03 N/m is what pore-network studies of
        oil/water drainage in Berea commonly use. Every entry pressure scales with it linearly.
    theta_deg : float
        Contact angle measured through the wetting fluid, **degrees**, in [0, 90). Default 0 (the
        paper's value: a perfectly water-wet rock).

    Raises
    ------
    InputError
        Non-finite or non-positive viscosity or tension; a contact angle outside [0, 90) degrees
        (at 90 degrees or more the injected fluid is not the non-wetting one and the process is not
        a drainage).

    Notes
    -----
    Young–Laplace entry pressure of a cylindrical throat of radius r, and the capillary pressure of
    a spherical pore body of radius R being filled:

    .. math:: P_e = \frac{2\sigma\cos\theta}{r}, \qquad P_{c,b} = \frac{2\sigma\cos\theta}{R}.

    Examples
    --------
    >>> f = Fluids()
    >>> round(f.capillary_pressure(1e-6))
    60000
    """

    mu_w: float = 1.0e-3
    mu_n: float = 1.0e-2
    sigma: float = 0.03
    theta_deg: float = 0.0

    def __post_init__(self):
        for name in ("mu_w", "mu_n", "sigma"):
            v = getattr(self, name)
            try:
                x = float(v)
            except (TypeError, ValueError):
                raise InputError(f"Fluids.{name} must be a number, got {v!r}") from None
            if not math.isfinite(x) or x <= 0:
                unit = "N/m" if name == "sigma" else "Pa.s"
                raise InputError(f"Fluids.{name} must be a finite number > 0 {unit}, got {v!r}")
            object.__setattr__(self, name, x)
        th = float(self.theta_deg)
        if not math.isfinite(th) or th < 0 or th >= 90:
            raise InputError(
                f"contact angle {self.theta_deg!r} deg is not a drainage of the wetting fluid: it must be "
                "in [0, 90) degrees (measured through the wetting fluid); swap the fluids or use "
                "theta_deg < 90"
            )
        object.__setattr__(self, "theta_deg", th)

    @property
    def cos_theta(self) -> float:
        """Cosine of the contact angle."""
        return math.cos(math.radians(self.theta_deg))

    @property
    def viscosity_ratio(self) -> float:
        """M = mu_n / mu_w (injected over displaced)."""
        return self.mu_n / self.mu_w

    def capillary_pressure(self, radius):
        """Young–Laplace pressure ``2 sigma cos(theta) / radius``, Pa, for radius in m (array-like)."""
        r = np.asarray(radius, dtype=float)
        return 2.0 * self.sigma * self.cos_theta / r

    def capillary_number(self, rate: float, area: float) -> float:
        """Ca = mu_n u / sigma with the Darcy velocity u = rate / area (m³/s over m²)."""
        return self.mu_n * (float(rate) / float(area)) / self.sigma


#: The paper's fluids: 1 cP wetting, 10 cP non-wetting, theta = 0, sigma = 0.03 N/m (our choice).
PAPER_FLUIDS = Fluids()
