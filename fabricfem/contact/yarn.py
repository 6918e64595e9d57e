"""Yarn-yarn frictional contact between hexahedral yarn meshes ([Man2006, sec. 3.2] and 3.4, Box 7).

Node-to-surface contact: the slave nodes are the vertices of one yarn's lateral surface facets, the
master surface is the other yarn's lateral facets (quadrilaterals of the hex mesh, each split into the
two triangles (v0, v1, v3), (v0, v3, v2) of dolfinx' tensor-product vertex order). Units: m, N, Pa.

Kinematics (sec. 3.2): every slave node x_s is projected onto the master surface (closest point on
the triangles, exact, vectorized); the projection x_p = sum_i N_i x_i (N_i: barycentric weights of
the master triangle = linear shape functions of the triangulated surface), the outward master
normal n = sum_i N_i n_i / |.| interpolated from the nodal normals n_i (area-weighted averages of the
adjacent facet normals: a continuous normal field, so that the force direction does not jump when
the foot point crosses a facet edge, which made Newton stall at 1e-3 of the force with facet normals)
and the signed normal gap

    g = n . (x_s - x_p)          (eq. 3.25, positive = separated; the thesis uses the opposite sign)

The tangential slip since the last converged step is the relative motion of x_s with respect to the
master material point x_ref = sum_i N_i(xi_n) x_i it was projected onto at that step (the convected
coordinate xi_n of eq. 3.74), taken in the current tangent plane: P (x_s - x_ref), P = 1 - n n^T.

Contact law: symmetrized augmented Lagrangian of Laursen ([Man2006, Box 7], eqs. 3.69, 3.74, 3.75, 3.79) with
multipliers lambda_N [Pa] and lambda_T [Pa, a tangential vector] per slave node, held fixed in the
Newton solve of one augmentation:

    p   = < lambda_N - eps_N g >                                    (eq. 3.69, contact pressure)
    t*  = P lambda_T - eps_T P (x_s - x_ref)                          (eq. 3.74, trial traction)
    t_T = t*                       if |t*| <= mu lambda_N  (stick)    (eq. 3.75 with [Man2006, Box 7]'s Phi~:
    t_T = mu lambda_N t* / |t*|    otherwise (slip)                    the limit uses lambda_N, fixed)

The slave node gets the force f_s = A_s (p n + t_T) [N] (A_s: its lumped reference area), the master
nodes get -N_i A_s p n at the current projection and -N_i(xi_n) A_s t_T at the reference point.
Uzawa augmentation between Newton solves ([Man2006, Box 7] step 3): lambda_N <- p, lambda_T <- t_T returned onto
the new cone |lambda_T| <= mu lambda_N (eq. 3.79), until the largest penetration and the largest
stick-slip violation are below `tolerance`. With `augmented=False` the law is the plain penalty one
(lambda = 0, friction limit mu p). After a converged load step (`commit`), the reference points move
to the current projections and lambda_T is kept as the history of the tangential traction.

Tangent (assembled into the Jacobian as dR/dx, R = internal - contact forces): with G = [1, -N_i] the
stencil weights at the projection and H = [1, -N_i(xi_n)] those of the reference point,

    K_jk = A eps_N G_j G_k n n^T - A H_j H_k D,     D = -eps_T P (stick)
                                                   D = -(mu lambda_N eps_T / |t*|)(P - tau tau^T) (slip)

It neglects the variation of n and of the projection xi (terms of relative size |g| / h and of the
curvature), so it is approximately consistent; it is symmetric because lambda_N is fixed ([Man2006, Box 7]).
With `consistent_tangent` both parts are central differences of the exact nodal forces over each
contact element's stencil instead (normal: slave + the 16 patch vertices of the master facet;
friction: those + the 4 reference facet vertices, branch fixed), which includes the rotation of n and
of the tangent plane P(n) (relative size ~ p / (eps_N h) and ~ mu).

Active-set strategy on the facets (`solve_with_fixed_sets`): during one Newton solve each
active slave keeps a fixed master facet and is projected onto the plane of a fixed triangle of it
(`freeze`, `project_onto_triangle_planes`), so the law is smooth; the set is updated from the
converged state until it no longer changes.

Search (sec. 3.2 / 3.4: global once, local afterwards): a global search pairs every slave node with
the master facets whose centroid lies within (the facet circumradius + margin) (scipy cKDTree);
these candidates are reused (a Verlet list) until some surface node has moved more than margin / 2
since that search, when the global search is repeated. margin defaults to the median facet edge.

Parallel: the surface node coordinates, displacements and facet connectivity of all yarns are
gathered on every rank (allgather; surfaces are small), every rank computes the same contact state,
and each rank adds only the rows it owns to the PETSc residual vector and Jacobian. Rows and columns
of constrained dofs (Dirichlet, or multi-point-constraint slaves) are dropped (their increment is zero
or given by other dofs); `dropped_active` counts active contact nodes that touch one.
"""
from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass, field
from typing import Sequence

import dolfinx.fem as fem
import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc
from scipy.spatial import cKDTree

from fabricfem.meshes._validate import positive
from fabricfem.solvers.newton import NewtonResult, SolverError

__all__ = ["ContactParameters", "ContactReport", "YarnContact", "closest_point_on_triangles",
           "project_onto_quads", "smooth_ramp", "symmetric_return_map", "solve_with_fixed_sets", "MAX_SET_UPDATES",
           "project_onto_triangle_planes", "triangle_of"]


_positive = positive


@dataclass(frozen=True)
class ContactParameters:
    """Parameters of the yarn contact law.

    Attributes:
        penalty: eps_N [Pa/m], normal penalty (eq. 3.69), > 0
        friction: Coulomb coefficient mu >= 0
        tangential_penalty: eps_T [Pa/m] (eq. 3.74), > 0; None = penalty
        tolerance: [m] augmentation stops when max penetration and max stick slip are below it, > 0
        max_augmentations: Uzawa updates per load step (>= 1)
        augmented: False = pure penalty law (no multipliers, one Newton solve per step)
        margin: [m] Verlet margin of the contact search; None = median master facet edge length
        smoothing: [m] >= 0, width delta of a C1 quadratic rounding of the Macaulay bracket of eq. 3.69
            (smooth_ramp with w = eps_N delta): removes the kink of the pressure where a node enters
            or leaves contact (Newton then does not cycle on the active set); 0 = the exact bracket.
            The rounding pushes with at most eps_N delta / 4 at zero gap, so delta is meant to be
            far below the penetration tolerance
        consistent_tangent: True = the normal part of the tangent by central differences of the exact
            nodal forces over each contact element's stencil (YarnContact._normal_tangent): includes the
            rotation of the master normals and the sliding of the foot point, which the closed form
            omits (a relative error ~ p / (eps_N h), measured 25% on the unit cell, where Newton then
            only converges linearly); False = the closed form of the module docstring
        penalty_growth: factor (>= 1) on eps_N and eps_T when the violation max(penetration, stick slip)
            has grown in two successive augmentations (`solve_with_contact`); 1 = never
    """

    penalty: float
    friction: float = 0.0
    tangential_penalty: float | None = None
    tolerance: float = 1e-9
    max_augmentations: int = 30
    augmented: bool = True
    margin: float | None = None
    smoothing: float = 0.0
    consistent_tangent: bool = False
    penalty_growth: float = 10.0

    def __post_init__(self) -> None:
        _positive("penalty", self.penalty)
        if not (isinstance(self.penalty_growth, (int, float)) and np.isfinite(self.penalty_growth)
                and self.penalty_growth >= 1.0):
            raise ValueError(f"penalty_growth must be a finite factor >= 1, got {self.penalty_growth!r}")
        try:
            mu = float(self.friction)
        except (TypeError, ValueError):
            raise ValueError(f"friction (Coulomb coefficient) must be a number >= 0, got {self.friction!r}") from None
        if not (np.isfinite(mu) and mu >= 0.0):
            raise ValueError(f"friction (Coulomb coefficient) must be finite and >= 0, got {self.friction!r}")
        if self.tangential_penalty is not None:
            _positive("tangential_penalty", self.tangential_penalty)
        _positive("tolerance", self.tolerance)
        if isinstance(self.max_augmentations, bool) or int(self.max_augmentations) != self.max_augmentations \
                or self.max_augmentations < 1:
            raise ValueError(f"max_augmentations must be an integer >= 1, got {self.max_augmentations!r}")
        if self.margin is not None:
            _positive("margin", self.margin)
        if not (isinstance(self.smoothing, (int, float)) and np.isfinite(self.smoothing) and self.smoothing >= 0.0):
            raise ValueError(f"smoothing must be a finite length >= 0 [m], got {self.smoothing!r}")

    @property
    def eps_T(self) -> float:
        return float(self.penalty if self.tangential_penalty is None else self.tangential_penalty)


@dataclass
class ContactReport:
    """Contact summary of one load step (forces in N on the slave bodies, lengths in m)."""

    augmentations: int
    max_penetration: float
    max_stick_slip: float
    force: np.ndarray  # total contact force on the slave yarns (3,) [N]
    normal_force: float  # sum of A_s p_s [N]
    tangential_force: float  # |sum of A_s t_T| [N]
    active: int
    slipping: int
    newton_iterations: list[int] = field(default_factory=list)
    dropped_active: int = 0
    penalty_growths: int = 0  # times eps_N, eps_T were raised by penalty_growth in this step (solve_with_contact)


# ---------------------------------------------------------------------------------------------
# pure geometry and friction helpers


def closest_point_on_triangles(x: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
                               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest points on triangles (a, b, c) to points x, all (n, 3) [m], vectorized.

    Returns (point (n, 3), barycentric weights (n, 3) of (a, b, c), distance (n,)). Exact: the
    projection onto the plane if it falls inside, otherwise the closest of the three edge points."""
    ab, ac, ax = b - a, c - a, x - a
    d00, d01, d11 = (ab * ab).sum(1), (ab * ac).sum(1), (ac * ac).sum(1)
    d20, d21 = (ax * ab).sum(1), (ax * ac).sum(1)
    den = d00 * d11 - d01 * d01
    if np.any(den <= 0.0):
        raise ValueError("master surface: degenerate (zero-area) triangle")
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    bary = np.column_stack([1.0 - v - w, v, w])
    inside = np.all(bary >= 0.0, axis=1)
    best_bary = np.where(inside[:, None], bary, 0.0)
    best_dist = np.where(inside, np.linalg.norm(x - (bary[:, :1] * a + v[:, None] * b + w[:, None] * c), axis=1),
                         np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):  # three edges, vectorized over points
        p, q = (a, b, c)[i], (a, b, c)[j]
        e = q - p
        t = np.clip(((x - p) * e).sum(1) / (e * e).sum(1), 0.0, 1.0)
        dist = np.linalg.norm(x - (p + t[:, None] * e), axis=1)
        better = dist < best_dist
        edge_bary = np.zeros_like(bary)
        edge_bary[:, i], edge_bary[:, j] = 1.0 - t, t
        best_bary = np.where(better[:, None], edge_bary, best_bary)
        best_dist = np.where(better, dist, best_dist)
    point = best_bary[:, :1] * a + best_bary[:, 1:2] * b + best_bary[:, 2:] * c
    return point, best_bary, best_dist


# the two triangles of a tensor-ordered quad (v0, v1, v2, v3) = (0,0), (1,0), (0,1), (1,1)
_QUAD_TRIANGLES = np.array([[0, 1, 3], [0, 3, 2]])


def project_onto_quads(x: np.ndarray, quads_x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closest point of x (n, 3) on quadrilateral facets quads_x (n, 4, 3) (tensor vertex order, both
    as two triangles), pairwise. Returns (point (n, 3), weights (n, 4) of the quad's vertices,
    outward unit normal (n, 3) (of the chosen triangle, (v1 - v0) x (v2 - v0) orientation, or along
    x - point when the foot point lies on an edge or vertex), distance (n,))."""
    best = None
    for tri in _QUAD_TRIANGLES:
        a, b, c = (quads_x[:, k] for k in tri)
        point, bary, dist = closest_point_on_triangles(x, a, b, c)
        normal = np.cross(b - a, c - a)
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        weights = np.zeros((len(x), 4))
        np.put_along_axis(weights, np.broadcast_to(tri, (len(x), 3)), bary, axis=1)
        if best is None:
            best = [point, weights, normal, dist]
        else:
            better = dist < best[3]
            best = [np.where(better[:, None], point, best[0]), np.where(better[:, None], weights, best[1]),
                    np.where(better[:, None], normal, best[2]), np.where(better, dist, best[3])]
    point, weights, normal, dist = best
    # foot point on an edge or a vertex: the normal is the direction of the distance vector (signed by
    # the facet normal), which keeps the gap continuous when the closest facet changes
    on_edge = np.count_nonzero(weights > 0.0, axis=1) < 3
    diff = x - point
    sign = np.where((diff * normal).sum(1) < 0.0, -1.0, 1.0)
    use = on_edge & (dist > 0.0)
    safe = np.where(use, dist, 1.0)
    normal = np.where(use[:, None], sign[:, None] * diff / safe[:, None], normal)
    return point, weights, normal, dist


def project_onto_triangle_planes(x: np.ndarray, quads_x: np.ndarray, tri: np.ndarray
                                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthogonal projection of x (n, 3) onto the plane of triangle `tri` (n,) (0: (v0, v1, v3), 1: (v0, v3,
    v2)) of the quads quads_x (n, 4, 3), pairwise, with the barycentric weights NOT clamped (the triangle's
    linear shape functions extrapolated beyond its edges): a smooth function of x and the vertices, the
    projection of a fixed facet in the active-set strategy. Returns (point (n, 3), weights (n, 4) of the
    quad's vertices, distance (n,))."""
    idx = _QUAD_TRIANGLES[np.asarray(tri, dtype=np.int64)]                                  # (n, 3)
    rows = np.arange(len(x))[:, None]
    a, b, c = (quads_x[rows[:, 0], idx[:, k]] for k in range(3))
    ab, ac, ax = b - a, c - a, x - a
    d00, d01, d11 = (ab * ab).sum(1), (ab * ac).sum(1), (ac * ac).sum(1)
    d20, d21 = (ax * ab).sum(1), (ax * ac).sum(1)
    den = d00 * d11 - d01 * d01
    if np.any(den <= 0.0):
        raise ValueError("master surface: degenerate (zero-area) triangle")
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    weights = np.zeros((len(x), 4))
    np.put_along_axis(weights, idx, np.column_stack([1.0 - v - w, v, w]), axis=1)
    point = (weights[:, :, None] * quads_x).sum(1)
    return point, weights, np.linalg.norm(x - point, axis=1)


def triangle_of(weights: np.ndarray) -> np.ndarray:
    """The triangle (0: (v0, v1, v3), 1: (v0, v3, v2)) of a quad holding a foot point with quad vertex
    weights (n, 4) from project_onto_quads (v2 has no weight on triangle 0)."""
    return np.where(weights[:, 2] == 0.0, 0, 1)


def _project(xs: np.ndarray, quad_x: np.ndarray, tri: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(foot point, weights): closest point on the quad where tri < 0 (or tri None), else the projection onto
    the plane of the fixed triangle tri (project_onto_triangle_planes)."""
    point, w, _, _ = project_onto_quads(xs, quad_x)
    if tri is None or not np.any(tri >= 0):
        return point, w
    fixed = tri >= 0
    p2, w2, _ = project_onto_triangle_planes(xs, quad_x, np.where(fixed, tri, 0))
    return np.where(fixed[:, None], p2, point), np.where(fixed[:, None], w2, w)


def symmetric_return_map(trial: np.ndarray, limit: np.ndarray, eps_T: float, projector: np.ndarray,
                         branch: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coulomb return mapping with a fixed friction limit ([Man2006, Box 7], eq. 3.75), n nodes, vectorized.

    trial: (n, 3) tangential trial tractions t* [Pa]; limit: (n,) mu lambda_N [Pa] >= 0;
    eps_T [Pa/m]; projector: (n, 3, 3) P = 1 - n n^T; branch: optional (n,) int, the branch imposed
    on a node (0 = stick, 1 = slip, -1 = the Coulomb test |t*| > limit decides): the fixed slip set of
    the active-set strategy (solve_with_fixed_sets).
    Returns (t_T (n, 3), D = dt_T/d(slip displacement) (n, 3, 3) [Pa/m], slip (n,) bool)."""
    norm = np.linalg.norm(trial, axis=1)
    slip = norm > limit
    if branch is not None:
        slip = np.where(branch >= 0, branch == 1, slip)
    safe = np.where(norm > 0.0, norm, 1.0)
    tau = trial / safe[:, None]
    traction = np.where(slip[:, None], limit[:, None] * tau, trial)                       # eq. 3.75
    stick_D = -eps_T * projector
    slip_D = -(limit * eps_T / safe)[:, None, None] * (projector - tau[:, :, None] * tau[:, None, :])
    return traction, np.where(slip[:, None, None], slip_D, stick_D), slip


def smooth_ramp(z: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """C1 rounding of the Macaulay bracket <z> = max(z, 0) and its slope, vectorized:
    0 for z <= -w, (z + w)^2 / (4 w) for |z| < w, z for z >= w (w = width >= 0; w = 0: the bracket)."""
    z = np.asarray(z, dtype=float)
    if width <= 0.0:
        return np.maximum(z, 0.0), (z > 0.0).astype(float)
    inner = np.abs(z) < width
    zi = np.where(inner, z, 0.0)
    value = np.where(z >= width, z, np.where(inner, (zi + width) ** 2 / (4.0 * width), 0.0))
    slope = np.where(z >= width, 1.0, np.where(inner, (zi + width) / (2.0 * width), 0.0))
    return value, slope


def _nodal_normals(x: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Unit outward normals at the nodes x (n, 3) of the quads (m, 4): area-weighted average of the
    adjacent facet normals (the quad's diagonals' cross product is twice its area vector)."""
    qx = x[quads]
    facet = np.cross(qx[:, 3] - qx[:, 0], qx[:, 2] - qx[:, 1])
    out = np.zeros_like(x)
    np.add.at(out, quads.ravel(), np.repeat(facet, 4, axis=0))
    norm = np.linalg.norm(out, axis=1)
    return out / np.where(norm > 0.0, norm, 1.0)[:, None]


# ---------------------------------------------------------------------------------------------
# the distributed contact operator


def _vertex_to_dof_block(V: fem.FunctionSpace) -> np.ndarray:
    """Local vertex -> local dof block of a P1 (vector) space; -1 for vertices without dofs."""
    mesh = V.mesh
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim, 0)
    c2v = mesh.topology.connectivity(tdim, 0)
    nv = mesh.topology.index_map(0).size_local + mesh.topology.index_map(0).num_ghosts
    per_cell = c2v.offsets[1] - c2v.offsets[0]
    dofs = V.dofmap.list.array.reshape(-1, per_cell)
    if dofs.shape[1] != per_cell:
        raise ValueError("u must be a first-order Lagrange vector Function (one dof block per vertex)")
    out = np.full(nv, -1, dtype=np.int64)
    out[c2v.array.reshape(-1, per_cell)] = dofs
    return out


class YarnContact:
    """Frictional node-to-surface contact between yarns of one dolfinx mesh.

    Parameters:
        u: displacement (or fluctuation) Function, first-order Lagrange vector space [m]; the placement
            of a node is x = Phi X + u with X its reference position and Phi (attribute, default 1)
            the macroscopic deformation gradient of a unit cell
        facet_tags: MeshTags of facets holding the yarns' lateral surface facets
        pairs: (slave tag, master tag) pairs; the slave yarn's vertices are pushed out of the master
            yarn's facets
        parameters: ContactParameters
        constrained_dofs: global scalar dof indices (any rank may give any) whose rows and columns are
            dropped from the contact contributions (Dirichlet / MPC slaves)
    """

    def __init__(self, u: fem.Function, facet_tags, pairs: Sequence[tuple[int, int]], parameters: ContactParameters,
                 constrained_dofs: np.ndarray | None = None):
        if not isinstance(parameters, ContactParameters):
            raise ValueError("parameters must be a ContactParameters")
        if not pairs:
            raise ValueError("pairs must contain at least one (slave tag, master tag) pair")
        V = u.function_space
        mesh = V.mesh
        self.u, self.params, self.comm = u, parameters, mesh.comm
        self.bs = V.dofmap.index_map_bs
        if self.bs != 3 or mesh.geometry.dim != 3:
            raise ValueError("u must be a 3-component vector Function on a 3D mesh")
        self.Phi = np.eye(3)
        imap = V.dofmap.index_map
        self.owned_range = np.array(imap.local_range, dtype=np.int64) * self.bs
        self.n_global = imap.size_global * self.bs

        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim - 1, 0)
        mesh.topology.create_connectivity(tdim - 1, tdim)
        mesh.topology.create_connectivity(tdim, 0)
        f2v, f2c, c2v = (mesh.topology.connectivity(tdim - 1, 0), mesh.topology.connectivity(tdim - 1, tdim),
                         mesh.topology.connectivity(tdim, 0))
        vertex_block = _vertex_to_dof_block(V)
        block_global = np.asarray(imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts,
                                                                  dtype=np.int32)), dtype=np.int64)
        # vertex -> geometry node (P1 geometry: same reference order as the topology)
        gdofs = mesh.geometry.dofmap.array.reshape(-1, c2v.offsets[1] - c2v.offsets[0])
        vertex_node = np.zeros(len(vertex_block), dtype=np.int64)
        vertex_node[c2v.array.reshape(-1, gdofs.shape[1])] = gdofs
        X_all = mesh.geometry.x

        tags = sorted({int(t) for pair in pairs for t in pair})
        present = set(np.unique(np.concatenate(self.comm.allgather(facet_tags.values))).tolist())
        for t in tags:
            if t not in present:
                raise ValueError(f"pairs: facet tag {t} marks no facet of the mesh")
        for s, m in pairs:
            if s == m:
                raise ValueError(f"pairs: slave and master tag must differ, got ({s}, {m})")

        # local quads (global dof blocks, outward orientation) of every tag, gathered everywhere
        per_facet = f2v.offsets[1] - f2v.offsets[0]
        if per_facet != 4:
            raise ValueError("the contact surfaces must be quadrilateral facets (hexahedral mesh)")
        fv = f2v.array.reshape(-1, 4)
        cell_vertices = c2v.array.reshape(-1, c2v.offsets[1] - c2v.offsets[0])
        quads_by_tag = {}
        owned_blocks, owned_X = [], []
        for t in tags:
            facets = facet_tags.indices[facet_tags.values == t]
            verts = fv[facets]
            x = X_all[vertex_node[verts]]
            cells = f2c.array[f2c.offsets[facets]]
            centre = X_all[vertex_node[cell_vertices[cells]]].mean(axis=1)
            normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
            inward = (normal * (x.mean(axis=1) - centre)).sum(1) < 0.0
            verts = np.where(inward[:, None], verts[:, [0, 2, 1, 3]], verts)
            blocks = block_global[vertex_block[verts]]
            quads_by_tag[t] = np.concatenate(self.comm.allgather(blocks)).reshape(-1, 4)
            local_blocks = vertex_block[np.unique(verts)]
            mine = local_blocks < imap.size_local
            owned_blocks.append(block_global[local_blocks[mine]])
            owned_X.append(X_all[vertex_node[np.unique(verts)[mine]]])
        owned_blocks = np.concatenate(owned_blocks)
        owned_X = np.concatenate(owned_X)
        owned_blocks, first = np.unique(owned_blocks, return_index=True)
        owned_X = owned_X[first]
        self._local_owned = (owned_blocks - imap.local_range[0]).astype(np.int64)  # local blocks to send
        all_blocks = self.comm.allgather(owned_blocks)
        self._recv_order = np.argsort(np.concatenate(all_blocks), kind="stable")
        self.nodes = np.concatenate(all_blocks)[self._recv_order]  # global dof blocks, sorted
        self.X = np.concatenate(self.comm.allgather(owned_X))[self._recv_order]  # reference positions [m]

        def local(blocks: np.ndarray) -> np.ndarray:
            idx = np.searchsorted(self.nodes, blocks)
            return idx

        # one facet once (a facet shared by ranks appears several times)
        for t in tags:
            q = local(quads_by_tag[t])
            key = np.sort(q, axis=1)
            _, keep = np.unique(key, axis=0, return_index=True)
            quads_by_tag[t] = q[np.sort(keep)]

        # slave nodes of every pair with lumped reference areas (area / 4 per quad vertex)
        slaves, areas, masters, pair_of_slave = [], [], [], []
        node_area = {}
        for t in tags:
            q = quads_by_tag[t]
            x = self.X[q]
            area = 0.5 * (np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 3] - x[:, 0]), axis=1)
                          + np.linalg.norm(np.cross(x[:, 3] - x[:, 0], x[:, 2] - x[:, 0]), axis=1))
            a = np.zeros(len(self.nodes))
            np.add.at(a, q.ravel(), np.repeat(area / 4.0, 4))
            node_area[t] = a
        for k, (s, m) in enumerate(pairs):
            nodes = np.unique(quads_by_tag[s])
            slaves.append(nodes)
            areas.append(node_area[s][nodes])
            pair_of_slave.append(np.full(len(nodes), k))
            masters.append(quads_by_tag[m])
        self.pairs = [(int(s), int(m)) for s, m in pairs]
        self.slave = np.concatenate(slaves)
        self.area = np.concatenate(areas)  # [m^2]
        self.pair_of_slave = np.concatenate(pair_of_slave)
        self.master_quads = masters  # per pair (m_k, 4) indices into self.nodes
        self._patches = [self._facet_patches(q) for q in masters]
        edges = np.concatenate([np.linalg.norm(self.X[q] - self.X[np.roll(q, 1, axis=1)], axis=2).ravel()
                                for q in masters])
        self.margin = float(np.median(edges)) if parameters.margin is None else float(parameters.margin)

        constrained = np.zeros(0, dtype=np.int64) if constrained_dofs is None else np.asarray(constrained_dofs,
                                                                                             dtype=np.int64)
        self.constrained = np.unique(np.concatenate(self.comm.allgather(constrained)))

        n = len(self.slave)
        self.lam_N = np.zeros(n)  # [Pa]
        self.lam_T = np.zeros((n, 3))  # [Pa]
        self.ref_quad = np.full(n, -1, dtype=np.int64)  # reference master facet (index into its pair's list)
        self.ref_weights = np.zeros((n, 4))
        self._candidates: list[np.ndarray] | None = None
        self._search_x: np.ndarray | None = None
        self.state: dict | None = None
        self.dropped_active = 0
        # fixed facet set of the active-set strategy (freeze / unfreeze, solve_with_fixed_sets): per slave the
        # master facet (-1 = free: closest facet) and the triangle of it whose plane the slave is projected on
        self.frozen_facet: np.ndarray | None = None
        self.frozen_tri: np.ndarray | None = None
        self.accepted_sets: tuple | None = None  # (facet, triangle, why) of the last accepted fixed-set solve
        self.set_updates: list[int] = []  # set changes per update of the last solve_with_fixed_sets

    @staticmethod
    def _facet_patches(quads: np.ndarray) -> dict:
        """Per master facet the facets sharing one of its vertices (the ones its nodal normals are
        averaged from, at most 9 on the lateral surface of a swept O-grid) and their vertices (at most
        16): local indices for the finite-difference tangent (set-up only)."""
        nq = len(quads)
        adjacent: dict[int, list[int]] = {}
        for q, row in enumerate(quads.tolist()):
            for v in row:
                adjacent.setdefault(v, []).append(q)
        pq = np.zeros((nq, 9), dtype=np.int64)
        pmask = np.zeros((nq, 9))
        pn = np.zeros((nq, 16), dtype=np.int64)
        pql = np.zeros((nq, 9, 4), dtype=np.int64)
        ql = np.zeros((nq, 4), dtype=np.int64)
        member = np.zeros((nq, 4, 9))
        for q, row in enumerate(quads.tolist()):
            patch = sorted({a for v in row for a in adjacent[v]})
            nodes = sorted({v for a in patch for v in quads[a].tolist()})
            if len(patch) > 9 or len(nodes) > 16:
                raise ValueError("contact surface: a facet vertex has more than 4 facets (not a structured "
                                 "quadrilateral surface); the consistent tangent needs at most 9 neighbours")
            local = {v: i for i, v in enumerate(nodes)}
            pq[q, :len(patch)] = patch
            pmask[q, :len(patch)] = 1.0
            pn[q, :len(nodes)] = nodes
            pn[q, len(nodes):] = -1
            pql[q, :len(patch)] = [[local[v] for v in quads[a].tolist()] for a in patch]
            ql[q] = [local[v] for v in row]
            for i, v in enumerate(row):
                member[q, i, :len(patch)] = [float(v in quads[a].tolist()) for a in patch]
        return dict(pq=pq, pmask=pmask, pn=pn, pql=pql, ql=ql, member=member)

    def _normal_forces(self, xs: np.ndarray, xp: np.ndarray, ql: np.ndarray, pql: np.ndarray, pmask: np.ndarray,
                       member: np.ndarray, lam: np.ndarray, area: np.ndarray,
                       tri: np.ndarray | None = None) -> np.ndarray:
        """Normal contact forces (m, 5, 3) [N] on (slave, 4 vertices of its master facet) as functions of
        the slave position xs (m, 3) and the patch vertex positions xp (m, 16, 3), exactly as evaluate()
        computes them for a fixed master facet (projection, interpolated nodal normal, eq. 3.69)."""
        m = len(xs)
        rows = np.arange(m)[:, None]
        quad_x = xp[rows, ql]                                                     # (m, 4, 3)
        point, w = _project(xs, quad_x, tri)
        pq_x = xp[np.arange(m)[:, None, None], pql]                               # (m, 9, 4, 3)
        facet = np.cross(pq_x[:, :, 3] - pq_x[:, :, 0], pq_x[:, :, 2] - pq_x[:, :, 1]) * pmask[:, :, None]
        nodal = np.einsum("mij,mjc->mic", member, facet)
        nodal /= np.linalg.norm(nodal, axis=2)[:, :, None]
        n = (w[:, :, None] * nodal).sum(1)
        n /= np.linalg.norm(n, axis=1)[:, None]
        gap = ((xs - point) * n).sum(1)                                           # eq. 3.25
        p, _ = smooth_ramp(lam - self.params.penalty * gap, self.params.penalty * self.params.smoothing)  # eq. 3.69
        f = (area * p)[:, None] * n
        return np.concatenate([f[:, None, :], -w[:, :, None] * f[:, None, :]], axis=1)

    def _tangential_forces(self, xs: np.ndarray, xp: np.ndarray, xr: np.ndarray, ql: np.ndarray, pql: np.ndarray,
                           pmask: np.ndarray, member: np.ndarray, lam: np.ndarray, lam_T: np.ndarray,
                           ref_w: np.ndarray, area: np.ndarray, slip: np.ndarray,
                           tri: np.ndarray | None = None) -> np.ndarray:
        """Friction forces (m, 5, 3) [N] on (slave, 4 vertices of its reference facet) as functions of the
        slave position xs (m, 3), the patch vertices xp (m, 16, 3) of its current master facet (they set
        the normal n, hence P = 1 - n n^T) and the reference facet vertices xr (m, 4, 3), exactly as
        evaluate() computes them with the friction branch `slip` (m,) fixed (eqs. 3.74-3.75)."""
        m = len(xs)
        quad_x = xp[np.arange(m)[:, None], ql]
        point, w = _project(xs, quad_x, tri)
        pq_x = xp[np.arange(m)[:, None, None], pql]
        facet = np.cross(pq_x[:, :, 3] - pq_x[:, :, 0], pq_x[:, :, 2] - pq_x[:, :, 1]) * pmask[:, :, None]
        nodal = np.einsum("mij,mjc->mic", member, facet)
        nodal /= np.linalg.norm(nodal, axis=2)[:, :, None]
        n = (w[:, :, None] * nodal).sum(1)
        n /= np.linalg.norm(n, axis=1)[:, None]
        P = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
        x_ref = (ref_w[:, :, None] * xr).sum(1)
        trial = np.einsum("mij,mj->mi", P, lam_T - self.params.eps_T * (xs - x_ref))     # eq. 3.74
        if self.params.augmented:
            limit = self.params.friction * lam
        else:
            gap = ((xs - point) * n).sum(1)
            limit = self.params.friction * smooth_ramp(-self.params.penalty * gap,
                                                       self.params.penalty * self.params.smoothing)[0]
        t, _, _ = symmetric_return_map(trial, limit, self.params.eps_T, P, slip.astype(np.int64))  # eq. 3.75
        f = area[:, None] * t
        return np.concatenate([f[:, None, :], -ref_w[:, :, None] * f[:, None, :]], axis=1)

    def _tangential_tangent(self, st: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Consistent tangent of the friction forces by central differences (slave, the 16 patch vertices of
        its current master facet and the 4 vertices of its reference facet: 63 directions, vectorized over
        the active slaves, branch fixed): includes the rotation of the tangent plane P(n) that the closed
        form -A H H D omits (a relative error ~ mu, measured to make Newton stall with the line search
        unable to decrease |R| on the TI unit cell). Returns (rows (m, 15), cols (m, 63), K = -dF/dx)."""
        act = np.flatnonzero(st["active"])
        x = st["x"]
        lam = self.lam_N if self.params.augmented else np.zeros(len(self.slave))
        lam_T = self.lam_T if self.params.augmented else np.zeros((len(self.slave), 3))
        out_rows, out_cols, out_K = [], [], []
        for k, patch in enumerate(self._patches):
            sel = act[self.pair_of_slave[act] == k]
            if len(sel) == 0:
                continue
            q = st["facet"][sel]
            pn = patch["pn"][q]
            xp = x[np.where(pn >= 0, pn, 0)]
            xs = x[self.slave[sel]]
            ref = st["ref_quads"][sel]
            xr = x[ref]
            m = len(sel)
            h = 1e-6 * self.margin  # [m], as in _normal_tangent
            n_dir = 63
            dxs = np.zeros((n_dir, 1, 3))
            dxp = np.zeros((n_dir, 1, 16, 3))
            dxr = np.zeros((n_dir, 1, 4, 3))
            dxs[np.arange(3), 0, np.arange(3)] = h
            dxp[3 + np.arange(48), 0, np.repeat(np.arange(16), 3), np.tile(np.arange(3), 16)] = h
            dxr[51 + np.arange(12), 0, np.repeat(np.arange(4), 3), np.tile(np.arange(3), 4)] = h
            args = [np.tile(patch[key][q], (2 * n_dir,) + (1,) * (patch[key].ndim - 1))
                    for key in ("ql", "pql", "pmask", "member")]
            XS = np.concatenate([xs[None] + dxs, xs[None] - dxs]).reshape(-1, 3)
            XP = np.concatenate([xp[None] + dxp, xp[None] - dxp]).reshape(-1, 16, 3)
            XR = np.concatenate([xr[None] + dxr, xr[None] - dxr]).reshape(-1, 4, 3)
            rep = 2 * n_dir
            F = self._tangential_forces(XS, XP, XR, *args, np.tile(lam[sel], rep), np.tile(lam_T[sel], (rep, 1)),
                                        np.tile(self.ref_weights[sel], (rep, 1)), np.tile(self.area[sel], rep),
                                        np.tile(st["slip"][sel], rep), np.tile(st["tri"][sel], rep))
            F = F.reshape(2, n_dir, m, 15)
            K = -(F[0] - F[1]) / (2.0 * h)                                        # (63, m, 15)
            out_K.append(np.transpose(K, (1, 2, 0)))
            out_rows.append(self._dofs(np.column_stack([self.slave[sel], ref])).reshape(m, 15))
            cols = self._dofs(np.column_stack([self.slave[sel], np.where(pn >= 0, pn, self.slave[sel][:, None]), ref]))
            cols = cols.reshape(m, 63)
            cols[:, 3:51] = np.where(np.repeat(pn >= 0, 3, axis=1), cols[:, 3:51], -1)
            out_cols.append(cols)
        if not out_K:
            return np.zeros((0, 15), np.int64), np.zeros((0, 63), np.int64), np.zeros((0, 15, 63))
        return np.concatenate(out_rows), np.concatenate(out_cols), np.concatenate(out_K)

    def _normal_tangent(self, st: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Consistent tangent of the normal contact forces by central differences over the stencil
        (slave + the 16 patch vertices of its master facet, 51 directions, vectorized over the active
        slaves): includes the rotation of the nodal normals and the sliding of the foot point that the
        closed-form tangent omits. Returns (row dofs (m, 15), column dofs (m, 51), K (m, 15, 51) = -dF/dx)."""
        act = np.flatnonzero(st["active"])
        x = st["x"]
        lam = self.lam_N if self.params.augmented else np.zeros(len(self.slave))
        out_rows, out_cols, out_K = [], [], []
        for k, patch in enumerate(self._patches):
            sel = act[self.pair_of_slave[act] == k]
            if len(sel) == 0:
                continue
            q = st["facet"][sel]
            pn = patch["pn"][q]
            xp = x[np.where(pn >= 0, pn, 0)]
            xs = x[self.slave[sel]]
            m = len(sel)
            h = 1e-6 * self.margin  # [m]: truncation O(h^2) and round-off ~1e-16 |x| / h both far below 1e-6
            n_dir = 51
            dxs = np.zeros((n_dir, 1, 3))
            dxp = np.zeros((n_dir, 1, 16, 3))
            dxs[np.arange(3), 0, np.arange(3)] = h
            dxp[3 + np.arange(48), 0, np.repeat(np.arange(16), 3), np.tile(np.arange(3), 16)] = h
            args = [np.tile(patch[key][q], (2 * n_dir,) + (1,) * (patch[key].ndim - 1))
                    for key in ("ql", "pql", "pmask", "member")]
            XS = np.concatenate([xs[None] + dxs, xs[None] - dxs]).reshape(-1, 3)
            XP = np.concatenate([xp[None] + dxp, xp[None] - dxp]).reshape(-1, 16, 3)
            F = self._normal_forces(XS, XP, *args, np.tile(lam[sel], 2 * n_dir), np.tile(self.area[sel], 2 * n_dir),
                                    np.tile(st["tri"][sel], 2 * n_dir))
            F = F.reshape(2, n_dir, m, 15)
            K = -(F[0] - F[1]) / (2.0 * h)                                        # (51, m, 15)
            out_K.append(np.transpose(K, (1, 2, 0)))
            cur = self.master_quads[k][q]
            out_rows.append(self._dofs(np.column_stack([self.slave[sel], cur])).reshape(m, 15))
            cols = self._dofs(np.column_stack([self.slave[sel], np.where(pn >= 0, pn, self.slave[sel][:, None])]))
            cols = cols.reshape(m, 51)
            cols[:, 3:] = np.where(np.repeat(pn >= 0, 3, axis=1), cols[:, 3:], -1)
            out_cols.append(cols)
        if not out_K:
            return np.zeros((0, 15), np.int64), np.zeros((0, 51), np.int64), np.zeros((0, 15, 51))
        return np.concatenate(out_rows), np.concatenate(out_cols), np.concatenate(out_K)

    # ----------------------------------------------------------------- state
    def positions(self) -> np.ndarray:
        """Current positions x = Phi X + u (n_nodes, 3) of all surface nodes (same on every rank) [m]."""
        values = self.u.x.array.reshape(-1, 3)[self._local_owned]
        u = np.concatenate(self.comm.allgather(values))[self._recv_order]
        x = self.X @ self.Phi.T + u
        if not np.all(np.isfinite(x)):
            raise ValueError("u: the surface positions are not finite (the solve diverged)")
        return x

    def _search(self, x: np.ndarray) -> list[np.ndarray]:
        """Candidate (slave, facet) pairs per contact pair: slave within the facet's circumradius + margin
        of its centroid."""
        out = []
        for k, quads in enumerate(self.master_quads):
            qx = x[quads]
            centroid = qx.mean(axis=1)
            radius = np.linalg.norm(qx - centroid[:, None], axis=2).max(axis=1)
            slaves = np.flatnonzero(self.pair_of_slave == k)
            hits = cKDTree(x[self.slave[slaves]]).query_ball_point(centroid, radius + self.margin)
            counts = np.fromiter(map(len, hits), dtype=np.int64, count=len(hits))
            found = np.fromiter(itertools.chain.from_iterable(hits), dtype=np.int64, count=int(counts.sum()))
            out.append(np.column_stack([slaves[found], np.repeat(np.arange(len(quads)), counts)]))
        return out

    def _candidate_pairs(self, x: np.ndarray) -> list[np.ndarray]:
        if self._candidates is None or np.linalg.norm(x - self._search_x, axis=1).max() > 0.5 * self.margin:
            self._candidates = self._search(x)
            self._search_x = x.copy()
        return self._candidates

    def evaluate(self) -> dict:
        """Contact state at the current u: projections, gaps, tractions and tangents of all slaves."""
        p_ = self.params
        x = self.positions()
        n = len(self.slave)
        facet = np.full(n, -1, dtype=np.int64)
        weights, normal = np.zeros((n, 4)), np.zeros((n, 3))
        point = x[self.slave].copy()
        dist = np.full(n, np.inf)
        for k, cand in enumerate(self._candidate_pairs(x)):
            if len(cand) == 0:
                continue
            s, f = cand[:, 0], cand[:, 1]
            pt, w, _, d = project_onto_quads(x[self.slave[s]], x[self.master_quads[k][f]])
            nodal = _nodal_normals(x, self.master_quads[k])
            nrm = (w[:, :, None] * nodal[self.master_quads[k][f]]).sum(1)  # interpolated nodal normal
            nrm /= np.linalg.norm(nrm, axis=1)[:, None]
            order = np.lexsort((d, s))
            first = order[np.unique(s[order], return_index=True)[1]]
            sel = s[first]
            facet[sel], weights[sel], normal[sel], point[sel], dist[sel] = f[first], w[first], nrm[first], \
                pt[first], d[first]
        if self.frozen_facet is not None:  # fixed sets: a frozen slave projects onto its frozen facet only
            for k, quads in enumerate(self.master_quads):
                sel = np.flatnonzero((self.frozen_facet >= 0) & (self.pair_of_slave == k))
                if len(sel) == 0:
                    continue
                f = self.frozen_facet[sel]
                pt, w, d = project_onto_triangle_planes(x[self.slave[sel]], x[quads[f]], self.frozen_tri[sel])
                nodal = _nodal_normals(x, quads)
                nrm = (w[:, :, None] * nodal[quads[f]]).sum(1)
                nrm /= np.linalg.norm(nrm, axis=1)[:, None]
                facet[sel], weights[sel], normal[sel], point[sel], dist[sel] = f, w, nrm, pt, d
        found = facet >= 0
        gap = np.where(found, ((x[self.slave] - point) * normal).sum(1), np.inf)  # eq. 3.25
        lam_N = self.lam_N if p_.augmented else np.zeros(n)
        z = np.where(found, lam_N - p_.penalty * np.where(found, gap, 0.0), -np.inf)
        pressure, slope = smooth_ramp(z, p_.penalty * p_.smoothing)  # eq. 3.69 (<z> when smoothing = 0)
        active = pressure > 0.0
        # first touch: the reference point is the current projection
        new = active & (self.ref_quad < 0)
        self.ref_quad[new], self.ref_weights[new] = facet[new], weights[new]
        ref_pair_quads = np.zeros((n, 4), dtype=np.int64)
        has_ref = self.ref_quad >= 0
        for k, quads in enumerate(self.master_quads):
            sel = has_ref & (self.pair_of_slave == k)
            ref_pair_quads[sel] = quads[self.ref_quad[sel]]
        x_ref = (self.ref_weights[:, :, None] * x[ref_pair_quads]).sum(1)
        P = np.eye(3)[None] - normal[:, :, None] * normal[:, None, :]
        lam_T = self.lam_T if p_.augmented else np.zeros((n, 3))
        trial = np.einsum("nij,nj->ni", P, lam_T - p_.eps_T * (x[self.slave] - x_ref))       # eq. 3.74
        limit = p_.friction * (self.lam_N if p_.augmented else pressure)                      # [Man2006, Box 7]: mu lambda_N
        traction, D, slip = symmetric_return_map(trial, limit, p_.eps_T, P)                   # eq. 3.75
        traction[~active], D[~active], slip[~active] = 0.0, 0.0, False
        cur_quads = np.zeros((n, 4), dtype=np.int64)
        for k, quads in enumerate(self.master_quads):
            sel = found & (self.pair_of_slave == k)
            cur_quads[sel] = quads[facet[sel]]
        self.state = dict(x=x, facet=facet, weights=weights, normal=normal, gap=gap, pressure=pressure,
                          active=active, traction=traction, D=D, slip=slip, trial=trial, cur_quads=cur_quads,
                          ref_quads=ref_pair_quads, has_ref=has_ref, slope=slope, dist=dist,
                          tri=np.full(n, -1) if self.frozen_tri is None else np.where(self.frozen_facet >= 0,
                                                                                      self.frozen_tri, -1))
        return self.state

    # ----------------------------------------------------------------- assembly
    def _stencil(self, st: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Active slaves' stencil nodes (m, 9) (slave, 4 current master, 4 reference master) and the
        weights G (normal) and H (tangential) (m, 9)."""
        act = np.flatnonzero(st["active"])
        m = len(act)
        nodes = np.column_stack([self.slave[act], st["cur_quads"][act], st["ref_quads"][act]])
        G = np.zeros((m, 9))
        H = np.zeros((m, 9))
        G[:, 0], G[:, 1:5] = 1.0, -st["weights"][act]
        H[:, 0], H[:, 5:9] = 1.0, -self.ref_weights[act]
        return act, nodes, G, H

    def _dofs(self, nodes: np.ndarray) -> np.ndarray:
        """Global scalar dofs (..., 3) of stencil nodes; -1 where constrained."""
        dofs = self.nodes[nodes][..., None] * 3 + np.arange(3)
        return np.where(np.isin(dofs, self.constrained), -1, dofs)

    def nodal_forces(self, st: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(stencil global dofs (m, 27), contact forces on those dofs (m, 27) [N])."""
        st = self.evaluate() if st is None else st
        act, nodes, G, H = self._stencil(st)
        A = self.area[act]
        fN = (A * st["pressure"][act])[:, None] * st["normal"][act]
        fT = A[:, None] * st["traction"][act]
        force = G[:, :, None] * fN[:, None, :] + H[:, :, None] * fT[:, None, :]
        return self._dofs(nodes).reshape(len(act), 27), force.reshape(len(act), 27)

    def add_residual(self, x: PETSc.Vec | None, b: PETSc.Vec) -> None:
        """b -= contact forces on the owned rows (call after the ghost reverse update). ResidualTerm interface
        (fabricfem.solvers.system): the state is read from the Function u, which the solver has set from x."""
        st = self.evaluate()
        dofs, force = self.nodal_forces(st)
        self.dropped_active = int(np.any(dofs < 0, axis=1).sum())
        lo, hi = self.owned_range
        dofs, force = dofs.ravel(), force.ravel()
        mine = (dofs >= lo) & (dofs < hi)
        local = np.zeros(hi - lo)
        np.add.at(local, dofs[mine] - lo, force[mine])
        arr = b.getArray()
        arr[:] -= local
        b.setArray(arr)  # ensures write-back on every vector type

    def add_jacobian(self, x: PETSc.Vec | None, A: PETSc.Mat) -> None:
        """A += contact stiffness on the owned rows (A must be assembled; assembled again here); state from u."""
        st = self.state if self.state is not None else self.evaluate()
        act, nodes, G, H = self._stencil(st)
        area = self.area[act]
        n = st["normal"][act]
        KT = -area[:, None, None] * st["D"][act]
        if self.params.consistent_tangent:  # both parts by finite differences below
            K = np.zeros((len(act), 9, 3, 9, 3))
        else:
            KN = (area * self.params.penalty * st["slope"][act])[:, None, None] * n[:, :, None] * n[:, None, :]
            K = (np.einsum("mj,mk,mab->mjakb", G, G, KN) + np.einsum("mj,mk,mab->mjakb", H, H, KT))
        K = K.reshape(len(act), 27, 27)
        dofs = self._dofs(nodes).reshape(len(act), 27)
        rows = np.broadcast_to(dofs[:, :, None], K.shape).ravel()
        cols = np.broadcast_to(dofs[:, None, :], K.shape).ravel()
        vals = K.ravel()
        if self.params.consistent_tangent:
            for r, c, KN in (self._normal_tangent(st), self._tangential_tangent(st)):
                rows = np.concatenate([rows, np.broadcast_to(r[:, :, None], KN.shape).ravel()])
                cols = np.concatenate([cols, np.broadcast_to(c[:, None, :], KN.shape).ravel()])
                vals = np.concatenate([vals, KN.ravel()])
        lo, hi = self.owned_range
        keep = (rows >= lo) & (rows < hi) & (cols >= 0) & (vals != 0.0)
        csr = sp.coo_matrix((vals[keep], (rows[keep] - lo, cols[keep])), shape=(hi - lo, self.n_global)).tocsr()
        csr.sum_duplicates()
        csr.sort_indices()
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        A.setValuesCSR(csr.indptr.astype(PETSc.IntType), csr.indices.astype(PETSc.IntType), csr.data,
                       addv=PETSc.InsertMode.ADD_VALUES)
        A.assemble()

    # ----------------------------------------------------------------- active-set strategy
    def freeze(self, facet: np.ndarray | None = None, tri: np.ndarray | None = None) -> None:
        """Fix each slave's master facet (-1 = free) and the triangle of it (0: (v0, v1, v3), 1: (v0, v3, v2))
        whose plane the slave is projected on (unclamped, project_onto_triangle_planes) for the following
        Newton solves: the normal gap, the normal and the foot point weights are then smooth in u. By
        default those of the active slaves at the current state (inactive slaves stay free)."""
        if facet is None or tri is None:
            self.unfreeze()
            st = self.evaluate()
            facet = np.where(st["active"], st["facet"], -1) if facet is None else facet
            tri = triangle_of(st["weights"]) if tri is None else tri
        self.frozen_facet = np.asarray(facet, dtype=np.int64).copy()
        self.frozen_tri = np.asarray(tri, dtype=np.int64).copy()
        self.state = None

    def unfreeze(self) -> None:
        """Back to the closest-point projection at every evaluation."""
        self.frozen_facet = None
        self.frozen_tri = None
        self.state = None

    # ----------------------------------------------------------------- augmentation
    def violation(self) -> tuple[float, float]:
        """(max penetration -g over active slaves [m], max stick slip |t* - lambda_T| / eps_T of stick slaves [m])."""
        st = self.evaluate()
        act = st["active"]
        pen = float(np.max(-st["gap"][act], initial=0.0))
        stick = act & ~st["slip"]
        slip = np.linalg.norm(st["traction"][stick] - self.lam_T[stick], axis=1) / self.params.eps_T
        if not self.params.augmented or self.params.friction == 0.0:
            slip = np.zeros(0)
        return max(pen, 0.0), float(np.max(slip, initial=0.0))

    def augment(self) -> None:
        """Uzawa update of the multipliers ([Man2006, Box 7] step 3, eq. 3.79)."""
        st = self.evaluate()
        self.lam_N = st["pressure"].copy()
        limit = self.params.friction * self.lam_N
        t = st["traction"]
        norm = np.linalg.norm(t, axis=1)
        scale = np.where(norm > limit, limit / np.where(norm > 0.0, norm, 1.0), 1.0)
        self.lam_T = t * scale[:, None]                                                      # eq. 3.79

    def commit(self) -> None:
        """After a converged load step: reference points <- current projections, history kept."""
        st = self.evaluate()
        act = st["active"]
        self.ref_quad = np.where(act, st["facet"], -1)
        self.ref_weights = np.where(act[:, None], st["weights"], 0.0)
        self.lam_T = np.where(act[:, None], st["traction"], 0.0) if self.params.augmented else self.lam_T
        self.lam_N = np.where(act, self.lam_N, 0.0)

    def totals(self) -> tuple[np.ndarray, float, float, int, int]:
        """(total force on the slaves (3,) [N], sum A p [N], |sum A t_T| [N], active count, slipping count)."""
        st = self.evaluate()
        act = st["active"]
        fN = (self.area * st["pressure"])[:, None] * st["normal"]
        fT = self.area[:, None] * st["traction"]
        total = (fN + fT)[act].sum(0)
        return (total, float((self.area * st["pressure"]).sum()), float(np.linalg.norm(fT[act].sum(0))),
                int(act.sum()), int((st["slip"] & act).sum()))


MAX_SET_UPDATES = 20  # updates of the fixed sets in one solve_with_fixed_sets
# a fixed facet is kept only while the foot point on its (extended) triangle plane has all weights >= -this:
# at most 5 % of the facet beyond its edge, so the master forces stay on the facet's own nodes
WEIGHT_SLACK = 0.05


def solve_with_fixed_sets(solve_newton, contact: YarnContact, accept, max_updates: int = MAX_SET_UPDATES):
    """Newton with an active-set strategy on the master facets (cf. fabricfem.contact.problem).

    On a faceted master surface the closest facet of a slave node switches where its foot point reaches
    a facet edge or vertex: the contact forces are only piecewise smooth there, and from inside the
    master (a penetrated node) the closest-point map is even discontinuous (the medial axis of the
    polyhedral surface runs through its vertices and edges). Measured on the TI unit cell (E11 0.127 ->
    0.145, first augmentation): 7 slave nodes pressed 13-19 um into the master at its vertices change
    facet at every iterate (one foot point jumping between two edges 2.6 um apart, normal turning by
    2.3 %, distance changing by 7e-8 m) and |R| stalls at 1e-3 of the force scale for 25 iterations.

    Rule: each Newton solve keeps every active slave on a fixed facet, projected onto the plane of a
    fixed triangle of it (`YarnContact.freeze`; unclamped, so the law is smooth in u and the
    finite-difference tangent is consistent with it). From the converged state the set is updated and
    the solve repeated until it no longer changes:
      * a node keeps its facet while the foot point on the plane is a closest point within the
        penetration tolerance (distance <= closest distance + contact.params.tolerance, the accuracy to
        which the augmented Lagrangian resolves the gap anyway) and lies on the facet up to WEIGHT_SLACK;
        otherwise, and for a newly active node, the closest facet and its triangle are taken.
    The friction branch is NOT fixed: the Coulomb test |t*| > mu lambda_N is applied at every evaluation
    (fixing it was tried: a node held on the slip branch while |t*| < mu lambda_N keeps a traction of
    full size along t* / |t*| with a tangent ~ 1 / |t*|, and Newton then stalled at 0.2 of the force
    scale on the crossed cylinders of fabricfem.verify.yarn_contact, where the free branch converges).
    A converged state is accepted at once when the residual of the unfixed law passes `accept()`. When
    the set does not change any more, Newton on the unfixed law is tried from there (`solve_newton` with
    the contact unfrozen: it converges in a few iterations where that law is smooth near the solution,
    and then gives the same state on every partition up to round-off, which the tie rule alone does
    not: measured 5e-6 relative in S between 2 ranks and serial); if it fails, the fixed-set state is
    restored and accepted: an equilibrium (|R| below the Newton tolerance) of the law with every foot
    point closest within the tolerance and every node on its Coulomb branch.

    solve_newton() -> NewtonResult; accept() -> bool, called with the contact unfrozen (it must evaluate
    the residual, e.g. |R| <= rtol force_scale). Returns a NewtonResult (iterations summed over the
    solves; reason DIVERGED_ACTIVE_SET if the set still changes after max_updates updates). The contact
    is left unfrozen; contact.set_updates lists the number of slaves whose facet changed at each update,
    contact.accepted_sets = (facet, triangle, why) the set of the accepted state."""
    iterations, norms = 0, []
    contact.set_updates = []
    try:
        contact.freeze()
        for _ in range(max_updates + 1):
            facet, tri = contact.frozen_facet.copy(), contact.frozen_tri.copy()
            result = solve_newton()
            iterations += result.iterations
            norms += list(result.residual_norms)
            if not result.converged:
                return NewtonResult(False, iterations, result.reason, norms)
            fixed = contact.evaluate()  # the fixed-set law at the converged state
            contact.unfreeze()
            free = contact.evaluate()   # closest-point projection
            act = free["active"] | fixed["active"]
            keep = (act & (facet >= 0) & (fixed["dist"] <= free["dist"] + contact.params.tolerance)
                    & (fixed["weights"].min(axis=1) >= -WEIGHT_SLACK))
            new_facet = np.where(keep, facet, np.where(free["active"], free["facet"], -1))
            new_tri = np.where(keep, tri, triangle_of(free["weights"]))
            changed = act & ((new_facet != facet) | ((new_tri != tri) & (new_facet >= 0)))
            if accept():
                contact.accepted_sets = (facet, tri, "unfixed residual")
                return NewtonResult(True, iterations, result.reason, norms)
            if not changed.any():
                # polish: Newton on the unfixed law from here (a few iterations where it is smooth, and the same
                # state on every partition up to round-off); if it fails, the fixed-set equilibrium stands
                saved = contact.u.x.array.copy()
                polish = solve_newton()
                iterations += polish.iterations
                norms += list(polish.residual_norms)
                if polish.converged:
                    contact.accepted_sets = (facet, tri, "unfixed law (polished)")
                    return NewtonResult(True, iterations, polish.reason, norms)
                contact.u.x.array[:] = saved
                contact.accepted_sets = (facet, tri, "set unchanged")
                return NewtonResult(True, iterations, result.reason, norms)
            contact.set_updates.append(int(changed.sum()))
            contact.freeze(new_facet, new_tri)
        return NewtonResult(False, iterations, "DIVERGED_ACTIVE_SET", norms)
    finally:
        contact.unfreeze()


def solve_with_contact(solve_newton, contact: YarnContact, step: int = 0) -> ContactReport:
    """[Man2006, Box 7] outer loop for one load step: Newton solve with fixed multipliers (`solve_newton()` returns a
    NewtonResult), then Uzawa augmentation until the penetration and stick slip are below the tolerance.
    Raises SolverError if Newton fails or the augmentations do not converge.

    Penalty growth (the method of multipliers with increasing penalty, Bertsekas 1982, sec. 2.2): on a convex
    problem the Uzawa update contracts for any eps_N, but where the tangent is indefinite (the crushed crossing
    of the TI unit cell) the violation can grow at every update (measured: x1.07-1.15 per update for 15
    updates, from 1.1e-7 m to 8.6e-7 m, at E11 = 0.141 of the biaxial path). When max(penetration, stick slip)
    has grown in two successive augmentations, eps_N and eps_T are multiplied by `penalty_growth` before the
    next update ([Man2006, Box 7] allows eps to change between augmentations: the multipliers carry the pressure)."""
    p_ = contact.params
    iterations, violations, growths = [], [], 0
    for k in range(p_.max_augmentations + 1):
        result = solve_newton()
        iterations.append(result.iterations)
        if not result.converged:
            raise SolverError(f"yarn contact: Newton {result.reason} after {result.iterations} iterations in "
                              f"augmentation {k} of load step {step}; residual norms "
                              f"{[f'{r:.3g}' for r in result.residual_norms]}", reason=result.reason)
        pen, slip = contact.violation()
        if not p_.augmented or (pen <= p_.tolerance and slip <= p_.tolerance):
            break
        if k == p_.max_augmentations:
            raise SolverError(f"yarn contact: penetration {pen:.3g} m / stick slip {slip:.3g} m still above the "
                              f"tolerance {p_.tolerance:.3g} m after {k} augmentations at load step {step}",
                              reason="DIVERGED_AUGMENTATION")
        violations.append(max(pen, slip))
        if p_.penalty_growth > 1.0 and len(violations) >= 3 and violations[-1] > violations[-2] > violations[-3]:
            q = contact.params
            contact.params = dataclasses.replace(q, penalty=q.penalty * p_.penalty_growth, tangential_penalty=(
                None if q.tangential_penalty is None else q.tangential_penalty * p_.penalty_growth))
            growths += 1
            violations.clear()
        contact.augment()
    total, fN, fT, active, slipping = contact.totals()
    report = ContactReport(augmentations=k, max_penetration=pen, max_stick_slip=slip, force=total,
                           normal_force=fN, tangential_force=fT, active=active, slipping=slipping,
                           newton_iterations=iterations, dropped_active=contact.dropped_active,
                           penalty_growths=growths)
    contact.commit()
    return report
