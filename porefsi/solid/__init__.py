"""porefsi.solid: the rock frame as a nonlinear elastic solid meshed from the image.

scikit-fem is imported only in this package. The public pieces:

- :func:`mesh_solid` -> :class:`MeshResult` (a :class:`SolidMesh`, removed floating solid);
- materials :class:`StVenantKirchhoff`, :class:`NeoHookean` (E, nu, density);
- boundary conditions :class:`Fixed`, :class:`Roller`, :class:`Prescribed`, :class:`Affine`,
  :class:`Traction`, :func:`uniaxial_bcs`;
- :class:`SolidModel`: the assembled model on free dofs (the integrators' ``SecondOrderSystem``);
- :func:`solve_static`, :func:`uniaxial_compression`; stress recovery in :mod:`porefsi.solid.stress`.
"""

from porefsi.solid.bc import Affine, Fixed, Prescribed, Roller, Traction, uniaxial_bcs
from porefsi.solid.linsolve import AMGSolverFactory, direct_solver_factory, jacobi_solver_factory
from porefsi.solid.materials import NeoHookean, StVenantKirchhoff, make_material
from porefsi.solid.mesh import FACE_NAMES, FACET_TAGS, PORE_WALL, MeshResult, SolidMesh, mesh_solid
from porefsi.solid.model import SolidModel
from porefsi.solid.shapes import box_mesh, shell_octant_mesh
from porefsi.solid.static import solve_static, uniaxial_compression
from porefsi.solid.stress import effective_modulus, element_cauchy, nodal_average, von_mises

__all__ = [
    "SolidMesh", "MeshResult", "mesh_solid", "FACET_TAGS", "FACE_NAMES", "PORE_WALL",
    "box_mesh", "shell_octant_mesh",
    "StVenantKirchhoff", "NeoHookean", "make_material",
    "Fixed", "Roller", "Prescribed", "Affine", "Traction", "uniaxial_bcs",
    "SolidModel", "AMGSolverFactory", "jacobi_solver_factory", "direct_solver_factory",
    "solve_static", "uniaxial_compression",
    "element_cauchy", "von_mises", "nodal_average", "effective_modulus",
]
