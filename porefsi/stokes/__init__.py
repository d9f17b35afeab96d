"""Voxel-scale single-phase Stokes flow on a segmented image: the permeability reference.

Depends only on :mod:`porefsi.image`, :mod:`porefsi.errors` and :mod:`porefsi.units`.
"""

from porefsi.stokes.permeability import StokesOptions, StokesResult, plane_fluxes, stokes_options, voxel_permeability
from porefsi.stokes.refine import ExtrapolatedPermeability, Extrapolation, extrapolated_permeability, richardson
from porefsi.stokes.sampled import (
    SampledBlock,
    SampledExtrapolation,
    choose_blocks,
    extrapolation_mode,
    sampled_permeability,
)
from porefsi.stokes.sampled_resume import resume_sampled_permeability
from porefsi.units import MILLIDARCY

__all__ = ["voxel_permeability", "StokesOptions", "stokes_options", "StokesResult", "plane_fluxes", "MILLIDARCY",
           "extrapolated_permeability",
           "ExtrapolatedPermeability", "Extrapolation", "richardson",
           "sampled_permeability", "SampledExtrapolation", "SampledBlock", "choose_blocks",
           "extrapolation_mode", "resume_sampled_permeability"]
