"""Contact verification: capstan friction (Euler-Eytelwein) and a Signorini plate on a sphere.

capstan-friction: a thin strip wrapped over a fixed rigid cylinder (an Ellipsoid with radii
(100 m, R, R): across the strip width the surface deviates from a cylinder by 1e-9 R), held by a dead
tension T1 at one end and pulled by a prescribed displacement along the tail at the other end. While
the pull grows the slip zone spreads from the pulled end; once every contact node slides the strip
slides as a whole and the tension T2 at the pulled end stays constant. That plateau is the tension at
impending slip (Coulomb friction is rate independent, so the limiting static tension equals the
quasi-static sliding tension): T2 / T1 = exp(mu theta) (Euler-Eytelwein).

signorini-penetration: a quarter of a square plate (symmetry on x = 0 and y = 0) lying on the apex of
a rigid sphere and loaded by its weight: the total contact force equals the weight (global
equilibrium) and the augmented Lagrangian drives the penetration below 1e-6 m. The penalty scaling
penetration ~ 1 / k_N is checked on a conforming contact with a closed-form pressure (the frictionless
strip wrapped on the cylinder under tension T: p = T / R); on the plate the apex contact is nearly a
point contact whose patch shrinks as k_N grows (measured slope -0.62), so there the penetration is not
proportional to 1 / k_N. The explicit [Man2006, Box 5] method leaves no node inside the body: tested on particles
falling onto an ellipsoid (the shell's explicit integrator, fabricfem.dynamics.explicit, is not coupled
to the contact here).
"""
from __future__ import annotations

import math

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact.explicit import box5_step
from fabricfem.contact.problem import ContactProblem
from fabricfem.materials import Fabric
from fabricfem.meshes import FabricMesh, plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.solvers.newton import NewtonSolver, SolverError
from fabricfem.verify import Timer, case, result

# ---------------------------------------------------------------------------------------------- capstan
CAPSTAN_RADIUS = 0.05       # m
CAPSTAN_TAIL = 0.0          # m, no straight tails: the strip covers exactly the wrap angle, so that every
                            # node is supported by the contact (a membrane tail has no transverse stiffness
                            # before it is tensioned)
CAPSTAN_WIDTH = 0.01        # m
CAPSTAN_E, CAPSTAN_T = 1e7, 1e-3   # Pa, m: E t = 1e4 N/m (membrane model: no bending)
CAPSTAN_T1 = 10.0           # N/m dead tension at the held end
CAPSTAN_INTERFERENCE = 1e-7  # m: the strip starts this far inside the cylinder, so that the contact is
                             # active (and the flexible strip supported) from the first Newton step; the
                             # hoop pre-tension this causes, E t delta / R = 0.02 N/m, is 0.2% of T1


def cylinder(radius: float = CAPSTAN_RADIUS, length: float = 100.0) -> Ellipsoid:
    """Rigid 'cylinder' along y: an ellipsoid with radii (length, R, R), axes e1 = y, e2 = z, e3 = x."""
    rotation = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    return Ellipsoid(np.zeros(3), rotation, np.array([length, radius, radius]))


def _wrap_map(theta: float, radius: float, tail: float):
    """Map arc length s along the strip to (x, z) and the unit tangent: tail, arc over the top, tail."""
    alpha0 = 0.5 * math.pi + 0.5 * theta

    def frame(s: np.ndarray):
        psi = np.clip((s - tail) / radius, 0.0, theta)
        alpha = alpha0 - psi
        tangent = np.stack([np.sin(alpha), -np.cos(alpha)])
        along = s - tail - radius * psi          # distance beyond the arc ends (<0 on tail 1, >0 on tail 2)
        point = radius * np.stack([np.cos(alpha), np.sin(alpha)]) + along * tangent
        return point, tangent
    return frame


def capstan_model(mu: float, theta: float, nx: int = 48, comm=MPI.COMM_WORLD):
    """The wrapped strip (membrane) on the cylinder; returns (problem, pull bc function,
    pull direction (x, z), solver)."""
    radius = CAPSTAN_RADIUS - CAPSTAN_INTERFERENCE
    length = 2 * CAPSTAN_TAIL + radius * theta
    flat = plate(length, CAPSTAN_WIDTH, nx, 1, cell="quadrilateral", origin=(0.0, -0.5 * CAPSTAN_WIDTH, 0.0),
                 comm=comm)
    frame = _wrap_map(theta, CAPSTAN_RADIUS - CAPSTAN_INTERFERENCE, CAPSTAN_TAIL)
    geometry = flat.mesh.geometry.x
    point, _ = frame(geometry[:, 0].copy())
    geometry[:, 0], geometry[:, 2] = point[0], point[1]

    def s_of(p):  # arc length back from the mapped coordinates (monotone in the polar angle / tails)
        s = np.empty(p.shape[1])
        alpha0 = 0.5 * math.pi + 0.5 * theta
        ang = np.arctan2(p[2], p[0])
        t1 = np.array([math.sin(alpha0), -math.cos(alpha0)])
        t2 = np.array([math.sin(alpha0 - theta), -math.cos(alpha0 - theta)])
        p1 = radius * np.array([math.cos(alpha0), math.sin(alpha0)])
        p2 = radius * np.array([math.cos(alpha0 - theta), math.sin(alpha0 - theta)])
        xz = np.stack([p[0], p[2]])
        a1 = t1 @ (xz - p1[:, None])
        a2 = t2 @ (xz - p2[:, None])
        on_arc = (a1 >= -1e-12) & (a2 <= 1e-12)
        s[:] = np.where(a1 < -1e-12, CAPSTAN_TAIL + a1,
                        np.where(a2 > 1e-12, CAPSTAN_TAIL + radius * theta + a2,
                                 CAPSTAN_TAIL + radius * (alpha0 - np.where(on_arc, ang, alpha0))))
        return s

    def warp(p):
        _, t = frame(s_of(p))
        return np.vstack([t[0], np.zeros_like(t[0]), t[1]])

    def normal(p):
        _, t = frame(s_of(p))
        return np.vstack([-t[1], np.zeros_like(t[0]), t[0]])   # (E1 x E2) with E2 = +y

    fmesh = FabricMesh(flat.mesh, flat.facet_tags, flat.tags, warp, normal)
    model = ShellModel(fmesh, Fabric.isotropic(CAPSTAN_E, 0.0, CAPSTAN_T), model="membrane")
    # Reference positions on the exact arc (the P2 nodes of the degree-1 geometry lie on chords, up to
    # R dphi^2 / 8 inside the cylinder): phi0 defines the reference metric of the shell forms.
    nodes = model.V2.tabulate_dof_coordinates().T
    exact, _ = frame(s_of(nodes))
    model.phi0.x.array[:] = np.column_stack([exact[0], nodes[1], exact[1]]).reshape(-1)
    _, t_start = frame(np.array([0.0]))
    _, t_end = frame(np.array([length]))
    t_start, t_end = t_start[:, 0], t_end[:, 0]
    model.add_edge_traction("left", (-CAPSTAN_T1 * t_start[0], 0.0, -CAPSTAN_T1 * t_start[1]))
    model.constrain(lambda p: np.full(p.shape[1], True), u=(None, 0.0, None))   # plane problem (nu = 0)
    pull = []
    for i, comp in ((0, 0), (2, 1)):      # u_x, u_z of the pulled edge follow our own functions
        sub = model.W.sub(i)
        V, _ = sub.collapse()
        dofs = fem.locate_dofs_topological((sub, V), 1, fmesh.facets("right"))
        g = fem.Function(V)
        model.bcs.append(fem.dirichletbc(g, dofs, sub))
        pull.append((g, t_end[comp]))
    problem = ContactProblem(model, [cylinder()], friction=mu)
    return problem, pull, t_end


def capstan_ratio(mu: float, theta: float, nx: int = 48, pull_max: float = 2e-3, pull_step: float = 2e-5,
                  comm=MPI.COMM_WORLD) -> dict:
    """Pull the end until every free contact node slides towards it (gross slip); returns the tension
    ratio T2 / T1 there, the forward-sliding fraction and the history. Pull steps halve when Newton fails
    (stick/slip switching) and grow by 1.5 after easy steps."""
    problem, pull, t_end = capstan_model(mu, theta, nx, comm)
    solver = NewtonSolver(problem.system)
    solve_load_path(problem.system, 1.0, solver=solver, initial_step=0.5)     # apply T1 with the end held
    tensions, fractions = [], []
    d, step = 0.0, pull_step
    while d < pull_max:
        saved = problem.w.x.array.copy()
        for g, c in pull:
            g.x.array[:] = (d + step) * c
        res = solver.solve()
        if not res.converged:
            problem.w.x.array[:] = saved
            step *= 0.5
            if step < 1e-3 * pull_step:
                raise SolverError(f"capstan: Newton {res.reason} at pull {d + step:.3e} m, step below "
                                  f"{1e-3 * pull_step:.1e} m")
            continue
        d += step
        problem.system.after_converged_step()
        reaction = np.array([problem.reaction("right", "u", 0), problem.reaction("right", "u", 2)])
        tensions.append(float(reaction @ t_end) / CAPSTAN_WIDTH)
        fractions.append(_forward_slip_fraction(problem))
        if fractions[-1] == 1.0:
            break
        if res.iterations <= 6:
            step *= 1.5
    return {"ratio": tensions[-1] / CAPSTAN_T1, "slip_fraction": fractions[-1], "tensions": tensions,
            "fractions": fractions, "pull": d, "ndofs": problem.ndofs, "problem": problem}


def _forward_slip_fraction(problem: ContactProblem) -> float:
    """Fraction of the free contact nodes on the slip cone sliding towards the pulled end (friction on the
    cloth pointing back along the strip, -e_s, with e_s = (n_z, 0, -n_x) the direction of increasing arc
    length)."""
    s = problem.evaluate()
    free = ~problem.nodes.constrained[:, 0]
    e_s = np.column_stack([s.normal[:, 2], np.zeros(len(s.gap)), -s.normal[:, 0]])
    # on the slip cone |t_T| = mu p (relative 1e-6: after a converged slip step the committed traction lies
    # on the cone up to rounding, so the return map's own slip flag is noise there)
    on_cone = np.linalg.norm(s.traction, axis=1) >= (1.0 - 1e-6) * problem.mu * s.pressure
    forward = on_cone & (s.pressure > 0) & (np.sum(s.traction * e_s, axis=1) < 0.0)
    comm = problem.comm
    n_free = comm.allreduce(int(np.sum(free & (s.pressure > 0))), op=MPI.SUM)
    return comm.allreduce(int(np.sum(forward & free)), op=MPI.SUM) / max(n_free, 1)


@case("capstan-friction")
def capstan_friction() -> list:
    """T2 / T1 at gross slip vs exp(mu theta) for mu = 0.1, 0.3, 0.5 and theta = pi/2, pi.

    Tolerance 5% (task): discretisation of the contact pressure on 48 elements and the membrane
    self-stress of the polygonal reference arc are well below it; bending (t = 0.1 mm, D / (R^2 T1)
    = 3e-4) is negligible."""
    out = []
    for theta in (0.5 * math.pi, math.pi):
        for mu in (0.1, 0.3, 0.5):
            with Timer() as timer:
                r = capstan_ratio(mu, theta)
            label = f"mu = {mu}, theta = {theta / math.pi:g} pi"
            out.append(result("capstan-friction", f"T2/T1 at gross slip, {label}", r["ratio"],
                              math.exp(mu * theta), 0.05, r["ndofs"], timer.elapsed))
            # gross slip: every contact node slides at the end of the pull (the plateau is reached)
            out.append(result("capstan-friction", f"fraction of contact nodes sliding, {label}", r["slip_fraction"],
                              1.0, 1e-12, r["ndofs"], timer.elapsed))
    return out


# -------------------------------------------------------------------------------------------- signorini
SPHERE_RADIUS = 0.1          # m
PLATE_HALF = 0.05            # m: quarter of a 0.1 m square plate
PLATE_E, PLATE_T, PLATE_RHO = 1e7, 1e-3, 436.0   # Pa, m, kg/m^3 (thesis sleeve density)
PLATE_INTERFERENCE = 1e-6    # m: the plate starts this far into the apex, so that the contact supports it
                             # from the first Newton step (otherwise the vertical rigid mode is free)
GRAVITY = 9.81               # m/s^2


def sphere(radius: float = SPHERE_RADIUS) -> Ellipsoid:
    return Ellipsoid(np.zeros(3), np.eye(3), np.full(3, radius))


def signorini_problem(method: str = "penalty", penalty: float | None = None, n: int = 8,
                      comm=MPI.COMM_WORLD) -> ContactProblem:
    """Quarter plate [0, a]^2 (Naghdi shell, quadrilaterals) on the apex of a rigid sphere under its weight;
    symmetry on x = 0 and y = 0."""
    fmesh = plate(PLATE_HALF, PLATE_HALF, n, n, cell="quadrilateral",
                  origin=(0.0, 0.0, SPHERE_RADIUS - PLATE_INTERFERENCE), comm=comm)
    model = ShellModel(fmesh, Fabric.isotropic(PLATE_E, 0.3, PLATE_T, density=PLATE_RHO))
    model.constrain("left", u=(0.0, None, None), theta=(None, 0.0))     # x = 0: no rotation about y
    model.constrain("bottom", u=(None, 0.0, None), theta=(0.0, None))   # y = 0: no rotation about x
    model.add_gravity((0.0, 0.0, -GRAVITY))
    return ContactProblem(model, [sphere()], method=method, penalty=penalty)


def plate_weight() -> float:
    """Weight of the quarter plate [N]."""
    return PLATE_RHO * PLATE_T * GRAVITY * PLATE_HALF ** 2


def solve_signorini(problem: ContactProblem) -> ContactProblem:
    solve_load_path(problem.system, 1.0, initial_step=0.25)
    return problem


def falling_particles(steps: int = 400, dt: float = 1e-3) -> dict:
    """5 x 5 particles dropped from 2 cm above an ellipsoid (radii 0.1, 0.08, 0.06 m) under gravity,
    [Man2006, Box 5] explicit steps. Returns the largest penetration after any step, the momentum balance error
    |P_end - P_0 - (gravity impulse + sum_n f_c^n dt)| [N s] and the contact impulse magnitude."""
    body = Ellipsoid(np.zeros(3), np.eye(3), np.array([0.1, 0.08, 0.06]))
    grid = np.linspace(-0.04, 0.04, 5)
    X, Y = np.meshgrid(grid, grid)
    top = 0.06 * np.sqrt(np.maximum(1.0 - (X / 0.1) ** 2 - (Y / 0.08) ** 2, 0.0))
    x = np.column_stack([X.ravel(), Y.ravel(), top.ravel() + 0.02])
    m = np.full(len(x), 1e-3)
    g = np.array([0.0, 0.0, -GRAVITY])
    v = np.zeros_like(x)
    a = np.tile(g, (len(x), 1))
    worst, momentum0 = 0.0, (m[:, None] * v).sum(axis=0)
    contact_impulse = np.zeros(3)
    for n in range(steps):
        x, v, a, contact = box5_step(x, v, a, m, dt, lambda p, t: np.tile(g, (len(p), 1)), n * dt,
                                     lambda t: [body])
        worst = max(worst, float(np.max(-body.distance(x))))
        contact_impulse += dt * contact.force.sum(axis=0)      # f_c = M a^c = -lambda acts over one step
    # the velocity of the last step holds only half of its correction (v^{n+1} = v* + dt/2 a^c)
    contact_impulse -= 0.5 * dt * contact.force.sum(axis=0)
    impulse = m.sum() * g * steps * dt + contact_impulse
    momentum = (m[:, None] * v).sum(axis=0)
    return {"max_penetration": worst, "momentum_error": float(np.linalg.norm(momentum - momentum0 - impulse)),
            "momentum_scale": float(np.linalg.norm(contact_impulse)),
            "contacts": int(np.count_nonzero(contact_impulse))}


def wrapped_strip_penetration(penalty: float, theta: float = math.pi, comm=MPI.COMM_WORLD) -> tuple[float, float]:
    """Frictionless strip wrapped on the cylinder under the tension T1 (end 2 held): conforming contact with
    the closed-form pressure p = T1 / R. Returns (mean penetration over the free contact nodes [m],
    T1 / (R k_N) [m])."""
    problem, _, _ = capstan_model(0.0, theta, comm=comm)
    problem.penalty = nodal_penalty = float(penalty)
    problem.tangential_penalty = nodal_penalty
    solve_load_path(problem.system, 1.0, initial_step=0.5)
    s = problem.evaluate()
    free = ~problem.nodes.constrained[:, 0]
    local = np.array([float(np.sum(-s.gap[free])), float(np.sum(free))])
    total = comm.allreduce(local, op=MPI.SUM)
    return total[0] / total[1], CAPSTAN_T1 / (CAPSTAN_RADIUS * nodal_penalty)


@case("signorini-penetration")
def signorini_penetration() -> list:
    """Plate on a sphere under its weight: force balance, augmented Lagrangian penetration < 1e-6 m; penalty
    penetration ~ 1/k_N on a conforming contact; explicit [Man2006, Box 5] particles never inside."""
    out = []
    weight = plate_weight()
    with Timer() as timer:
        problem = solve_signorini(signorini_problem())
        total = problem.total_force()
        ndofs = problem.ndofs
    # global equilibrium in z (no vertical support but the contact): exact up to Newton's tolerance; 1%
    out.append(result("signorini-penetration", f"plate on sphere, penalty k_N = {problem.penalty:.2e} Pa/m: total "
                      f"contact force z / weight", total[2] / weight, 1.0, 0.01, ndofs, timer.elapsed))
    with Timer() as timer:
        k_al = problem.penalty / 10.0
        problem = signorini_problem(method="augmented", penalty=k_al)
        solve_load_path(problem.system, 1.0, initial_step=0.25)
        report = problem.solve_augmented(tolerance=1e-6)
    out.append(result("signorini-penetration", f"plate on sphere, augmented Lagrangian at k_N = {k_al:.2e} Pa/m: "
                      f"largest penetration [m] after {report.augmentations} augmentations (limit 1e-6 m)",
                      report.max_penetration, 0.0, 1e-6, ndofs, timer.elapsed, scale=1.0))
    out.append(result("signorini-penetration", "plate on sphere, augmented Lagrangian: total contact force z / weight",
                      problem.total_force()[2] / weight, 1.0, 0.01, ndofs, timer.elapsed))
    with Timer() as timer:
        stiffnesses = np.array([1e7, 1e8, 1e9])
        pairs = [wrapped_strip_penetration(k) for k in stiffnesses]
    penetrations = np.array([p for p, _ in pairs])
    slope = np.polyfit(np.log(stiffnesses), np.log(penetrations), 1)[0]
    # slope -1 exactly for p = T1 / R independent of k_N; 1%: the radius R - g and the hoop strain change p
    # by O(g / R) <= 1e-3 and the strip ends carry slightly different nodal loads
    out.append(result("signorini-penetration", f"wrapped strip (p = T/R): d log(penetration) / d log(k_N), k_N = "
                      f"1e7...1e9 Pa/m, penetrations {penetrations[0]:.3e}...{penetrations[-1]:.3e} m",
                      slope, -1.0, 0.01, 0, timer.elapsed))
    out.append(result("signorini-penetration", "wrapped strip: mean penetration / (T1 / (R k_N)) at k_N = 1e8 Pa/m",
                      pairs[1][0] / pairs[1][1], 1.0, 0.01, 0, timer.elapsed))
    with Timer() as timer:
        particles = falling_particles()
    # explicit [Man2006, Box 5]: projected nodes land on the surface up to rounding (1e-12 m on 0.1 m radii)
    out.append(result("signorini-penetration", "explicit [Man2006, Box 5] (25 particles onto an ellipsoid): largest "
                      "penetration after any step [m]", particles["max_penetration"], 0.0, 1e-12, 0, timer.elapsed,
                      scale=1.0))
    # momentum change = impulse of gravity and contact forces (trapezoidal, as central differences integrate)
    out.append(result("signorini-penetration", "explicit [Man2006, Box 5]: |momentum change - impulse| / |contact impulse|",
                      particles["momentum_error"] / particles["momentum_scale"], 0.0, 1e-10, 0, timer.elapsed,
                      scale=1.0))
    return out
