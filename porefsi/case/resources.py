"""The memory a coupled run will need, estimated from its image before anything large is built.

:func:`estimate_run` counts what the run will hold without building it: voxels, the mesh's
tetrahedra and nodes (:func:`porefsi.solid.mesh.mesh_size`, on the block grid), the free dofs,
and the linear solver the solid will get (:func:`porefsi.solid.footprint.choose_linear_solver`).
Its peak is a sum of per-entity costs measured on centred crops (120³-400³) of the 400³ Berea
(``benchmarks/bench_coupled_large.py``; docs/benchmarks.md, "The coupled run at 400³"):

* what the whole run holds: the image, its voxel labels and the flow network, per voxel;
* the mesh, the P1 assembler and the tangent, per tetrahedron;
* the larger of the set-up's transients (the extraction's distance map and flood, per voxel)
  and the run's (a sparse LU's factor, or the AMG hierarchy and CG vectors, per dof; the
  checkpoints' copies of the voxel labels, per voxel).

:func:`require_memory` refuses a run whose peak exceeds the memory budget
(:func:`porefsi.solid.footprint.memory_budget`: available memory and ``ulimit -v``) with a
one-line :class:`~porefsi.errors.ConfigError` that says how much it needs and what lowers it.
"""

from __future__ import annotations

import dataclasses

from porefsi.errors import ConfigError
from porefsi.image.voxel_image import VoxelImage
from porefsi.solid.footprint import (
    MEMORY_FLOOR,
    amg_bytes,
    choose_linear_solver,
    format_bytes,
    lu_factor_bytes,
    memory_budget,
)
from porefsi.solid.mesh import mesh_size

__all__ = ["RunEstimate", "estimate_run", "require_memory"]

#: Interpreter, numpy/scipy/numba/pyamg and compiled kernels, bytes (measured RSS before the image).
BASE_BYTES = 0.25 * 2**30
#: Held for the whole run per voxel: the image (uint8), its extraction's int32 labels, the
#: percolating copy (uint8) and the network's voxel-derived arrays.
HELD_BYTES_PER_VOXEL = 7.0
#: Checkpoints and snapshots per voxel: a checkpoint write (and a resumed run's restore) holds
#: copies of the int32 voxel labels next to the run's own (measured: the resumed 400³ run,
#: writing snapshots, checkpoints and figures, peaked 0.72 GiB above the first two steps').
OUTPUT_BYTES_PER_VOXEL = 12.0
#: Transient of the extraction per voxel (distance map, maximal balls, flood queue), measured.
EXTRACT_BYTES_PER_VOXEL = 10.0
#: Held per tetrahedron: mesh, P1 assembler (gradients, CSR pattern), tangent, interface, stress.
BYTES_PER_TET = 1000.0
#: Free dofs per mesh node (the constrained faces take a few percent of the 3 per node).
DOFS_PER_NODE = 2.85


@dataclasses.dataclass(frozen=True)
class RunEstimate:
    """What a coupled run will hold, counted before it is built.

    Attributes
    ----------
    n_voxels, n_tets, n_nodes, n_dofs : int
        Image voxels; tetrahedra, nodes and (estimated) free dofs of the solid mesh.
    linear_solver : str
        The solver the solid will get (``"direct"`` may become ``"amg"``).
    bytes_by_part : dict
        Estimated bytes of ``base``, ``held`` (image, labels, network), ``mesh`` (mesh, model,
        tangent), ``extraction`` (transient), ``solver`` (transient + hierarchy or factor) and
        ``output`` (checkpoint writes and restores).
    coarsen : int
        The mesh's block coarsening (what lowers the solid's part).
    """

    n_voxels: int
    n_tets: int
    n_nodes: int
    n_dofs: int
    linear_solver: str
    bytes_by_part: dict
    coarsen: int

    @property
    def peak_bytes(self) -> float:
        """Estimated peak resident memory of the run, bytes."""
        b = self.bytes_by_part
        return b["base"] + b["held"] + max(b["extraction"], b["mesh"] + b["solver"] + b["output"])

    def describe(self) -> str:
        """The counts and the solver, e.g. ``64,000,000 voxels, 2,063,100 tetrahedra, ~1,510,000 dofs, amg solver``."""
        return (f"{self.n_voxels:,} voxels, {self.n_tets:,} tetrahedra, ~{self.n_dofs:,} dofs, "
                f"{self.linear_solver} solver")


def estimate_run(image: VoxelImage, coarsen: int, linear_solver: str, budget: float | None = None) -> RunEstimate:
    """Estimate the memory of a coupled run on ``image`` meshed at ``coarsen`` (module docstring).

    Parameters
    ----------
    image : VoxelImage
        The (cropped) image of the run.
    coarsen : int
        ``solid.coarsen``.
    linear_solver : str
        ``solid.linear_solver`` as requested.
    budget : float, optional
        Bytes available, for the solver choice (default: :func:`memory_budget`).
    """
    n_vox = int(image.phases.size)
    n_tets, n_nodes = mesh_size(image, coarsen=coarsen)
    n_dofs = int(DOFS_PER_NODE * n_nodes)
    kind = choose_linear_solver(linear_solver, n_dofs, budget).kind
    solver = lu_factor_bytes(n_dofs) if kind == "direct" else amg_bytes(n_dofs)
    parts = {"base": BASE_BYTES, "held": HELD_BYTES_PER_VOXEL * n_vox, "extraction": EXTRACT_BYTES_PER_VOXEL * n_vox,
             "mesh": BYTES_PER_TET * n_tets, "solver": solver, "output": OUTPUT_BYTES_PER_VOXEL * n_vox}
    return RunEstimate(n_vox, n_tets, n_nodes, n_dofs, kind, parts, int(coarsen))


def require_memory(est: RunEstimate, budget: float | None = None) -> None:
    """Refuse a run whose estimated peak exceeds ``budget`` (default :func:`memory_budget`).

    A run estimated below :data:`~porefsi.solid.footprint.MEMORY_FLOOR` (1 GiB) is never refused.

    Raises
    ------
    ConfigError
        One line: the estimate, what is available, and the setting that lowers it
        (``[solid] coarsen``, or ``[image] crop``).
    """
    budget = memory_budget() if budget is None else budget
    if budget is None or est.peak_bytes <= max(budget, MEMORY_FLOOR):
        return
    b = est.bytes_by_part
    if b["mesh"] + b["solver"] + b["output"] >= b["extraction"]:
        fix = (f"raise [solid] coarsen (now {est.coarsen}; the solid's part falls like 1/coarsen^3) or crop the image "
               "([image] crop)")
    else:
        fix = "crop the image ([image] crop) or run on a machine with more memory"
    raise ConfigError(f"this run needs ~{format_bytes(est.peak_bytes)} of memory ({est.describe()}) but "
                      f"{format_bytes(budget)} is available; {fix}")
