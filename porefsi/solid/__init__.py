"""porefsi.solid: the rock frame as a nonlinear elastic solid meshed from the image.

scikit-fem is imported only in this package (and only when a name that needs it is used). The
public pieces:

- :func:`mesh_solid` -> :class:`MeshResult` (a :class:`SolidMesh`, removed floating solid);
  :func:`mesh_graded`, the same with fine blocks only near a refined region (2:1 octree);
  :func:`tet_quality` (dihedral angles, radius ratio), :func:`p1_interpolate` (a nodal field at points);
- materials :class:`StVenantKirchhoff`, :class:`NeoHookean` (E, nu, density);
- boundary conditions :class:`Fixed`, :class:`Roller`, :class:`Prescribed`, :class:`Affine`,
  :class:`Traction`, :func:`uniaxial_bcs`;
- :class:`SolidModel`: the assembled model on free dofs (the integrators' ``SecondOrderSystem``);
- :func:`solve_static`, :func:`uniaxial_compression`; stress recovery in :mod:`porefsi.solid.stress`.
"""

from porefsi._lazy import exports

#: Public name -> the module that defines it (imported on first use).
_EXPORTS = {
    "SolidMesh": "porefsi.solid.mesh",
    "MeshResult": "porefsi.solid.mesh",
    "mesh_solid": "porefsi.solid.mesh",
    "mesh_graded": "porefsi.solid.graded",
    "tet_quality": "porefsi.solid.quality",
    "p1_interpolate": "porefsi.solid.interpolate",
    "FACET_TAGS": "porefsi.solid.mesh",
    "FACE_NAMES": "porefsi.solid.mesh",
    "PORE_WALL": "porefsi.solid.mesh",
    "tet_volumes": "porefsi.solid.mesh",
    "box_mesh": "porefsi.solid.shapes",
    "shell_octant_mesh": "porefsi.solid.shapes",
    "Material": "porefsi.solid.materials",
    "StVenantKirchhoff": "porefsi.solid.materials",
    "NeoHookean": "porefsi.solid.materials",
    "make_material": "porefsi.solid.materials",
    "MATERIALS": "porefsi.solid.materials",
    "Fixed": "porefsi.solid.bc",
    "Roller": "porefsi.solid.bc",
    "Prescribed": "porefsi.solid.bc",
    "Affine": "porefsi.solid.bc",
    "Traction": "porefsi.solid.bc",
    "uniaxial_bcs": "porefsi.solid.bc",
    "check_load_path": "porefsi.solid.bc",
    "midpoint_nodes": "porefsi.solid.bc",
    "SolidModel": "porefsi.solid.model",
    "AMGSolverFactory": "porefsi.solid.linsolve",
    "jacobi_solver_factory": "porefsi.solid.linsolve",
    "direct_solver_factory": "porefsi.solid.linsolve",
    "solve_static": "porefsi.solid.static",
    "uniaxial_compression": "porefsi.solid.static",
    "UniaxialResult": "porefsi.solid.static",
    "NewtonInfo": "porefsi.solid.static",
    "element_cauchy": "porefsi.solid.stress",
    "von_mises": "porefsi.solid.stress",
    "nodal_average": "porefsi.solid.stress",
    "effective_modulus": "porefsi.solid.stress",
}

__all__ = [
    "SolidMesh",
    "MeshResult",
    "mesh_solid",
    "mesh_graded",
    "tet_quality",
    "p1_interpolate",
    "FACET_TAGS",
    "FACE_NAMES",
    "PORE_WALL",
    "tet_volumes",
    "box_mesh",
    "shell_octant_mesh",
    "Material",
    "StVenantKirchhoff",
    "NeoHookean",
    "make_material",
    "MATERIALS",
    "Fixed",
    "Roller",
    "Prescribed",
    "Affine",
    "Traction",
    "uniaxial_bcs",
    "check_load_path",
    "midpoint_nodes",
    "SolidModel",
    "AMGSolverFactory",
    "jacobi_solver_factory",
    "direct_solver_factory",
    "solve_static",
    "uniaxial_compression",
    "UniaxialResult",
    "NewtonInfo",
    "element_cauchy",
    "von_mises",
    "nodal_average",
    "effective_modulus",
]

__getattr__, __dir__ = exports(__name__, _EXPORTS)
