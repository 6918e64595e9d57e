"""Node-to-ellipsoid contact at the displacement nodes of a shell ([Man2006, sec. 3.3], Box 3, eq. 3.69).

Each owned displacement node i of the sheet carries the lumped reference area w_i = int phi_i dA [m^2]
(phi_i: the scalar Lagrange basis function of the node). On quadrilateral Q2 meshes every w_i is
positive (corner, edge and centre weights 1/36, 1/9, 4/9 of a parallelogram's area). On P2 triangles
the vertex weights int phi_i dA vanish, so a nodal contact law would leave the vertices unconstrained:
such meshes are refused (ValueError).

Normal law at the deformed node x_i = X_i + u_i with signed gap g_i [m] (positive outside) and unit
outward body normal n_i (minimum over the body segments):

    p_i = < lambda_i - k_N g_i >               [Pa]   (eq. 3.69; penalty [Man2006, Box 3]: lambda_i = 0)
    f_i = w_i (p_i n_i + t_T,i)                 [N]    force of the body on the cloth node

(the thesis writes g as a penetration, positive inside; here g is a signed distance). t_T is the
Coulomb friction traction (fabricfem.contact.friction). The residual of the shell gets -f_i on the
three displacement rows of node i; its consistent tangent -df_i/dx_i = w_i k_N n n^T (+ friction).
The curvature term -w_i p_i dn/dx (of size w_i p_i / r, r the body radius of curvature) is neglected:
it is smaller than the kept term by p / (k_N r) = |g| / r (1e-4 or less in practice) and does not
change the residual, only Newton's rate (measured: quadratic convergence retained, tests/test_contact.py).

Default penalty: k_N = c E t / h^2 [Pa/m] with the membrane stiffness E t [N/m] (largest of the two
Young's moduli) and the mean element size h [m], c = 10. The nodal contact spring w_i k_N ~ c E t then
is c times stiffer than the membrane stiffness attached to a node, so the penetration is a small
fraction of the deformation that the same force produces in the sheet, while the condition number of
the Jacobian grows only by a factor ~c.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.body import ellipsoid as ellipsoid_module
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.forms import shell as shell_forms
from fabricfem.meshes._validate import positive

DEFAULT_PENALTY_FACTOR = 10.0


def positive_parameter(name: str, value: float) -> float:
    """A finite positive float or ValueError naming `name`."""
    return positive(name, value)


@dataclass
class ContactNodes:
    """The owned displacement nodes of a shell model, as seen by the contact layer.

    Attributes:
        dofs: (N, 3) local indices in model.W of (u_x, u_y, u_z) at each owned node.
        reference: (N, 3) reference positions X_i = phi0 [m].
        area: (N,) lumped reference areas w_i = int phi_i dA [m^2].
        constrained: (N, 3) True where the displacement component carries a Dirichlet condition.
        scalar_space: the collapsed scalar space of one displacement component (for output fields).
        node_index: (N,) indices of the owned nodes in scalar_space.
        element_size: h [m], sqrt(global area / global number of cells).
    """

    dofs: np.ndarray
    reference: np.ndarray
    area: np.ndarray
    constrained: np.ndarray
    scalar_space: fem.FunctionSpace
    node_index: np.ndarray
    element_size: float

    @property
    def count(self) -> int:
        return len(self.area)


def _displacement_space(model):
    """The displacement space (collapsed, blocked, 3 components) and its dof map into model.W."""
    if model.model == "naghdi":
        V, to_parent = model.W.sub(0).collapse()
        return V, np.asarray(to_parent, dtype=np.int32)
    V = model.W
    n = (V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts) * V.dofmap.index_map_bs
    return V, np.arange(n, dtype=np.int32)


class CurrentAreas:
    """Lumped current (deformed) areas a_i = int phi_i J dA [m^2] of the contact nodes for the state in
    model.w (J = da / dA, forms.shell.area_stretch). The contact law's p_i is per reference area w_i; the
    pressure on the body, force per unit deformed cloth area, is p_i w_i / a_i (Cauchy pressure)."""

    def __init__(self, model, nodes: ContactNodes):
        u = ufl.split(model.w)[0] if model.model == "naghdi" else model.w
        F0 = ufl.grad(model.phi0)
        J = shell_forms.area_stretch(F0 + ufl.grad(u), F0, model.t1, model.t2)
        dx = ufl.dx(domain=model.mesh, metadata={"quadrature_degree": 4})
        self._form = fem.form(ufl.TestFunction(nodes.scalar_space) * J * dx)
        self._index = nodes.node_index

    def __call__(self) -> np.ndarray:
        vec = fem_petsc.assemble_vector(self._form)
        vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        areas = vec.array[self._index].copy()
        vec.destroy()
        return areas


def pressure_on_body(pressure: np.ndarray, reference_area: np.ndarray, current_area: Callable[[], np.ndarray] | None,
                     per: str) -> np.ndarray:
    """Nodal contact pressure [Pa] from the contact law's p_i (per reference area w_i [m^2]): per unit current
    cloth area, p_i w_i / a_i, the pressure on the body (`per="current"`; `current_area()` gives a_i [m^2]), or
    p_i itself (`per="reference"`)."""
    if per == "reference":
        return pressure
    if per != "current":
        raise ValueError(f"per must be 'current' or 'reference', got {per!r}")
    return pressure * reference_area / current_area()


def pressure_function(space, node_index: np.ndarray, pressure: np.ndarray) -> fem.Function:
    """The contact pressure field [Pa]: a scalar Function on `space` (the contact nodes' Q2 space) with
    `pressure` at the local nodes `node_index` and 0 elsewhere, ghosts updated. The one pressure field of
    every contact formulation (output, renders)."""
    f = fem.Function(space, name="contact_pressure")
    f.x.array[node_index] = pressure
    f.x.scatter_forward()
    return f


def contact_nodes(model) -> ContactNodes:
    """Owned displacement nodes, reference positions X = phi0 (model.phi0 at the nodes), lumped areas
    and Dirichlet flags of a ShellModel.

    Raises:
        ValueError: the mesh has triangles (P2 vertex weights vanish) or a node has a non-positive weight.
    """
    mesh = model.mesh
    cellname = mesh.ufl_cell().cellname()
    if cellname != "quadrilateral":
        raise ValueError(f"mesh: nodal contact needs quadrilateral cells (Q2 nodes all have positive lumped "
                         f"areas); P2 {cellname}s have zero vertex weights int phi_i dA = 0 and are not supported")
    V, to_parent = _displacement_space(model)
    n_owned = V.dofmap.index_map.size_local
    dofs = to_parent.reshape(-1, 3)[:n_owned]
    reference = fem.Function(V)
    reference.interpolate(model.phi0)
    X = reference.x.array.reshape(-1, 3)[:n_owned].copy()
    # lumped areas on the scalar space of one component, mapped to the nodes of V
    S, to_vector = V.sub(0).collapse()
    node_of_scalar = np.asarray(to_vector, dtype=np.int64) // 3
    weight = fem_petsc.assemble_vector(fem.form(ufl.TestFunction(S) * ufl.dx(domain=mesh)))
    weight.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    n_owned_scalar = S.dofmap.index_map.size_local
    area = np.zeros(n_owned)
    owned_scalar = node_of_scalar[:n_owned_scalar]
    area[owned_scalar] = weight.array[:n_owned_scalar]
    weight.destroy()
    if n_owned and area.min() <= 0.0:
        raise ValueError(f"mesh: {int(np.sum(area <= 0))} nodes have a non-positive lumped area; nodal contact "
                         f"needs positive weights (quadrilateral Q2 elements)")
    bc_flag = np.zeros(len(model.w.x.array), dtype=bool)
    for bc in model.bcs:
        bc_flag[bc.dof_indices()[0]] = True
    n_cells = model.comm.allreduce(mesh.topology.index_map(2).size_local, op=MPI.SUM)
    total_area = model.comm.allreduce(float(area.sum()), op=MPI.SUM)
    node_index = np.zeros(n_owned, dtype=np.int32)
    node_index[owned_scalar] = np.arange(n_owned_scalar, dtype=np.int32)
    return ContactNodes(dofs=dofs, reference=X, area=area, constrained=bc_flag[dofs], scalar_space=S,
                        node_index=node_index, element_size=float(np.sqrt(total_area / n_cells)))


def default_penalty(model, element_size: float, factor: float = DEFAULT_PENALTY_FACTOR) -> float:
    """k_N = c E t / h^2 [Pa/m] (module docstring)."""
    factor = positive_parameter("penalty_factor", factor)
    fabric = model.fabric
    return factor * max(fabric.E1, fabric.E2) * fabric.thickness / element_size ** 2


def nearest_gap(x: np.ndarray, ellipsoids: Sequence[Ellipsoid],
                segment: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smallest signed gap [m] over the ellipsoids, the unit outward normal there and the segment index.

    With `segment` (N,) given, the gap and normal of that segment instead of the nearest one (a frozen
    assignment, ContactProblem's active-set strategy). Loops over the (few) segments, vectorised over the
    N points (see `Ellipsoid.gap`).
    """
    g, n, nearest = ellipsoid_module.nearest_gap(x, ellipsoids, segment)
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(n))):
        raise ValueError("x: the contact gap is not finite (positions contain NaN/inf: the solve diverged)")
    return g, n, nearest


def normal_pressure(gap: np.ndarray, multiplier: np.ndarray, penalty: float,
                    active: np.ndarray | None = None) -> np.ndarray:
    """p = < lambda - k_N g > [Pa] (eq. 3.69 with g positive outside; lambda = 0 is the penalty law).

    With a fixed active set `active` (N,) bool (the active-set strategy of ContactProblem), the law is
    p = lambda - k_N g on the active nodes -- a bilateral spring, p may turn slightly negative during
    the Newton iterations -- and p = 0 elsewhere. Where the set agrees with the sign of lambda - k_N g
    both laws give the same p.
    """
    trial = multiplier - penalty * gap
    if active is None:
        return np.maximum(trial, 0.0)
    return np.where(active, trial, 0.0)


def keep_ties(previous: np.ndarray, gap: np.ndarray, multiplier: np.ndarray, penalty: float,
              tie: float) -> np.ndarray:
    """Contact set of an active-set update (ContactProblem) in which the nodes on the switch keep their status:
    (N,) bool, `previous` where |lambda - k_N g| <= k_N tie, else lambda - k_N g > 0 (eq. 3.69's switch).
    A kept contact node has tension lambda - k_N g >= -k_N tie [Pa]; a kept free node has
    -g <= tie - lambda / k_N <= tie [m] (lambda >= 0)."""
    trial = multiplier - penalty * gap
    return np.where(np.abs(trial) <= penalty * tie, np.asarray(previous, dtype=bool), trial > 0.0)


def normal_force_and_tangent(area: np.ndarray, pressure: np.ndarray, normal: np.ndarray,
                             penalty: float, active: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Nodal normal force f = w p n [N] (N, 3) and its stiffness K = -df/dx = w k_N n n^T [N/m] (N, 3, 3)
    (curvature term neglected, module docstring) on the `active` nodes (default: p > 0)."""
    force = (area * pressure)[:, None] * normal
    active = (pressure > 0.0) if active is None else np.asarray(active, dtype=bool)
    stiffness = (area * penalty * active.astype(float))[:, None, None] * normal[:, :, None] * normal[:, None, :]
    return force, stiffness
