"""The two immiscible, incompressible fluids of a drainage and their wettability."""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np

from porefsi._schema import Limits
from porefsi.errors import InputError
from porefsi.network.geometry import class_shape_factor, shape_class

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

    #: Allowed values of each parameter (the case file's bounds are these).
    LIMITS: ClassVar[dict[str, Limits]] = {"mu_w": Limits(0.0, None, lo_open=True),
                                           "mu_n": Limits(0.0, None, lo_open=True),
                                           "sigma": Limits(0.0, None, lo_open=True),
                                           "theta_deg": Limits(0.0, 90.0, hi_open=True)}

    def __post_init__(self):
        for name in ("mu_w", "mu_n", "sigma"):
            v = getattr(self, name)
            try:
                x = float(v)
            except (TypeError, ValueError):
                raise InputError(f"Fluids.{name} must be a number, got {v!r}") from None
            if not math.isfinite(x) or not self.LIMITS[name].contains(x):
                unit = "N/m" if name == "sigma" else "Pa.s"
                raise InputError(f"Fluids.{name} must be a finite number > 0 {unit}, got {v!r}")
            object.__setattr__(self, name, x)
        th = float(self.theta_deg)
        if not math.isfinite(th) or not self.LIMITS["theta_deg"].contains(th):
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

    def entry_pressure(self, radius, shape_factor=None):
        r"""Piston-like drainage entry pressure of a duct of inscribed radius ``radius``, Pa.

        Without ``shape_factor``: Young–Laplace for a circular tube, ``2 sigma cos(theta) / r``
        (the paper's model). With it: the section class of
        :func:`porefsi.network.geometry.shape_class` and, for triangles (n = 3 corners, the
        measured G) and squares (n = 4, G = 1/16), the Mayer–Stowe–Princen energy balance with
        the wetting fluid left in every corner (Øren, Bakke & Arntzen 1998; Valvatne & Blunt 2004):

        .. math:: P_e = \frac{\sigma\cos\theta}{r}\left(1 + \sqrt{1 + \frac{4 G D}{\cos^2\theta}}\right),
                  \qquad D = \pi - n\theta + n\sin\theta\cos\theta - \frac{\cos^2\theta}{4G};

        circles keep ``2 sigma cos(theta) / r``. At theta = 0 this is
        :math:`\sigma(1 + 2\sqrt{\pi G})/r` for every class (the circle's ``2 sigma / r`` at
        G = 1/(4 pi)). The corner menisci exist while theta < 90° minus the corner half-angle
        (any angle below 45° for squares; for triangles, up to 60° for the equilateral one and less
        for sharp ones): the formula assumes they do, exactly true at the paper's theta = 0.

        Parameters
        ----------
        radius : array_like of float
            Inscribed radius, m, > 0.
        shape_factor : array_like of float, optional
            G = A/P² of the section (broadcast with ``radius``).

        Returns
        -------
        ndarray of float
            Pa.
        """
        r = np.asarray(radius, dtype=float)
        ct = self.cos_theta
        if shape_factor is None:
            return 2.0 * self.sigma * ct / r
        G0 = np.asarray(shape_factor, dtype=float)
        cls = shape_class(G0)
        G = class_shape_factor(G0)
        th = math.radians(self.theta_deg)
        n = np.where(cls == 0, 3.0, 4.0)
        D = np.pi - n * th + n * math.sin(th) * ct - ct * ct / (4.0 * G)
        msp = self.sigma * ct * (1.0 + np.sqrt(np.maximum(1.0 + 4.0 * G * D / (ct * ct), 0.0))) / r
        circle = 2.0 * self.sigma * ct / r
        return np.where(cls == 2, circle, np.where((cls == 1) & (th >= np.pi / 4), circle, msp))

    def capillary_number(self, rate: float, area: float) -> float:
        """Ca = mu_n u / sigma with the Darcy velocity u = rate / area (m³/s over m²)."""
        return self.mu_n * (float(rate) / float(area)) / self.sigma


#: The paper's fluids: 1 cP wetting, 10 cP non-wetting, theta = 0, sigma = 0.03 N/m (our choice).
PAPER_FLUIDS = Fluids()
