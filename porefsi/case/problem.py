"""A case as the coupling's inputs: its image read and cropped, its sections as option objects.

:func:`coupled_options` is the one place where the case file's choices (``interface.method``)
become objects (:class:`~porefsi.coupling.options.HullOptions` or
:class:`~porefsi.coupling.options.TractionOptions`); :func:`problem_from_case` reads the image and
calls :func:`porefsi.coupling.problem.build_problem`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from porefsi.case.config import Case
from porefsi.case.resources import estimate_run, require_memory
from porefsi.coupling import CoupledOptions, CoupledProblem, HullOptions, StageClock, TractionOptions, build_problem
from porefsi.errors import ConfigError, InputError
from porefsi.flow.fluids import Fluids
from porefsi.image.io import load_sample, read_image
from porefsi.image.ops import crop
from porefsi.image.voxel_image import VoxelImage

__all__ = ["problem_from_case", "coupled_options", "interface_options", "load_case_image"]


def load_case_image(case: Case) -> VoxelImage:
    """Read (or load the built-in sample), segment and crop the case's image.

    Raises
    ------
    InputError
        ``image.path`` does not exist (or the file cannot be read).
    ConfigError
        ``image.crop`` reaches beyond the image.
    """
    ic = case.image
    if ic.path:
        if not Path(ic.path).exists():
            raise InputError(f"image.path {ic.path!r} does not exist; fix the path in the case file "
                             "or leave it empty for the built-in sample")
        img = read_image(ic.path, voxel_size=ic.voxel_size, threshold=ic.threshold, pore_value=ic.pore_value,
                         invert=ic.invert)
    else:
        img = load_sample()
        if ic.voxel_size is not None:
            img = VoxelImage(img.phases, ic.voxel_size, img.origin)
    if ic.crop:
        over = [f"{ax}: stop {c[1]} > {n}" for ax, c, n in zip("xyz", ic.crop, img.shape, strict=True) if c[1] > n]
        if over:
            raise ConfigError(f"image.crop {ic.crop!r} reaches beyond the image ({img.shape[0]} x {img.shape[1]} x "
                              f"{img.shape[2]} voxels; {', '.join(over)}); keep each stop <= the image size")
        img = crop(img, [c[0] for c in ic.crop], [c[1] for c in ic.crop])
    return img


def interface_options(case: Case) -> HullOptions | TractionOptions:
    """The builder of the case's interface (``interface.method``)."""
    ic = case.interface
    if ic.method == "hull":
        return HullOptions(n_test_points=ic.n_test_points, tolerance=ic.tolerance, seed=ic.seed,
                           throat_forces=ic.throat_forces)
    # a coarsened mesh's wall facets sit up to a block (coarsen voxels) from the pore voxels; a graded mesh
    # refined near the invaded pores only has walls of its coarsest leaves elsewhere
    sc = case.solid
    block = sc.coarsen_max if sc.mesh == "graded" and sc.refine == "invaded" else sc.coarsen
    return TractionOptions(max_steps=max(4, 2 * max(block, sc.coarsen)))


def coupled_options(case: Case) -> CoupledOptions:
    """The case's sections as the coupling's option objects."""
    return CoupledOptions(axis=case.image.axis, fluids=Fluids(**dataclasses.asdict(case.fluids)),
                          drainage=case.drainage, solid=case.solid, interface=interface_options(case),
                          network=case.network, coupling=case.coupling)


def problem_from_case(case: Case) -> CoupledProblem:
    """Read the case's image and build its coupled problem (network, mesh, solid model, interface).

    The set-up times (:attr:`CoupledProblem.seconds`) start with the image's (``image``).

    Raises
    ------
    ConfigError
        The run's estimated memory (:func:`porefsi.case.resources.estimate_run`) exceeds what the
        machine has; the message says how much it needs and which setting lowers it.
    """
    clock = StageClock()
    with clock("image"):
        img = load_case_image(case)
    # refuse before anything large is built: a run the machine cannot hold stops here, in one line
    require_memory(estimate_run(img, case.solid.coarsen, case.solid.linear_solver))
    problem = build_problem(img, coupled_options(case))
    return dataclasses.replace(problem, seconds=clock.wall | problem.seconds,
                               cpu_seconds=clock.cpu | problem.cpu_seconds)
