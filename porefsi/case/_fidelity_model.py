"""The error and cost model behind ``fidelity = "auto"`` (private; :mod:`porefsi.case.fidelity`).

Everything here is read off the image and the case before a run (:class:`Scene`) and combined
with constants measured on the built-in sample (``fidelity_calibration.json``, shipped with the
package; the data and the fits are in docs/fidelity.md).

Error (relative L2 of the nodal displacement over the run, the speed-accuracy study's measure):

- mesh: ``E_mesh(c) = A (c / lambda)^p``, ``c`` the coarsening, ``lambda`` the mean pore chord of
  the image in voxels (the length a block of ``c`` voxels must resolve); against the study's
  reference (coarsen ``c_ref`` = 3) the expected value is ``sqrt(E_mesh(c)^2 + E_mesh(c_ref)^2)``
  (the two meshes' errors are not aligned: the block geometry changes with ``c``);
- interface: 0 for the consistent traction (the reference's), a constant model error for the hull;
- integrator: 0 static or TDG with the right load rule (quasi-static solid), a constant for the
  left rule;
- network update, solid response: a constant times the expected strain (capillary entry pressure
  of the mean pore over Young's modulus);
- drainage scheme: the adaptive scheme's measured difference from the exact one, interpolated in
  log10 Ca;
- combined conservatively: the sum of the terms (aligned errors, the triangle inequality's worst).

Cost (CPU seconds, one thread): extraction per voxel, meshing and interface per tetrahedron
(hull: per pore and test point), the solid's factorisation as a quadratic in log dofs (direct LU)
or per dof and step (AMG-CG above the direct limit), per step its back-substitution, the stress per
tetrahedron, the network update per pore, the drainage per step and per event x pore; TDG
and the linear response as measured factors on the solid stage, the adaptive scheme as the
measured ratio on the drainage (interpolated in log10 Ca) plus its measured extra set-up.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
from importlib import resources

import numpy as np

from porefsi.flow.fluids import Fluids
from porefsi.solid.footprint import DIRECT_MAX_DOFS
from porefsi.solid.mesh import MIN_BLOCKS, MIN_PORE_KEPT, mesh_size

__all__ = ["Scene", "Setting", "scene_of", "calibration", "expected_error", "expected_cpu", "cpu_parts", "pore_chord",
           "graded_size"]

CALIBRATION_FILE = "fidelity_calibration.json"
#: Coarsenings ``auto`` considers; of them those whose blocks tile the image (every size a multiple),
#: as in the calibration, unless fewer than two do.
COARSENINGS = tuple(range(2, 17))


@functools.cache
def calibration() -> dict:
    """The shipped calibration constants (``porefsi/case/fidelity_calibration.json``)."""
    return json.loads(resources.files("porefsi.case").joinpath(CALIBRATION_FILE).read_text(encoding="utf-8"))


@dataclasses.dataclass(frozen=True)
class Setting:
    """One combination of the fidelity knobs, as the model sees it."""

    coarsen: int
    interface: str = "traction"
    n_test_points: int = 800
    integrator: str = "static"
    tdg_iterations: int = 2
    load_rule: str = "right"
    update: str = "geometric"
    scheme: str = "exact"
    response: str = "nonlinear"
    order: int = 1
    mesh: str = "uniform"
    coarsen_max: int = 16
    grading: float = 1.0
    refine: str = "walls"
    ligaments: float = 0.0


@dataclasses.dataclass(frozen=True)
class Scene:
    """What the image and the case tell before a run.

    Attributes
    ----------
    shape : tuple of int
        Image voxels per axis.
    n_voxels, n_pore_voxels : int
    pore_chord : float
        Mean pore chord (voxels, over the three axes).
    voxel_size : float
        m.
    n_steps : int
        Exchange steps of the run.
    capillary_number : float
        ``mu_n Q / (A sigma)``, A the inlet face.
    strain : float
        Expected strain: the entry pressure of the mean pore over Young's modulus.
    n_pores : float
        Expected pores of the extraction.
    n_events : float
        Expected fills over the horizon (injected volume over the mean pore volume, at most n_pores).
    mesh : dict
        coarsening -> (n_tets, n_dofs, porosity kept, peak bytes, auto may choose it).
    memory_bytes : float
        The machine's physical memory (candidates above it are infeasible).
    injected_voxels : float
        Twice the injected volume in voxels (``2 rate t_end / h^3``): the pore volume a graded
        mesh refined at the predicted invasion keeps fine.
    """

    shape: tuple
    n_voxels: int
    n_pore_voxels: int
    pore_chord: float
    voxel_size: float
    n_steps: int
    capillary_number: float
    strain: float
    n_pores: float
    n_events: float
    mesh: dict
    memory_bytes: float = math.inf
    injected_voxels: float = 0.0

    def feasible(self, coarsen: int) -> bool:
        """Whether ``auto`` may choose ``coarsen`` (meshable, tiling the image, fitting in memory)."""
        return coarsen in self.mesh and self.mesh[coarsen][4] and self.mesh[coarsen][3] <= self.memory_bytes


def pore_chord(phases: np.ndarray) -> float:
    """Mean length (voxels) of the runs of pore voxels along the three axes (1 = pore)."""
    pore = phases == 1
    runs = 0
    for ax in range(3):
        m = np.moveaxis(pore, ax, 0).astype(np.int8)
        runs += int(np.count_nonzero(np.diff(m, axis=0, prepend=0) == 1))
    return 3.0 * float(np.count_nonzero(pore)) / runs if runs else 0.0


def _mesh_table(image, extra=()) -> dict:
    """Coarsening -> (n_tets, n_dofs, porosity kept, peak bytes, auto may choose it).

    ``auto`` may choose a coarsening the mesher accepts (enough blocks, enough porosity kept) whose
    blocks tile the image (every size a multiple, as in the calibration; any size if fewer than two
    tile it); ``extra`` coarsenings (a case's own, the presets') are sized too.
    """
    from porefsi.case.resources import estimate_run

    phi = float(np.count_nonzero(image.phases == 1)) / image.phases.size
    tiling = [c for c in COARSENINGS if all(n % c == 0 for n in image.shape)]
    allowed = set(tiling if len(tiling) >= 2 else COARSENINGS)
    out = {}
    for c in sorted(set(COARSENINGS) | {int(x) for x in extra}):
        if min(image.shape) // c < MIN_BLOCKS and c not in extra:
            continue
        n_tets, _ = mesh_size(image, coarsen=c)
        blocks = math.prod(-(-n // c) for n in image.shape)
        kept = 1.0 - n_tets / 5.0 / blocks
        ok = c in allowed and min(image.shape) // c >= MIN_BLOCKS and kept >= MIN_PORE_KEPT * phi and n_tets > 0
        est = estimate_run(image, c, "direct", budget=_physical_memory())
        out[c] = (est.n_tets, est.n_dofs, kept, est.peak_bytes, ok)
    return out


def _physical_memory() -> float:
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return math.inf


def scene_of(image, case, cal: dict | None = None, extra_coarsen=()) -> Scene:
    """The :class:`Scene` of ``case`` on its (cropped) ``image`` (``extra_coarsen``: also size these meshes)."""
    cal = calibration() if cal is None else cal
    vs = float(image.voxel_size)
    n_pore = int(np.count_nonzero(image.phases == 1))
    lam = pore_chord(image.phases)
    ax = "xyz".index(case.image.axis)
    face = math.prod(n for i, n in enumerate(image.shape) if i != ax) * vs * vs
    fl = Fluids(mu_w=case.fluids.mu_w, mu_n=case.fluids.mu_n, sigma=case.fluids.sigma, theta_deg=case.fluids.theta_deg)
    radius = max(lam, 1.0) * vs / 2.0
    entry = 2.0 * fl.sigma * math.cos(math.radians(fl.theta_deg)) / radius
    n_pores = max(n_pore / (cal["cost"]["pore_voxels_per_chord3"] * max(lam, 1.0) ** 3), 1.0)
    pore_vol = n_pore * vs ** 3 / n_pores
    n_events = min(n_pores, case.drainage.rate * case.drainage.t_end / pore_vol)
    n_steps = max(1, math.ceil(case.drainage.t_end / case.coupling.exchange_dt - 1e-9))
    return Scene(tuple(int(n) for n in image.shape), int(image.phases.size), n_pore, lam, vs, n_steps,
                 fl.capillary_number(case.drainage.rate, face), entry / case.solid.E, n_pores, n_events,
                 _mesh_table(image, (case.solid.coarsen, *extra_coarsen)), _physical_memory(),
                 min(2.0 * case.drainage.rate * case.drainage.t_end / vs ** 3, float(n_pore)))


def _mesh_error(scene: Scene, coarsen: int, cal: dict) -> float:
    m = cal["mesh"]
    return m["A"] * (coarsen / max(scene.pore_chord, 1.0)) ** m["p"]


def _interp_log_ca(scene: Scene, table: dict, key: str) -> float:
    x = math.log10(max(scene.capillary_number, 1e-30))
    return float(np.interp(x, table["log10_ca"], table[key]))


def expected_error(scene: Scene, s: Setting, cal: dict | None = None, *, vs_reference: bool = False) -> float:
    """Expected relative L2 displacement error of setting ``s`` on ``scene`` (module docstring).

    ``vs_reference``: against the study's reference (coarsen ``mesh.reference_coarsen``, traction)
    instead of a converged mesh.
    """
    cal = calibration() if cal is None else cal
    e = _mesh_error(scene, s.coarsen, cal)
    own = 0.0  # the graded mesh's own term: its coarse leaves away from the load
    if _graded(s):
        own = cal.get("graded", {}).get("error", 0.0)
    e += cal["interface"][s.interface]
    if s.integrator == "tdg" and s.load_rule == "left":
        e += cal["integrator"]["tdg_left"]
    e += cal["update"][s.update] * scene.strain
    e += cal["response"][s.response] * scene.strain
    if s.scheme == "adaptive":
        e += _interp_log_ca(scene, cal["scheme"]["adaptive"], "error")
    if vs_reference:
        c_ref = cal["mesh"]["reference_coarsen"]
        if _graded(s) and s.coarsen == c_ref:  # its fine blocks are the reference's own mesh there
            return float(e - _mesh_error(scene, s.coarsen, cal) + own)
        e = math.hypot(e, _mesh_error(scene, c_ref, cal))
    return float(e + own)


def _graded(s: Setting) -> bool:
    """Whether ``s`` is a graded mesh refined at the predicted invasion.

    Refined at every wall it is the uniform mesh of its fine block to within a percent of the
    nodes (docs/solid.md), and modelled as that.
    """
    return s.mesh == "graded" and s.refine == "invaded"


def graded_size(scene: Scene, s: Setting, cal: dict | None = None) -> tuple[float, float]:
    """Expected (n_tets, n_dofs) of a graded mesh: its coarsest leaves everywhere plus the fine region.

    The fine region grows with the pore volume it resolves (``scene.injected_voxels``): tetrahedra
    = the uniform mesh of ``coarsen_max`` + ``kappa * injected_voxels / coarsen^3`` (``kappa``
    measured on the calibration's graded run), at most the uniform mesh of ``coarsen``; dofs in
    the uniform mesh's proportion.
    """
    cal = calibration() if cal is None else cal
    n_tets, n_dofs = scene.mesh[s.coarsen][:2]
    if not _graded(s) or "graded" not in cal:
        return float(n_tets), float(n_dofs)
    big = max((c for c in scene.mesh if c <= s.coarsen_max), default=s.coarsen)
    tets = min(float(n_tets), scene.mesh[big][0] + cal["graded"]["kappa"] * scene.injected_voxels / s.coarsen ** 3)
    return tets, n_dofs * tets / max(n_tets, 1)


def _solid_cpu(n_dofs: float, n_steps: int, cal: dict) -> float:
    """CPU s of the nonlinear quasi-static solid stage: factorisation + per-step solves."""
    c = cal["cost"]
    step = c["direct_step_s"] * (n_dofs / c["direct_step_dofs"]) ** (4.0 / 3.0)
    if n_dofs > DIRECT_MAX_DOFS:  # AMG-CG: per dof and step
        return c["amg_per_dof_step"] * n_dofs * n_steps
    q = c["direct_factor_loglog"]
    x = math.log(n_dofs)
    return math.exp(q[0] + q[1] * x + q[2] * x * x) + n_steps * step


def cpu_parts(scene: Scene, s: Setting, cal: dict | None = None) -> dict:
    """Expected CPU seconds of setting ``s`` on ``scene`` by stage: set-up, solid, stress, update, fluid."""
    cal = calibration() if cal is None else cal
    c = cal["cost"]
    n_tets, n_dofs = graded_size(scene, s, cal)
    if s.order == 2:
        n_dofs *= c["p2_dofs_factor"]
    solid = _solid_cpu(n_dofs, scene.n_steps, cal)
    if s.integrator == "tdg":
        solid *= c["tdg_factor"][str(s.tdg_iterations)]
    if s.response == "auto":
        solid *= c["response_auto_factor"]
    setup = c["extract_per_voxel"] * scene.n_voxels + c["mesh_per_tet"] * n_tets
    setup += (c["hull_per_pore_point"] * scene.n_pores * s.n_test_points if s.interface == "hull"
              else c["traction_per_tet"] * n_tets)
    fluid = scene.n_steps * c["fluid_per_step"] + c["fluid_per_event_pore"] * scene.n_events * scene.n_pores
    if s.scheme == "adaptive":
        ratio = _interp_log_ca(scene, cal["scheme"]["adaptive"], "fluid_cost_ratio")
        fluid = fluid * ratio + c["adaptive_fluid_extra_s"]
    update = scene.n_steps * c["update_per_pore_step"] * scene.n_pores if s.update != "none" else 0.0
    stress = scene.n_steps * c["stress_per_tet_step"] * n_tets
    return {"setup": float(setup), "solid": float(solid), "stress": float(stress), "update": float(update),
            "fluid": float(fluid)}


def expected_cpu(scene: Scene, s: Setting, cal: dict | None = None) -> float:
    """Expected CPU seconds (one thread) of setting ``s`` on ``scene`` (module docstring)."""
    return float(sum(cpu_parts(scene, s, cal).values()))
