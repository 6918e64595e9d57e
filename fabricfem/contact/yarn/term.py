"""The distributed yarn contact term `YarnContact`: node-to-surface frictional contact between the yarns of one
dolfinx mesh, a ResidualTerm (fabricfem.solvers.system: add_residual, add_jacobian, commit) with the state,
active-set and augmentation steps of [Man2006, Box 7] (fabricfem.contact.yarn, package docstring). Units: m, N, Pa.
"""
from __future__ import annotations

from functools import partial
from typing import Sequence

import dolfinx.fem as fem
import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from fabricfem.contact.yarn.geometry import (
    candidate_pairs,
    facet_patches,
    interpolated_normal,
    project_onto_quads,
    project_onto_triangle_planes,
    triangle_of,
)
from fabricfem.contact.yarn.law import (
    ContactParameters,
    normal_forces,
    smooth_ramp,
    symmetric_return_map,
    tangential_forces,
)
from fabricfem.contact.yarn.surface import gather_surfaces, lumped_areas
from fabricfem.contact.yarn.tangent import central_difference, closed_form

__all__ = ["YarnContact"]


def _triplets(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols, values) of element matrices K (m, r, c) with row dofs (m, r) and column dofs (m, c)."""
    rows = np.concatenate([np.broadcast_to(r[:, :, None], K.shape).ravel() for r, _, K in parts])
    cols = np.concatenate([np.broadcast_to(c[:, None, :], K.shape).ravel() for _, c, K in parts])
    return rows, cols, np.concatenate([K.ravel() for _, _, K in parts])


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
        self._check_arguments(u, pairs, parameters)
        V = u.function_space
        self.u, self.params, self.comm = u, parameters, V.mesh.comm
        self.bs = V.dofmap.index_map_bs
        self.Phi = np.eye(3)
        imap = V.dofmap.index_map
        self.owned_range = np.array(imap.local_range, dtype=np.int64) * self.bs
        self.n_global = imap.size_global * self.bs
        self._surfaces = gather_surfaces(V, facet_tags, sorted({int(t) for pair in pairs for t in pair}))
        self.nodes = self._surfaces.nodes  # global dof blocks of all surface nodes, sorted
        self.X = self._surfaces.X  # their reference positions [m]
        self._set_pairs(pairs)
        constrained = np.zeros(0, dtype=np.int64) if constrained_dofs is None else np.asarray(constrained_dofs,
                                                                                             dtype=np.int64)
        self.constrained = np.unique(np.concatenate(self.comm.allgather(constrained)))
        self._reset_state()

    @staticmethod
    def _check_arguments(u: fem.Function, pairs: Sequence[tuple[int, int]], parameters: ContactParameters) -> None:
        """ValueError on a wrong parameters type, no or a self pair, or u not a 3-vector on a 3D mesh."""
        if not isinstance(parameters, ContactParameters):
            raise ValueError("parameters must be a ContactParameters")
        if not pairs:
            raise ValueError("pairs must contain at least one (slave tag, master tag) pair")
        if u.function_space.dofmap.index_map_bs != 3 or u.function_space.mesh.geometry.dim != 3:
            raise ValueError("u must be a 3-component vector Function on a 3D mesh")
        for s, m in pairs:
            if s == m:
                raise ValueError(f"pairs: slave and master tag must differ, got ({s}, {m})")

    def _set_pairs(self, pairs: Sequence[tuple[int, int]]) -> None:
        """Slave nodes of every pair with their lumped reference areas, the master facets with their patches
        (the consistent tangent's stencils) and the search margin (default the median master facet edge)."""
        quads = self._surfaces.quads
        slaves = [np.unique(quads[s]) for s, _ in pairs]
        self.pairs = [(int(s), int(m)) for s, m in pairs]
        self.slave = np.concatenate(slaves)
        self.area = np.concatenate([lumped_areas(self.X, quads[s])[nodes] for (s, _), nodes in zip(pairs, slaves)])
        self.pair_of_slave = np.concatenate([np.full(len(nodes), k) for k, nodes in enumerate(slaves)])
        self.master_quads = [quads[m] for _, m in pairs]  # per pair (m_k, 4) indices into self.nodes
        self._patches = [facet_patches(q) for q in self.master_quads]
        edges = np.concatenate([np.linalg.norm(self.X[q] - self.X[np.roll(q, 1, axis=1)], axis=2).ravel()
                                for q in self.master_quads])
        self.margin = float(np.median(edges)) if self.params.margin is None else float(self.params.margin)

    def _reset_state(self) -> None:
        """No contact history: zero multipliers, no reference points, no search, no fixed sets."""
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

    # ----------------------------------------------------------------- state
    def positions(self) -> np.ndarray:
        """Current positions x = Phi X + u (n_nodes, 3) of all surface nodes (same on every rank) [m]."""
        u = self._surfaces.gather(self.u.x.array.reshape(-1, 3), self.comm)
        x = self.X @ self.Phi.T + u
        if not np.all(np.isfinite(x)):
            raise ValueError("u: the surface positions are not finite (the solve diverged)")
        return x

    def _candidate_pairs(self, x: np.ndarray) -> list[np.ndarray]:
        """Verlet list: the candidates of the last global search, repeated once a node moved > margin / 2."""
        if self._candidates is None or np.linalg.norm(x - self._search_x, axis=1).max() > 0.5 * self.margin:
            self._candidates = candidate_pairs(x, self.slave, self.pair_of_slave, self.master_quads, self.margin)
            self._search_x = x.copy()
        return self._candidates

    def _foot_points(self, x: np.ndarray) -> tuple[np.ndarray, ...]:
        """(master facet (n,) (-1: none), weights (n, 4), normal (n, 3), foot point (n, 3) [m], distance (n,) [m])
        of every slave: the closest candidate facet, or the plane of its frozen triangle when frozen."""
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
            nrm = interpolated_normal(x, self.master_quads[k], f, w)
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
                facet[sel], weights[sel], normal[sel], point[sel], dist[sel] = f, w, interpolated_normal(
                    x, quads, f, w), pt, d
        return facet, weights, normal, point, dist

    def _pair_quads(self, facet: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Vertices (n, 4) (indices into nodes) of each slave's facet `facet` of its pair where valid, else 0."""
        out = np.zeros((len(self.slave), 4), dtype=np.int64)
        for k, quads in enumerate(self.master_quads):
            sel = valid & (self.pair_of_slave == k)
            out[sel] = quads[facet[sel]]
        return out

    def evaluate(self) -> dict:
        """Contact state at the current u: projections, gaps, tractions and tangents of all slaves."""
        p_ = self.params
        x = self.positions()
        n = len(self.slave)
        facet, weights, normal, point, dist = self._foot_points(x)
        found = facet >= 0
        gap = np.where(found, ((x[self.slave] - point) * normal).sum(1), np.inf)  # eq. 3.25
        lam_N = self.lam_N if p_.augmented else np.zeros(n)
        z = np.where(found, lam_N - p_.penalty * np.where(found, gap, 0.0), -np.inf)
        pressure, slope = smooth_ramp(z, p_.penalty * p_.smoothing)  # eq. 3.69 (<z> when smoothing = 0)
        active = pressure > 0.0
        # first touch: the reference point is the current projection
        new = active & (self.ref_quad < 0)
        self.ref_quad[new], self.ref_weights[new] = facet[new], weights[new]
        has_ref = self.ref_quad >= 0
        ref_pair_quads = self._pair_quads(self.ref_quad, has_ref)
        x_ref = (self.ref_weights[:, :, None] * x[ref_pair_quads]).sum(1)
        P = np.eye(3)[None] - normal[:, :, None] * normal[:, None, :]
        lam_T = self.lam_T if p_.augmented else np.zeros((n, 3))
        trial = np.einsum("nij,nj->ni", P, lam_T - p_.eps_T * (x[self.slave] - x_ref))       # eq. 3.74
        limit = p_.friction * (self.lam_N if p_.augmented else pressure)       # [Man2006, Box 7]: mu lambda_N
        traction, D, slip = symmetric_return_map(trial, limit, p_.eps_T, P)                   # eq. 3.75
        traction[~active], D[~active], slip[~active] = 0.0, 0.0, False
        self.state = dict(x=x, facet=facet, weights=weights, normal=normal, gap=gap, pressure=pressure,
                          active=active, traction=traction, D=D, slip=slip, trial=trial,
                          cur_quads=self._pair_quads(facet, found), ref_quads=ref_pair_quads, has_ref=has_ref,
                          slope=slope, dist=dist,
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

    def _consistent_tangent(self, st: dict, friction: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Consistent tangent of the normal (friction False) or friction forces by central differences of the
        exact element forces (law.normal_forces / law.tangential_forces, branch fixed) over the stencil of
        every active slave: the slave and the 16 patch vertices of its current master facet (51 directions),
        for friction also the 4 vertices of its reference facet (63). Includes the rotation of the nodal
        normals and of the tangent plane P(n) and the sliding of the foot point, which the closed form omits
        (relative errors ~ p / (eps_N h) and ~ mu; the latter measured to make Newton stall with the line
        search unable to decrease |R| on the TI unit cell). Returns (row dofs (m, 15), column dofs (m, 51 or 63),
        K (m, 15, 51 or 63) = -dF/dx [N/m]); rows: slave + current master facet (normal) or reference facet."""
        act = np.flatnonzero(st["active"])
        x = st["x"]
        lam = self.lam_N if self.params.augmented else np.zeros(len(self.slave))
        lam_T = self.lam_T if self.params.augmented else np.zeros((len(self.slave), 3))
        h = 1e-6 * self.margin  # [m]: truncation O(h^2) and round-off ~1e-16 |x| / h both far below 1e-6
        out_rows, out_cols, out_K = [], [], []
        for k, patch in enumerate(self._patches):
            sel = act[self.pair_of_slave[act] == k]
            if len(sel) == 0:
                continue
            q = st["facet"][sel]
            pn = patch["pn"][q]
            slave = self.slave[sel]
            positions = [x[slave], x[np.where(pn >= 0, pn, 0)]]
            shared = [patch[key][q] for key in ("ql", "pql", "pmask", "member")]
            if friction:
                moved = st["ref_quads"][sel]
                positions.append(x[moved])
                fixed = shared + [lam[sel], lam_T[sel], self.ref_weights[sel], self.area[sel], st["slip"][sel],
                                  st["tri"][sel]]
                K = central_difference(partial(tangential_forces, self.params), positions, fixed, h)
            else:
                moved = self.master_quads[k][q]
                K = central_difference(partial(normal_forces, self.params), positions,
                                       shared + [lam[sel], self.area[sel], st["tri"][sel]], h)
            out_K.append(K)
            out_rows.append(self._dofs(np.column_stack([slave, moved])).reshape(len(sel), 15))
            stencil = [slave, np.where(pn >= 0, pn, slave[:, None])] + ([moved] if friction else [])
            cols = self._dofs(np.column_stack(stencil)).reshape(len(sel), K.shape[2])
            cols[:, 3:51] = np.where(np.repeat(pn >= 0, 3, axis=1), cols[:, 3:51], -1)
            out_cols.append(cols)
        if not out_K:
            n_col = 63 if friction else 51
            return np.zeros((0, 15), np.int64), np.zeros((0, n_col), np.int64), np.zeros((0, 15, n_col))
        return np.concatenate(out_rows), np.concatenate(out_cols), np.concatenate(out_K)

    def add_jacobian(self, x: PETSc.Vec | None, A: PETSc.Mat) -> None:
        """A += contact stiffness on the owned rows (A must be assembled; assembled again here); state from u.
        The closed form (tangent.closed_form), or with params.consistent_tangent the central differences of
        the normal and the friction forces (_consistent_tangent)."""
        st = self.state if self.state is not None else self.evaluate()
        if self.params.consistent_tangent:
            parts = [self._consistent_tangent(st, friction) for friction in (False, True)]
        else:
            act, nodes, G, H = self._stencil(st)
            dofs = self._dofs(nodes).reshape(len(act), 27)
            parts = [(dofs, dofs, closed_form(self.area[act], self.params.penalty, st["slope"][act],
                                              st["normal"][act], st["D"][act], G, H))]
        rows, cols, vals = _triplets(parts)
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
