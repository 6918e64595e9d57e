"""Yarn-yarn frictional contact between hexahedral yarn meshes ([Man2006, sec. 3.2] and 3.4, Box 7).

Modules, one job each: `geometry` (projections onto the master facets, normals, facet patches, the contact
search), `law` (ContactParameters, the return mapping, the element forces), `tangent` (the closed-form tangent and
the one central-difference helper), `surface` (the yarns' surfaces gathered on every rank), `term` (YarnContact,
the distributed ResidualTerm), `solve` (the augmentation and active-set loops of one load step).

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
With `consistent_tangent` both parts are central differences (tangent.central_difference) of the exact
nodal forces over each contact element's stencil instead (normal: slave + the 16 patch vertices of the master facet;
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
from fabricfem.contact.yarn.geometry import (
    closest_point_on_triangles,
    project_onto_quads,
    project_onto_triangle_planes,
    triangle_of,
)
from fabricfem.contact.yarn.law import ContactParameters, smooth_ramp, symmetric_return_map
from fabricfem.contact.yarn.solve import (
    MAX_SET_UPDATES,
    ContactReport,
    solve_with_contact,
    solve_with_fixed_sets,
)
from fabricfem.contact.yarn.term import YarnContact

__all__ = ["ContactParameters", "ContactReport", "YarnContact", "closest_point_on_triangles",
           "project_onto_quads", "smooth_ramp", "symmetric_return_map", "solve_with_contact", "solve_with_fixed_sets",
           "MAX_SET_UPDATES", "project_onto_triangle_planes", "triangle_of"]
