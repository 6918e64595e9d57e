"""Cloth-cloth contact in explicit central differences: a shell's nodes against its own triangles (and those of
every other garment panel in the same mesh), penalty with Coulomb friction ([Bridson2002, sec. 6-7]).

Geometry (fabricfem.contact.cloth_surface, fabricfem.contact.proximity): the Q2 cells split into triangles through
their nodes; every vertex p closer than the contact distance d_c (default the shell's thickness) to a triangle
(a, b, c) that is not a neighbour forms a pair, with x_c = sum_i w_i x_i the closest point (barycentric w) and
delta = |x_p - x_c| [m]. Neighbours: the vertex is a node of the triangle, or the two belong to the same connected
part of the mesh (its cells, joined by the node pairs `joined`, e.g. a garment's seams) and are closer than
EXCLUSION x d_c in the reference (stress-free) configuration, where they touch by construction and contact would
fight the shell's own stiffness. Separate parts (two sheets, two garments) are never neighbours, however close
their reference positions. A vertex and the other triangles of its own cells are not neighbours: a cell folded onto
itself or into the next one within d_c is a fold like any other, and the independent crossing count
(fabricfem.contact.intersections: triangles that share no node) counts it
(docs/findings/2026-11-29-wrapped-pants.md).

Response, in `forces` (before the division of the step; d^{n+1} and v~ = v^n + dt/2 a^n of the integrator):

    n = (x_p - x_c) / delta,      v_rel = v_p - sum_i w_i v_i,      v_N = v_rel . n
    f_N = s < k_N A_p (d_c - delta) - c v_N >,   c = 2 zeta sqrt(s k_N A_p m_eff)     ([Bridson2002, sec. 7.1])
    f_T = -min(mu f_N, m_eff |v_T| / dt) v_T / |v_T|,   v_T = v_rel - v_N n                 ([Bridson2002, sec. 7.2])
    1 / m_eff = 1 / m_p + sum_i w_i^2 / m_i

f = f_N n + f_T acts on p and -w_i f on the triangle's nodes (momentum conserved). k_N [Pa/m] is the penalty of the
body contact (fabricfem.contact.nodal.default_penalty: 10 E t / h^2), A_p the vertex's lumped reference area
[m^2], m the lumped masses (M + dt/2 C) [kg], zeta the damping ratio of the pair's spring (the damping never pulls:
< . > is the positive part). The friction is Coulomb's law mu f_N while the pair slides; the bound m_eff |v_T| / dt
is the force that stops the relative tangential velocity within the step (sticking). s = 1 / (the number of pairs
of p whose closest point lies on the same feature): a vertex above an edge or a node of the other layer is one
contact, not one per triangle around that feature.

Per step (`forces`): the pairs come from a Verlet list (fabricfem.contact.cloth_kernel: the candidates within d_c +
s of the last search, s the skin, default d_c, searched again once a node has moved more than s / 2), the same
pairs as a search at every step; the response runs in C (`cloth_kernel.respond`; `_respond` is its numpy twin).
Velocities are gathered only when there are pairs.

Parallel: every rank gathers the positions and velocities of all nodes (ClothSurface), finds all pairs and computes
all forces, and adds the forces of its owned nodes to its rows, so the pairs across rank boundaries are treated as
on one rank. Several garments (fabricfem.scenes.garments): with `layer` set (each node's garment), the pairs
between two garments a < b are answered by their own call of the response and their normal forces kept in
`between[(a, b)]` (the per-garment monitors, fabricfem.wear.layers); the forces are the same.

Edge-edge pairs (`edges=True`, the default; fabricfem.contact.edge_contact, [Bridson2002, sec. 6]): two edges of the
triangulation that share no node, closer than d_c with their closest points inside both edges, take the same law
with the four nodes' barycentric weights; they hold two layers whose edges cross with no vertex within d_c of the
other's triangles (coarse folds, free edges side by side). Their candidates ride on the same Verlet list (searched
again together), their neighbours are excluded by the same reference rule, their forces go into the same arrays
(and `between`), and `edge_pairs` holds the step's active pairs.

Impulses (`passes` > 0; fabricfem.contact.impulses, [Bridson2002, sec. 7.1-7.2]): after the division (`correct`),
the step's pairs (vertex-triangle and edge-edge, closer than d_c at d^{n+1}) that approach take inelastic impulses
with Coulomb friction on the predicted velocities u = v~ + dt a^{n+1}, in `passes` Gauss-Seidel passes:
a^{n+1} += du / dt. With `body` set (the body contact, whose Lagrange correction then runs before this one), the
nodes it holds on the body this step (its `active` nodes) take no impulse (infinite mass): the layers above them
are pushed off instead of pushing them into the body. The impulses accompany the penalty (which still pushes the
pairs back out to d_c); `impulse` (N, 3) holds the step's normal impulses [N s], `impulse_friction` the friction
ones, `impulse_passes` the passes taken. A pair inside d_c is driven apart at RESTORE_RATE (d_c - delta) (the
impulses' restoring target): on the sleeve flexed to 130 degrees it held the folds to 120 degrees, 116 without.

Impact zones (`zones=True`; fabricfem.contact.impact_zones, [Bridson2002, sec. 7.3-7.4]): after the impulses, the
continuous collision detection of the step x^{n+1} -> x^{n+1} + dt u over the vertex-triangle and edge-edge
candidates (the Verlet list, which holds every pair within d_c at x^{n+1}, when the step's relative motion
2 max |dt u| + eta is below d_c; a search within that motion otherwise), and the nodes of colliding pairs moved as
rigid zones, until the step is collision-free or `zone_iterations` rounds; the nodes held on the body (`body`) are
of infinite mass (a zone containing one moves with them) until a zone still colliding at round
impact_zones.RELEASE_ROUND releases them (not the nodes with a prescribed
component). `zone_report` holds the last step's counts, `zone_totals` their sums
over the run (released_steps: the steps in which a zone released held nodes). SI units.
"""
from __future__ import annotations

import math
import time

import numpy as np
from mpi4py import MPI

from fabricfem.contact import cloth_kernel, edge_contact, impact_zones, impulses, nodal, stitch_groups
from fabricfem.contact import friction as friction_law
from fabricfem.contact.cloth_surface import ClothSurface
from fabricfem.contact.edge_contact import EdgePairs
from fabricfem.contact.proximity import Pairs, compiled_pairs

EXCLUSION = 2.0          # reference distance / d_c below which a vertex and a triangle are neighbours
DEFAULT_DAMPING = 0.5    # zeta of the pair's penalty spring
RESTORE_RATE = 200.0     # 1/s: the impulses' target separation rate r (fabricfem.contact.impulses), 1 / (5 ms)
FEATURE_TOLERANCE = 1e-6  # barycentric coordinates below this name no node of the closest feature
BLOW_UP_SPEED = 1.0e3    # m/s: no point of a garment moves at 1 km/s (3 x sound in air); a faster node has blown up


def checked_contact_distance(value: float | None, thickness: float, element_size: float) -> float:
    """d_c [m]: `value` (default: the shell's `thickness`), refused (ValueError naming `contact_distance`) unless
    0 < d_c <= the mesh size `element_size` [m]."""
    d = thickness if value is None else value
    if isinstance(d, bool) or not (isinstance(d, (int, float)) and math.isfinite(d) and d > 0.0):
        raise ValueError(f"contact_distance must be a positive length [m], got {value!r}")
    if d > element_size:
        raise ValueError(f"contact_distance = {d:g} m exceeds the mesh size {element_size:g} m")
    return float(d)


class SelfContact:
    """Cloth-cloth contact of a shell model as an explicit hook (fabricfem.solvers.system.ExplicitHook; module
    docstring for the law).

    Args:
        model: the ShellModel (quadrilateral Q2 cells; all its panels and garments are one surface).
        contact_distance: d_c [m], default the fabric's thickness; 0 < d_c <= the mesh size.
        friction: Coulomb coefficient mu >= 0 between cloth layers.
        penalty: k_N [Pa/m], default fabricfem.contact.nodal.default_penalty.
        damping: zeta >= 0 of the pair springs.
        joined: (k, 2) global node indices (ClothSurface numbering) of node pairs that make two mesh parts one
            (a garment's seams), for the neighbour rule (module docstring).
        skin: s [m] of the Verlet list (module docstring), default d_c; > 0.
        edges: also the edge-edge pairs (module docstring).
        passes: Gauss-Seidel passes of the velocity-level impulses after the division (module docstring); 0: none.
        zones: the failsafe of continuous collision detection and rigid impact zones after them (module docstring).

    After each step: `force` (N, 3) the contact forces [N] on all nodes (global order of `surface`, every rank),
    `normal_force` / `friction_force` its two parts, `pairs` the active pairs, `timings` [s] accumulated,
    `searches` the number of pair searches (Verlet list rebuilds), `edge_pairs` the active edge-edge pairs (rows of
    `edges`, the (E, 2) global node indices of the triangulation's edges).
    """

    def __init__(self, model, contact_distance: float | None = None, friction: float = 0.0,
                 penalty: float | None = None, damping: float = DEFAULT_DAMPING, joined: np.ndarray | None = None,
                 skin: float | None = None, edges: bool = True, passes: int = 0, zones: bool = False):
        self.model = model
        self.passes = impulses.checked_passes(passes)
        if not isinstance(zones, (bool, np.bool_)):
            raise ValueError(f"impact_zones must be true or false, got {zones!r}")
        self.zones = bool(zones)
        self.zone_iterations = impact_zones.DEFAULT_ITERATIONS
        self.zone_report: dict = {}
        self.zone_totals = {"steps": 0, "collisions": 0, "unresolved_steps": 0, "rounds": 0, "most_left": 0,
                            "released_steps": 0}
        self.comm = model.comm
        self.surface = ClothSurface(model)
        self.distance = checked_contact_distance(contact_distance, model.fabric.thickness,
                                                 self.surface.nodes.element_size)
        self.mu = friction_law.friction_coefficient(friction)
        self.penalty = (nodal.default_penalty(model, self.surface.nodes.element_size) if penalty is None
                        else nodal.positive_parameter("penalty", penalty))
        if isinstance(damping, bool) or not (isinstance(damping, (int, float)) and damping >= 0.0):
            raise ValueError(f"damping must be a number >= 0, got {damping!r}")
        self.damping = float(damping)
        s = self.surface
        self.part = s.parts(joined)
        self.use_edges = bool(edges)
        self.edges = edge_contact.surface_edges(s.triangles)
        self.stitched = s.stitched(joined)   # (N,) one label per point of the cloth (a seam's stitched nodes)
        self._star = stitch_groups.star_pairs(self.stitched, s.held)   # the groups kept together in `correct`
        seam_pairs, seam_edge_pairs = seam_neighbours(s, self.stitched, self.edges)
        near = self.search(s.reference, EXCLUSION * self.distance)
        same = self.part[near.vertex] == self.part[s.triangles[near.triangle, 0]]
        self._excluded = np.union1d(self._keys(near.subset(same)), seam_pairs)
        near_edges = self.search_edges(s.reference, EXCLUSION * self.distance, interior=False)
        same = self.part[self.edges[near_edges.first, 0]] == self.part[self.edges[near_edges.second, 0]]
        self._excluded_edges = np.union1d(near_edges.subset(same).keys(len(self.edges)), seam_edge_pairs)
        self._inverse_area = np.ascontiguousarray(np.where(s.held, 0.0, 1.0 / s.area))
        self.edge_pairs = self._edge_candidates = edge_contact.no_edge_pairs()
        N = s.count
        self.force, self.normal_force, self.friction_force = np.zeros((N, 3)), np.zeros((N, 3)), np.zeros((N, 3))
        self.pairs = Pairs(*(np.zeros(0, dtype=np.int64),) * 2, np.zeros(0), np.zeros((0, 3)))
        self._mass: tuple[object, float, np.ndarray] | None = None
        self._finite_mass = np.ones(N)       # the lumped masses [kg], finite also for held nodes (impact zones)
        self.timings = {"gather": 0.0, "search": 0.0, "response": 0.0, "impulses": 0.0, "zones": 0.0}
        self.impulse, self.impulse_friction = np.zeros((N, 3)), np.zeros((N, 3))
        self.impulse_passes = 0              # the passes taken in the last step
        self._x: np.ndarray | None = None    # the positions [m] of the last step's `forces` (d^{n+1}), None before
        self._ranks = impulses.node_ranks(s.reference)   # the pairs' sweep order (fabricfem.contact.impulses)
        self.restore_rate = RESTORE_RATE if self.passes else 0.0   # 1/s (fabricfem.contact.impulses)
        self.body = None     # the body contact (ExplicitBodyContact) whose active nodes the impulses hold
        self.skin = self.distance if skin is None else nodal.positive_parameter("skin", skin)
        self._candidates: Pairs | None = None
        self._searched_at = np.zeros((N, 3))
        self.searches = 0
        self._triangles = np.ascontiguousarray(s.triangles, dtype=np.int64)
        self.layer: np.ndarray | None = None     # (N,) garment of every node (several garments), else None
        self.between: dict[tuple[int, int], np.ndarray] = {}   # (a, b) -> (N, 3) normal forces [N] between them

    def penalty_frequency(self) -> float:
        """omega_p = sqrt(4 k_N / (rho t)) [rad/s]: the pair spring on the reduced mass of two nodes (factor 2), a
        node both a vertex and a triangle's node (factor 2); add it to the step's frequency as the body contact's.
        An edge-edge pair's spring has at most half this frequency (fabricfem.contact.edge_contact); not added."""
        return float(np.sqrt(4.0 * self.penalty / self.model.fabric.areal_density))

    def limit_frequency(self, omega: float) -> None:
        """Lower k_N (never raise it) so that `penalty_frequency()` <= omega [rad/s]: k_N <= rho t omega^2 / 4 [Pa/m]
        (a penalty that leaves the critical step of the shell alone)."""
        self.penalty = min(self.penalty, self.model.fabric.areal_density * omega ** 2 / 4.0)

    def search(self, x: np.ndarray, radius: float | None = None) -> Pairs:
        """The vertex-triangle pairs of the positions x (N, 3) [m] closer than `radius` (default d_c), the vertex not
        a node of the triangle (fabricfem.contact.proximity.compiled_pairs)."""
        s = self.surface
        return compiled_pairs(x, s.triangles, s.triangle_index, s.triangles,
                              self.distance if radius is None else radius, self.comm)

    def search_edges(self, x: np.ndarray, radius: float | None = None, interior: bool = True) -> EdgePairs:
        """The edge-edge pairs of the positions x (N, 3) [m] closer than `radius` (default d_c) that share no node;
        with `interior` only those that take contact (fabricfem.contact.edge_contact.compiled_pairs)."""
        return edge_contact.compiled_pairs(x, self.edges, self.distance if radius is None else radius,
                                           FEATURE_TOLERANCE, self.comm, interior)

    def _keys(self, pairs: Pairs) -> np.ndarray:
        return pairs.vertex * len(self.surface.triangles) + pairs.triangle

    def contact_pairs(self, x: np.ndarray, radius: float | None = None) -> Pairs:
        """`search` without the reference neighbours (module docstring): the pairs that take contact."""
        pairs = self.search(x, radius)
        return pairs.subset(~_member(self._keys(pairs), self._excluded))

    def contact_edge_pairs(self, x: np.ndarray, radius: float | None = None, interior: bool = True) -> EdgePairs:
        """`search_edges` without the reference neighbours (module docstring)."""
        pairs = self.search_edges(x, radius, interior)
        return pairs.subset(~_member(pairs.keys(len(self.edges)), self._excluded_edges))

    def near_pairs(self, x: np.ndarray) -> Pairs:
        """The pairs closer than d_c at the positions x (N, 3) [m] that take contact, from the Verlet list
        (module docstring; the same pairs as `contact_pairs(x)`), grouped by vertex."""
        x = np.ascontiguousarray(x, dtype=float)
        pairs = None
        if self._candidates is not None:
            pairs = cloth_kernel.narrow(x, self._searched_at, 0.5 * self.skin, self._candidates, self._triangles,
                                        self.distance, self.comm)
        if pairs is None:
            self._candidates = self.contact_pairs(x, self.distance + self.skin)
            if self.use_edges:
                self._edge_candidates = self.contact_edge_pairs(x, self.distance + self.skin, interior=False)
            self._searched_at = x.copy()
            self.searches += 1
            pairs = cloth_kernel.narrow(x, x, 0.0, self._candidates, self._triangles, self.distance, self.comm)
        if self.use_edges:
            self.edge_pairs = edge_contact.narrow(x, self._edge_candidates, self.edges, self.distance,
                                                  FEATURE_TOLERANCE, self.comm)
        return pairs

    def _masses(self, integrator) -> tuple[np.ndarray, np.ndarray]:
        """(N,) lumped translational mass (M + dt/2 C) [kg] of all nodes, inf for a node with a held component, and
        its inverse [1/kg] (0 there)."""
        cached = self._mass
        if cached is None or cached[0] is not integrator or cached[1] != integrator.dt:
            s = self.surface
            m = integrator.denominator.getArray(readonly=True)[s.nodes.dofs[:, 0]]
            mass = s.gather(m[:, None])[:, 0]
            self._finite_mass = mass.copy()
            mass[s.held] = np.inf
            self._mass = cached = (integrator, integrator.dt, (mass, np.ascontiguousarray(1.0 / mass)))
        return cached[2]

    # ------------------------------------------------------------------ integrator hooks
    def forces(self, integrator, t: float, rhs) -> None:
        """rhs += the contact forces at d^{n+1} (owned rows; module docstring). A node that moved faster than
        BLOW_UP_SPEED [m/s] since the last step raises ValueError (`_check_speed`) before the broad phase: a
        blown-up state that stays finite would put every triangle into one hash cell."""
        s = self.surface
        tic = time.perf_counter()
        rows = s.nodes.dofs
        x = s.gather(s.nodes.reference + integrator.d.getArray(readonly=True)[rows])
        if self._x is not None:
            _check_speed((x - self._x) / integrator.dt, "step motion / dt (the step diverged before it)", t)
        toc = time.perf_counter()
        had_pairs = len(self.pairs) + len(self.edge_pairs) > 0
        self.pairs = pairs = self.near_pairs(x)
        self._x = x
        edge_pairs = self.edge_pairs
        tac = time.perf_counter()
        if len(pairs) or len(edge_pairs) or had_pairs:
            for buffer in (self.force, self.normal_force, self.friction_force):
                buffer.fill(0.0)
        self.between = {}
        if len(pairs) or len(edge_pairs):      # the same counts on every rank (all search the gathered surface)
            vel = s.gather(integrator.velocity_predictor.getArray(readonly=True)[rows])
            mass, inverse = self._masses(integrator)
            law = (self.penalty, self.distance, self.damping, self.mu, integrator.dt, FEATURE_TOLERANCE)
            share = edge_contact.shares(edge_pairs, self.edges, self.surface.count)
            if self.layer is None:
                cloth_kernel.respond(pairs, self._triangles, x, vel, inverse, self.surface.area, law,
                                     self.normal_force, self.friction_force, self.comm)
                edge_contact.respond(edge_pairs, share, self.edges, x, vel, inverse, self._inverse_area, law[:5],
                                     self.normal_force, self.friction_force, self.comm)
            else:
                self._respond_by_layers(pairs, edge_pairs, share, x, vel, inverse, law)
            np.add(self.normal_force, self.friction_force, out=self.force)
            rhs.getArray()[rows] += s.owned_rows(self.force)
        self.timings["gather"] += toc - tic
        self.timings["search"] += tac - toc
        self.timings["response"] += time.perf_counter() - tac

    def _respond_by_layers(self, pairs: Pairs, edge_pairs: EdgePairs, share: np.ndarray, x: np.ndarray,
                           vel: np.ndarray, inverse: np.ndarray, law: tuple) -> None:
        """The pairs' forces as `cloth_kernel.respond` and `edge_contact.respond` give them, those between two
        garments (node labels `layer`, a < b) also kept apart: their normal forces [N] in `between[(a, b)]` (N, 3).
        A vertex's pairs on one feature stay together (the feature's nodes belong to one garment), so the feature
        share is unchanged; the edge pairs' shares are those of all edge pairs (`share`)."""
        lo, hi = _layer_pair(self.layer[pairs.vertex], self.layer[self._triangles[pairs.triangle, 0]])
        edge_lo, edge_hi = _layer_pair(self.layer[self.edges[edge_pairs.first, 0]],
                                       self.layer[self.edges[edge_pairs.second, 0]])
        garments = set(zip(lo[lo != hi].tolist(), hi[lo != hi].tolist()))
        garments |= set(zip(edge_lo[edge_lo != edge_hi].tolist(), edge_hi[edge_lo != edge_hi].tolist()))
        groups = [((lo == hi), (edge_lo == edge_hi), None)]
        groups += [((lo == a) & (hi == b), (edge_lo == a) & (edge_hi == b), (a, b)) for a, b in sorted(garments)]
        for vertex_triangle, edge_edge, key in groups:
            normal, friction = np.zeros_like(self.normal_force), np.zeros_like(self.friction_force)
            cloth_kernel.respond(pairs.subset(vertex_triangle), self._triangles, x, vel, inverse, self.surface.area,
                                 law, normal, friction, self.comm)
            edge_contact.respond(edge_pairs.subset(edge_edge), share[edge_edge], self.edges, x, vel, inverse,
                                 self._inverse_area, law[:5], normal, friction, self.comm)
            self.normal_force += normal
            self.friction_force += friction
            if key is not None:
                self.between[key] = normal

    def correct(self, integrator, t: float) -> None:
        """With `passes` > 0: the impulses of the step's pairs on u = v~ + dt a^{n+1}; with `zones`, then the impact
        zones of the step's collisions; a^{n+1} += du / dt on the owned rows (module docstring; every rank computes
        all, as the forces). A velocity [m/s] entering or leaving the correction that is non-finite or faster than
        BLOW_UP_SPEED raises ValueError naming the stage, the time t [s] and the node (every rank alike: the
        velocities are gathered), so the run stops with that reason instead of carrying NaN into the next step."""
        has_pairs = len(self.pairs) or len(self.edge_pairs)
        zones = self.zones and self._may_collide(integrator)
        self.impulse_passes = 0
        if not zones and (not self.passes or not has_pairs):
            return
        tic = time.perf_counter()
        s, dt = self.surface, integrator.dt
        rows = s.nodes.dofs
        a = integrator.a.getArray()
        u0 = s.gather(integrator.velocity_predictor.getArray(readonly=True)[rows] + dt * a[rows])
        _check_speed(u0, "predicted velocities entering the cloth-cloth correction (the step diverged before it)", t)
        u = u0.copy()
        _, inverse = self._masses(integrator)
        if self.body is not None:
            on_body = np.zeros(len(s.nodes.dofs))
            on_body[self.body.moving] = self.body.active
            inverse = np.where(s.gather(on_body[:, None])[:, 0] > 0.0, 0.0, inverse)
        sewn = stitch_groups.closed(self._star, self._x, s.nodes.element_size)
        if self.passes and has_pairs:
            pairs, edge_pairs = impulses.canonical(self.pairs, self.edge_pairs, self._triangles, self.edges,
                                                   self._ranks)
            self.impulse, self.impulse_friction, _, self.impulse_passes = impulses.apply(
                pairs, edge_pairs, self._triangles, self.edges, self._x, u, inverse, self.distance, self.mu,
                self.passes, self.comm, self.restore_rate)
            stitch_groups.weld(u, u0, sewn, self._finite_mass, inverse == 0.0)
            _check_speed(u, "velocities after the cloth-cloth impulses", t)
        toc = time.perf_counter()
        self.timings["impulses"] += toc - tic
        if zones:
            self._impact_zones(u, inverse, dt, sewn)
            stitch_groups.weld(u, u0, sewn, self._finite_mass, inverse == 0.0)
            _check_speed(u, "velocities after the impact zones", t)
            self.timings["zones"] += time.perf_counter() - toc
        a[rows] += s.owned_rows((u - u0) / dt)

    def _may_collide(self, integrator) -> bool:
        """False only when no candidate pair is listed and no node moves by d_c / 2 - eta within the step (then no
        pair can collide: module docstring); the same answer on every rank; True for a non-finite velocity (which
        `correct` then reports)."""
        if self._candidates is None or len(self._candidates) or len(self._edge_candidates) or not self.use_edges:
            return True
        rows, dt = self.surface.nodes.dofs, integrator.dt
        a = integrator.a.getArray(readonly=True)
        u = integrator.velocity_predictor.getArray(readonly=True)[rows] + dt * a[rows]
        local = float(np.sqrt((u * u).sum(axis=1).max(initial=0.0)))
        fastest = self.comm.allreduce(local if math.isfinite(local) else math.inf, op=MPI.MAX)   # NaN: checked
        return 2.0 * dt * fastest + impact_zones.TOLERANCE * self.distance >= self.distance

    def _impact_zones(self, u: np.ndarray, inverse: np.ndarray, dt: float, sewn: np.ndarray) -> None:
        """The detection and rigid zones of fabricfem.contact.impact_zones on u (N, 3) [m/s] in place, from the
        step's positions `_x`; candidates: the Verlet list while it covers the step's motion, else a search within
        1.5 times that motion, at most the mesh size (a node moving further in one step: pairs missed); `sewn`: the
        stitched groups a zone takes whole (fabricfem.contact.stitch_groups)."""
        x, eta = self._x, impact_zones.TOLERANCE * self.distance
        searched: dict[float, tuple] = {}

        def candidates(velocity: np.ndarray) -> tuple:
            reach = 2.0 * dt * float(np.sqrt((velocity * velocity).sum(axis=1).max(initial=0.0))) + eta
            if self.use_edges and self._candidates is not None and reach < self.distance:
                pairs, edge_pairs = self._candidates, self._edge_candidates
            else:
                cap = self.surface.nodes.element_size      # the search's largest radius (memory)
                radius = max([r for r in searched if r >= min(reach, cap)], default=None)
                if radius is None:
                    radius = min(1.5 * reach, cap)
                    searched[radius] = (self.contact_pairs(x, radius),
                                        self.contact_edge_pairs(x, radius, interior=False))
                pairs, edge_pairs = searched[radius]
            return pairs.vertex, pairs.triangle, self._triangles, edge_pairs.first, edge_pairs.second, self.edges

        # a node with a prescribed component is never released: the integrator imposes its motion whatever u says
        report = impact_zones.resolve(candidates, x, u, dt, self._finite_mass, inverse == 0.0, eta,
                                      self.zone_iterations, self.comm, releasable=~self.surface.held,
                                      joined=sewn)
        self.zone_report = report
        totals = self.zone_totals
        totals["steps"] += report["collisions"] > 0
        totals["collisions"] += report["collisions"]
        totals["unresolved_steps"] += report["left"] > 0
        totals["rounds"] += report["rounds"]
        totals["most_left"] = max(totals["most_left"], report["left"])
        totals["released_steps"] = totals.get("released_steps", 0) + (report["released"] > 0)

    def state(self) -> dict:
        """What the next steps read from the past ones (a checkpoint, fabricfem.wear.checkpoint; the same on every
        rank): the Verlet list (its vertex-triangle and edge-edge candidates, the positions [m] of its search and
        the search count: a resumed run searches again where the uninterrupted one does), the last step's pairs,
        and the impact zones' last report and totals (their counts go on over the whole run)."""
        return {"candidates": self._candidates, "edge_candidates": self._edge_candidates,
                "searched_at": self._searched_at.copy(), "searches": self.searches, "pairs": self.pairs,
                "edge_pairs": self.edge_pairs, "zone_report": dict(self.zone_report),
                "zone_totals": dict(self.zone_totals)}

    def restore(self, state: dict) -> None:
        """Continue from a `state()` of the same surface; ValueError (starting "resume:") for a checkpoint of
        another surface (node count)."""
        if state["searched_at"].shape != self._searched_at.shape:
            raise ValueError(f"resume: the checkpoint's cloth self-contact has {len(state['searched_at'])} nodes, "
                             f"this run's {len(self._searched_at)}")
        self._candidates, self._edge_candidates = state["candidates"], state["edge_candidates"]
        self._searched_at, self.searches = state["searched_at"].copy(), int(state["searches"])
        self.pairs, self.edge_pairs = state["pairs"], state["edge_pairs"]
        self.zone_report, self.zone_totals = dict(state["zone_report"]), dict(state["zone_totals"])

    def _respond(self, x: np.ndarray, vel: np.ndarray, pairs: Pairs, mass: np.ndarray, dt: float,
                 edge_pairs: EdgePairs | None = None) -> None:
        """The forces of the pairs and the edge pairs (module docstring) into force, normal_force, friction_force
        (N, 3) [N] (numpy: the compiled response's twin)."""
        N = self.surface.count
        for buffer in (self.force, self.normal_force, self.friction_force):
            buffer.fill(0.0)
        if edge_pairs is not None and len(edge_pairs):
            law = (self.penalty, self.distance, self.damping, self.mu, dt)
            normal, friction = edge_contact.respond_numpy(edge_pairs, edge_contact.shares(edge_pairs, self.edges, N),
                                                          self.edges, x, vel, 1.0 / mass, self._inverse_area, law)
            self.normal_force += normal
            self.friction_force += friction
            np.add(self.normal_force, self.friction_force, out=self.force)
        if not len(pairs):
            return
        tri = self.surface.triangles[pairs.triangle]
        w, p = pairs.bary, pairs.vertex
        xc = np.einsum("ij,ijk->ik", w, x[tri])
        normal = self._normals(x[p] - xc, pairs.distance, x[tri])
        v_rel = vel[p] - np.einsum("ij,ijk->ik", w, vel[tri])
        v_n = np.einsum("ij,ij->i", v_rel, normal)
        share = _feature_share(p, tri, w)
        inverse_mass = 1.0 / mass[p] + np.einsum("ij,ij->i", w ** 2, 1.0 / mass[tri])
        m_eff = np.where(inverse_mass > 0.0, 1.0 / np.where(inverse_mass > 0.0, inverse_mass, 1.0), np.inf)
        spring = share * self.penalty * self.surface.area[p]
        damper = 2.0 * self.damping * np.sqrt(spring * np.where(np.isfinite(m_eff), m_eff, 0.0))
        f_n = np.maximum(spring * (self.distance - pairs.distance) - damper * v_n, 0.0)
        f_normal = f_n[:, None] * normal
        f_friction = np.zeros_like(f_normal)
        if self.mu > 0.0:
            v_t = v_rel - v_n[:, None] * normal
            speed = np.linalg.norm(v_t, axis=1)
            magnitude = np.minimum(self.mu * f_n, m_eff * speed / dt)
            f_friction = -(magnitude / np.where(speed > 0.0, speed, 1.0))[:, None] * v_t
        for total, pair_force in ((self.normal_force, f_normal), (self.friction_force, f_friction)):
            nodes = np.concatenate([p, tri.ravel()])
            for k in range(3):
                values = np.concatenate([pair_force[:, k], -(w * pair_force[:, k:k + 1]).ravel()])
                total[:, k] += np.bincount(nodes, values, minlength=N)
        np.add(self.normal_force, self.friction_force, out=self.force)

    def _normals(self, offset: np.ndarray, distance: np.ndarray, corners: np.ndarray) -> np.ndarray:
        """Unit (x_p - x_c) / delta, or the triangle's unit normal (towards p's side) where delta < 1e-9 d_c."""
        tiny = distance < 1e-9 * self.distance
        normal = offset / np.where(tiny, 1.0, distance)[:, None]
        if tiny.any():
            face = np.cross(corners[tiny, 1] - corners[tiny, 0], corners[tiny, 2] - corners[tiny, 0])
            normal[tiny] = face / np.linalg.norm(face, axis=1)[:, None]
        return normal


def _feature_share(vertex: np.ndarray, tri: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(n,) 1 / (number of pairs of the same vertex whose closest point lies on the same feature: the triangle's
    interior, an edge or a node, named by its nodes with w > FEATURE_TOLERANCE: a vertex above a node of the other layer
    is found by each triangle around that node, in the node's, an edge's or the interior's region by round-off)."""
    feature = np.sort(np.where(w > FEATURE_TOLERANCE, tri, -1), axis=1)
    _, inverse, counts = np.unique(np.column_stack([vertex, feature]), axis=0, return_inverse=True,
                                   return_counts=True)
    return 1.0 / counts[inverse.ravel()]


def _check_speed(u: np.ndarray, what: str, t: float) -> None:
    """ValueError "self-contact: non-finite or faster than BLOW_UP_SPEED <what> at t = ... s (k of N nodes, node i,
    |u| = ... m/s)" unless every row of u (N, 3) [m/s] is finite and below BLOW_UP_SPEED. A blown-up step that stays
    finite would otherwise go on: its huge positions put every triangle into one cell of the broad phase, whose
    search then costs N x T per step and the run seems to hang."""
    speed = node_speeds(u)
    bad = ~(speed <= BLOW_UP_SPEED)
    if bad.any():
        node = int(np.argmax(bad))
        raise ValueError(f"self-contact: non-finite or faster than {BLOW_UP_SPEED:g} m/s {what} at t = {t:.6g} s "
                         f"({int(bad.sum())} of {len(u)} nodes, node {node}, |u| = {speed[node]:.3g} m/s)")


def node_speeds(u: np.ndarray) -> np.ndarray:
    """(N,) |u| of the rows of u (N, 3) [m/s]; inf (not a warning) where they overflow, NaN where not finite."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.sqrt(np.einsum("ij,ij->i", u, u))


def seam_neighbours(surface: ClothSurface, labels: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs that the seams make neighbours, as sorted keys: vertex-triangle (vertex x T + triangle) where the
    vertex is stitched to a node of the triangle, and edge-edge (first x E + second, first < second) where
    the two edges have stitched nodes in common; `labels` (N,): one per point of the cloth
    (`ClothSurface.stitched`). A sewn seam holds those nodes together, so these pairs touch by construction, as a
    vertex and its own triangles do."""
    sewn = np.bincount(labels)[labels] > 1
    cells, per_cell = surface.triangles, 1
    node, cell = cells.ravel(), np.repeat(np.arange(len(cells), dtype=np.int64), cells.shape[1])
    label_cell = np.unique(np.c_[labels[node[sewn[node]]], cell[sewn[node]]], axis=0)
    vertex, row = _same_label(labels, np.flatnonzero(sewn), label_cell[:, 0])
    triangle = (label_cell[row, 1][:, None] * per_cell + np.arange(per_cell)).ravel()
    vertex_keys = np.unique(np.repeat(vertex, per_cell) * len(surface.triangles) + triangle)
    ends = np.c_[edges.ravel(), np.repeat(np.arange(len(edges), dtype=np.int64), 2)]
    ends = np.unique(np.c_[labels[ends[sewn[ends[:, 0]], 0]], ends[sewn[ends[:, 0]], 1]], axis=0)   # (label, edge)
    start = np.searchsorted(ends[:, 0], ends[:, 0], side="right")       # the later edges of the same label
    count = start - np.arange(len(ends)) - 1
    first = np.repeat(ends[:, 1], count)
    second = ends[np.repeat(np.arange(len(ends)) + 1, count) + _ramp(count), 1]
    low, high = np.minimum(first, second), np.maximum(first, second)
    return vertex_keys, np.unique(low[low != high] * len(edges) + high[low != high])


def _same_label(labels: np.ndarray, nodes: np.ndarray, wanted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(node, row): every node of `nodes` whose label is wanted[row], for every row."""
    nodes = nodes[np.argsort(labels[nodes], kind="stable")]
    start = np.searchsorted(labels[nodes], wanted, side="left")
    count = np.searchsorted(labels[nodes], wanted, side="right") - start
    return nodes[np.repeat(start, count) + _ramp(count)], np.repeat(np.arange(len(wanted)), count)


def _ramp(count: np.ndarray) -> np.ndarray:
    """0, 1, ..., count[0] - 1, 0, 1, ..., count[1] - 1, ... (int64)."""
    total = int(count.sum())
    return np.arange(total, dtype=np.int64) - np.repeat(np.cumsum(count) - count, count)


def _member(keys: np.ndarray, sorted_keys: np.ndarray) -> np.ndarray:
    """(n,) True where a key of `keys` is in the sorted array `sorted_keys`."""
    if not len(sorted_keys):
        return np.zeros(len(keys), dtype=bool)
    return sorted_keys[np.minimum(np.searchsorted(sorted_keys, keys), len(sorted_keys) - 1)] == keys


def _layer_pair(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) of two (n,) arrays of garment labels."""
    return np.minimum(a, b), np.maximum(a, b)
