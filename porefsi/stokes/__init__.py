"""Voxel-scale single-phase Stokes flow on a segmented image: the permeability reference.

Depends only on :mod:`porefsi.image`, :mod:`porefsi.errors` and :mod:`porefsi.units`.
"""

from porefsi.stokes.permeability import StokesResult, plane_fluxes, voxel_permeability
from porefsi.stokes.refine import ExtrapolatedPermeability, Extrapolation, extrapolated_permeability, richardson
from porefsi.units import MILLIDARCY

__all__ = ["voxel_permeability", "StokesResult", "plane_fluxes", "MILLIDARCY", "extrapolated_permeability",
           "ExtrapolatedPermeability", "Extrapolation", "richardson"]
