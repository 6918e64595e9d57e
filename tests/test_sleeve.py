"""Sleeve scene [Man2006, sec. 5.3]: scene validation, start clearance, moment balance of the elbow torque,
outputs, and the same torque history on 1 and 2 MPI ranks. Quick variants (mesh I, <= 6 degrees). The moment
balance and the active-set / step-limiter tests use the quasi-static route (solver="quasistatic",
fabricfem.wear.quasistatic); the scene run and the MPI test the default explicit route (the garment engine). The
sleeve scene is a wear scene: scenes/sleeve.toml (the explicit engine) and tests/data/sleeve_quasistatic.toml (the
same sleeve with [route] solver = "quasistatic")."""
import csv
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from shipped_scenes import TEST_MESH

from fabricfem import scenes as scene_module
from fabricfem.body.arm import DEFAULT_ARM
from fabricfem.scenes.build import sleeve_config
from fabricfem.scenes.schema import SceneError
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.quasistatic import build_sleeve, run_quasistatic
from fabricfem.wear.run import run_sleeve
from fabricfem.wear.sleeve import ELBOW_AXIS

ROOT = Path(__file__).resolve().parents[1]
QUICK = SleeveConfig.of(n_around=10, n_along=13, final_angle=6.0, angle_steps=2, solver="quasistatic")
QUICK_EXPLICIT = SleeveConfig.of(n_around=10, n_along=13, final_angle=6.0, output_angle_step=1.0)


SLEEVE_SCENES = {"explicit": ROOT / "scenes" / "sleeve.toml",                       # the shipped scene: the engine
                 "quasistatic": ROOT / "tests" / "data" / "sleeve_quasistatic.toml"}   # its Newton route


def sleeve_data(route: str = "explicit") -> dict:
    """The sleeve as a wear scene (mesh I, mu = 0.1) on `route`: SLEEVE_SCENES (the shipped scene on mesh I)."""
    data = tomllib.loads(SLEEVE_SCENES[route].read_text())
    data["garment"].update(TEST_MESH)
    return data


@pytest.mark.parametrize("route", SLEEVE_SCENES)
def test_sleeve_scene_is_valid(route):
    scene = scene_module.validate(sleeve_data(route))
    assert scene.kind == "wear" and scene["contact"]["friction"] == 0.1
    if route != "explicit":          # the Newton routes' configuration (fabricfem.scenes.build.sleeve_config)
        assert sleeve_config(scene.parsed).route.solver == route


def _named(section: str, key: str, text: str) -> str:
    """The refusal of [section] key: "section.key: key <text>" or the scene contract's "section: key <text>"
    (fabricfem.scenes.contract: a section's dataclass refusing a value names the section, its message the key)."""
    return rf"{section}(\.{key})?: {key} {re.escape(text)}"


# the sleeve scene's bad values: (mutation, the refusal naming the key), on both routes' scenes
BAD_SLEEVE = [
    (lambda d: d["contact"].update(frictoin=0.2), r"contact: unknown key 'frictoin' \(did you mean 'friction'\?\)"),
    (lambda d: d["body"].update(radius=0.05), r"body: unknown key 'radius'"),
    (lambda d: d.pop("fabric"), r"missing section \[fabric\]"),
    (lambda d: d["fabric"].pop("E1"), r"fabric: missing required key 'E1'"),
    (lambda d: d["garment"].update(radius=0.05),
     r"garment.radius: .*must exceed the arm's largest radius .*upper_arm_girth"),
    (lambda d: d["body"].update(forearm_girth=0.40), r"garment.radius: .*must exceed .*arm.forearm_girth"),
    (lambda d: d["contact"].update(friction=-0.1), _named("contact", "friction", "must be a number >= 0")),
    (lambda d: d["motion"].update(type="flexion"), r"motion.type: unknown 'flexion'"),
    (lambda d: d["contact"].update(method="mortar"), r"contact.method: method must be one of .* got 'mortar'"),
    (lambda d: d["motion"].update(solver="implicit"), r"motion: unknown key 'solver'"),   # a [route] key
    (lambda d: d["contact"].update(gravity=False), r"contact: unknown key 'gravity'"),    # a [route] key
    (lambda d: d["route"].update(solver="walking"), _named("route", "solver", "must be one of")),
    (lambda d: d["route"].update(rotary_inertia_scale=0.5),
     _named("route", "rotary_inertia_scale", "must be a number >= 1")),
    (lambda d: d["motion"].update(settle_time=-0.1), _named("motion", "settle_time", "must be a number >= 0")),
    (lambda d: d["motion"].update(angle_steps=0), _named("motion", "angle_steps", "must be a positive integer")),
    (lambda d: d["scene"].update(kind="static"), r"unknown section \[garment\]"),
    (lambda d: d["scene"].update(kind="weer"), r"scene.kind: unknown kind 'weer' \(did you mean 'wear'\?\)"),
    (lambda d: d["scene"].update(kind="sleeve"), r"the older sleeve layout is no longer read"),
    (lambda d: d.pop("motion"), r"missing section \[motion\]"),
]
# the route's own: the contact method of the route; a motion other than the flexion
BAD_SLEEVE_ROUTE = {
    "explicit": [
        (lambda d: d["contact"].update(method="augmented"),
         r"contact.method: .* for solver 'explicit', got 'augmented'"),
        (lambda d: d["motion"].update(type="walking"), r"motion.type: .*'walking'"),
    ],
    "quasistatic": [
        (lambda d: d["contact"].update(method="lagrange"),
         r"contact.method: .* for solver 'quasistatic', got 'lagrange'"),
        (lambda d: d["motion"].update(type="walking"), r"route.solver: 'quasistatic' runs the arm in a tube sleeve "
                                                       r"flexing at the elbow"),
    ],
}


@pytest.mark.parametrize("route, mutate, message",
                         [(r, m, t) for r in SLEEVE_SCENES for m, t in BAD_SLEEVE + BAD_SLEEVE_ROUTE[r]],
                         ids=[f"{r}-{k}-{re.sub(r'[^A-Za-z0-9_.]+', '_', t)[:40].strip('_')}" for r in SLEEVE_SCENES
                              for k, (_, t) in enumerate(BAD_SLEEVE + BAD_SLEEVE_ROUTE[r])])
def test_bad_sleeve_scene_fails_before_meshing(route, mutate, message, monkeypatch):
    data = sleeve_data(route)
    mutate(data)
    for where in ("fabricfem.meshes.tube", "fabricfem.wear.sleeve.tube", "fabricfem.scenes.wear.tube"):
        monkeypatch.setattr(where, lambda *a, **k: pytest.fail("meshed before validation"))
    with pytest.raises(SceneError, match=message):
        scene_module.validate(data)


@pytest.mark.parametrize("kwargs, message", [
    (dict(friction=-0.5), r"friction must be a number >= 0"),
    (dict(radius=0.05), r"radius: the sleeve radius"),
    (dict(thickness=0.0), r"thickness must be a positive"),
    (dict(method="mortar"), r"method must be"),
    (dict(solver="quasistatic", method="lagrange"), r"method must be one of \('penalty', 'augmented'\)"),
    (dict(rotary_inertia_scale=0.5), r"rotary_inertia_scale must be"),
    (dict(quadrature=(2, 4)), r"quadrature must be"),
    (dict(time_step_safety=1.2), r"time_step_safety must lie in"),
])
def test_bad_config_names_the_parameter(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SleeveConfig.of(**kwargs)


def test_start_clearance_and_first_contact():
    """At t = 0 the arm is inside the sleeve without contact: the smallest gap is the upper-arm clearance
    R - r(x_k) at the node ring x_k nearest the ellipsoid's widest section (closed form, r(x) = r_u
    sqrt(1 - ((x - a) / a)^2), a = 0.1675 m; R - r_u = 4.296 mm, the ring 5.6 mm off adds 3.1e-5 m). Nodes
    lie on the circle (second-order geometry). Tolerance 1e-6 m: the gap is measured along the body normal,
    which is tilted by ~0.01 rad from the radial direction there, changing a 4.3 mm gap by ~3e-7 m."""
    problem = build_sleeve(QUICK, MPI.COMM_SELF)
    a, r_u = DEFAULT_ARM.upper_arm_length / 2, DEFAULT_ARM.upper_arm_girth / (2 * math.pi)
    rings = np.arange(2 * QUICK.tube.n_along + 1) * QUICK.tube.length / (2 * QUICK.tube.n_along)   # Q2 node rings
    x_k = rings[np.argmin(abs(rings - a))]
    reference = 0.06 - r_u * math.sqrt(1 - ((x_k - a) / a) ** 2)
    assert abs(problem.min_gap() - reference) < 1e-6
    history = run_quasistatic(problem)
    torques = history.torque("elbow")          # the start pose (0 deg), 3 and 6 deg
    assert [s.coordinate for s in history.steps] == [0.0, 3.0, 6.0]
    assert torques[0] == 0.0          # no contact at the start pose: no force at all
    # the forearm (clearance 12.3 mm at its widest) first touches the sleeve between 3 and 6 degrees
    assert torques[1] == 0.0 and torques[2] > 0.0
    assert all(s.drag_ratio == 0.0 for s in history.steps)   # plain Newton equilibria, no regularisation


def test_elbow_torque_balances_the_shoulder_reactions():
    """Conservation of angular momentum (statics): the moment about the elbow axis of all contact forces
    on the arm equals the moment of the support reactions at the held shoulder ring,
    tau = a . sum_held (x_i - J) x R_int,i (the internal forces of the objective shell energy have no net
    moment once the rotation rows are in equilibrium). Independent of the torque routine: reactions come
    from the assembled internal force vector. Tolerance: the Newton residual's moment (bounded by
    sqrt(n) |r|_2 (L + 1 m), checked to be < 1% of the torque) plus the non-objectivity of the discrete
    shell: the director d(theta) is built from interpolated angles, so a rigid rotation is represented only
    up to O(|theta| (h / R)^2) ~ 0.01 x 0.4 = 4e-3 on mesh I; 4e-3 relative (measured: 2.2e-5)."""
    problem = build_sleeve(QUICK, MPI.COMM_SELF)
    run_quasistatic(problem)
    model, contact = problem.model, problem.contact
    b = model.create_vector()
    model.internal_force(model.w.vector, b)
    s = contact.evaluate()
    held = contact.nodes.constrained.all(axis=1)
    reactions = b.array[contact.nodes.dofs[held]]
    elbow = problem.body.joint_position("elbow", contact.time)
    tau_reactions = float(np.dot(np.cross(s.position[held] - elbow, reactions).sum(axis=0), ELBOW_AXIS))
    resisting_all = -contact.joint_torque("elbow", ELBOW_AXIS)   # both segments
    r = problem.system.create_vector()
    problem.system.residual(model.w.vector, r)
    bound = math.sqrt(r.getSize()) * r.norm() * (QUICK.tube.length + 1.0)
    assert abs(resisting_all) > 1e-4 and bound < 1e-2 * abs(resisting_all)
    assert abs(resisting_all - (-tau_reactions)) < bound + 4e-3 * abs(resisting_all)
    # at 6 degrees only the forearm touches: the forearm torque is the whole torque
    assert problem.resisting_torque() == pytest.approx(resisting_all, rel=1e-12)


def test_sleeve_scene_run_writes_outputs(tmp_path):
    data = sleeve_data()
    data["motion"].update(final_angle=6.0, output_angle_step=3.0)
    data["output"] = {"dir": str(tmp_path), "render_at": [6.0]}
    from fabricfem.scenes.run import run_scene
    outcome = run_scene(scene_module.validate(data))
    history = outcome.result
    assert history.completed and outcome.exit_code == 0
    for name in ("cloth.xdmf", "cloth.h5", "cloth_pressure.xdmf", "body.pvd", "body_0002.vtp", "torque.csv",
                 "torque.png", "torque.sto", "pressure_06.00deg.png"):
        assert (tmp_path / name).exists(), name
    rows = list(csv.DictReader(open(tmp_path / "torque.csv")))     # every record: the settling's, the flexion's
    assert [r["phase"] for r in rows] == [s.phase for s in history.steps]
    first = next(k for k, r in enumerate(rows) if r["phase"] == "motion")
    assert [float(r["axis"]) for r in rows[first - 1:]] == pytest.approx([0.0, 3.0, 6.0], abs=1e-9)
    final = history.steps[-1].torques["elbow"]
    assert float(rows[-1]["elbow_torque_Nm"]) == pytest.approx(final)
    assert final > 0.0              # the forearm touches the sleeve between 3 and 6 degrees


@pytest.mark.mpi
def test_torque_history_same_on_one_and_two_ranks():
    """Explicit route: the torque history on COMM_WORLD equals the serial one (COMM_SELF) within 1e-6
    relative, at every record (the settling's and the flexion's). Each rank treats its owned nodes (contact,
    friction history) and the torque is an allreduce; the assembly differs only in the summation order (round-off
    1e-16), which the damped steps of the rest and of the flexion to 6 degrees amplify by far less than 1e10."""
    parallel = run_sleeve(QUICK_EXPLICIT, MPI.COMM_WORLD)
    serial = run_sleeve(QUICK_EXPLICIT, MPI.COMM_SELF)
    assert np.max(np.abs(parallel.torque("elbow"))) > 0 and len(parallel.steps) == len(serial.steps)
    np.testing.assert_allclose(parallel.torque("elbow"), serial.torque("elbow"), rtol=1e-6, atol=1e-12)


def test_explicit_run_reports_a_timing_breakdown():
    """The explicit history carries the per-part wall times of `step_breakdown`: every part >= 0 except
    `other` (the remainder, which can be slightly negative only by timer granularity: > -1 % of the loop), the
    parts add up to the loop time (by construction, to round-off) and ms/step = loop / steps, over the flexion."""
    from fabricfem.wear.engine import TIMING_PARTS, format_breakdown
    h = run_sleeve(QUICK_EXPLICIT.with_(final_angle=3.0), MPI.COMM_SELF)
    t = h.timings
    parts = [t[f"{p}_s"] for p in TIMING_PARTS]
    assert all(v >= 0.0 for v in parts[:-1]) and parts[-1] > -0.01 * t["loop_s"]
    assert sum(parts) == pytest.approx(t["loop_s"], rel=1e-12)
    assert sum(t[f"{p}_share"] for p in TIMING_PARTS) == pytest.approx(1.0, rel=1e-12)
    # the flexion's steps (the settling's records are not timed)
    assert t["steps"] == sum(s.time_steps for s in h.steps if s.phase == "motion") > 0
    assert t["ms_per_step"] == pytest.approx(1e3 * t["loop_s"] / t["steps"])
    assert "ms/step" in format_breakdown(t)


def test_dynamic_similarity_scales_speed_and_damping_by_the_wave_speed():
    """flexion_speed = omega c / c_ref and damping = alpha c / c_ref with c = sqrt(E / rho) (closed form for
    fabrics II and III of the study: c_II / c_I = sqrt(350 / 1.2) = 17.08, c_III / c_I = sqrt(7200 / 1.2 x
    436 / 700) = 61.13); off by default (factor 1)."""
    from fabricfem.studies.sleeve import variants
    fabrics = variants(quick=True)["fabrics"]
    assert fabrics["fabric I"].flexion_speed == pytest.approx(45.0, rel=1e-14)
    assert fabrics["fabric II"].flexion_speed == pytest.approx(45.0 * math.sqrt(350.0 / 1.2), rel=1e-14)
    assert fabrics["fabric III"].damping == pytest.approx(10.0 * math.sqrt(7200.0 / 1.2 * 436.0 / 700.0), rel=1e-14)
    plain = SleeveConfig.of(E=350e6)
    assert plain.flexion_speed == 45.0 and plain.damping == 10.0
    with pytest.raises(ValueError, match="similarity_reference"):
        SleeveConfig.of(similarity_reference=(0.0, 436.0))


def test_torque_bounce_of_an_alternating_signal():
    """torque_bounce on tau_n = a n + b + A (-1)^n: the moving average over an even window w (entries n - w/2
    ... n + w/2 - 1) removes the alternation exactly and gives a (n - 1/2) + b for the linear part, so the
    deviation is A (-1)^n + a / 2 and its RMS sqrt(A^2 + a^2 / 4) (closed form); window 1 gives 0."""
    from fabricfem.studies.sleeve import torque_bounce
    n = np.arange(400)
    tau = 1e-4 * n + 0.02 + 3e-3 * (-1.0) ** n
    angles = n * 0.1
    rms, rel = torque_bounce(angles, tau, 20, from_angle=10.0)
    assert rms == pytest.approx(math.sqrt(3e-3 ** 2 + (1e-4 / 2) ** 2), rel=1e-9)
    smooth = 1e-4 * (n - 0.5) + 0.02
    assert rel == pytest.approx(rms / np.sqrt(np.mean(smooth[(angles >= 10.0) & (n < 390)] ** 2)), rel=1e-9)
    assert torque_bounce(angles, tau, 1)[0] == 0.0


def test_study_cli_rejects_unknown_meshes_and_fabrics(capsys):
    """`fabricfem study sleeve --meshes I,V` / `--fabrics IV` / `--mesh-frictions 0.7` / `--only nosuch`: exit status 2 with the parameter named, before
    any run."""
    from fabricfem.cli import main
    assert main(["study", "sleeve", "--meshes", "I,V"]) == 2
    assert "fine / meshes: unknown mesh 'V'" in capsys.readouterr().err
    assert main(["study", "sleeve", "--fabrics", "IV"]) == 2
    assert "fabrics: unknown fabric set 'IV'" in capsys.readouterr().err
    assert main(["study", "sleeve", "--mesh-frictions", "0.7"]) == 2
    assert "mesh_frictions" in capsys.readouterr().err
    assert main(["study", "sleeve", "--only", "mesh_mu0.5,nosuch"]) == 2
    assert "only: unknown figure 'nosuch'" in capsys.readouterr().err
    assert main(["study", "sleeve-methods", "--methods", "lagrange,uzawa"]) == 2
    assert "methods: unknown ['uzawa']" in capsys.readouterr().err
    assert main(["study", "sleeve-methods", "--al-budget", "-5"]) == 2
    assert "al_budget" in capsys.readouterr().err


# ------------------------------------------------------------------ active-set strategy and damped Newton
TIGHT = {"snes_rtol": 1e-14, "snes_stol": 1e-15, "snes_max_it": 60}


def test_active_set_gives_the_plain_penalty_solution_on_the_signorini_plate():
    """Plate on a sphere under its weight (fabricfem.verify.contact), plain penalty Newton vs the active-set
    strategy (contact set fixed per Newton solve, updated until stable): where the plain law converges both
    solve the same equations, so the states agree to the Newton tolerance. Both are driven to round-off
    (rtol 1e-14), so 1e-10 relative to the largest state component is the task's bound and leaves four
    decades for the conditioning of the contact Jacobian (k_N / (E t / h^2) = 10)."""
    from fabricfem.solvers.newton import NewtonSolver
    from fabricfem.verify import contact as cases
    states = []
    for active_set in (False, True):
        problem = cases.signorini_problem(n=6, comm=MPI.COMM_SELF)
        problem.active_set = active_set
        solver = NewtonSolver(problem.system, TIGHT)
        for lam in (0.5, 1.0):
            problem.system.set_load_factor(lam)
            result = problem.solve(solver)
            assert result.converged, result.reason
            problem.system.after_converged_step()
        states.append(problem.model.w.x.array.copy())
        contacts = int(np.sum(problem.evaluate().pressure > 0))
        solver.destroy()
    assert contacts >= 1
    scale = np.max(np.abs(states[0]))
    assert np.max(np.abs(states[1] - states[0])) <= 1e-10 * scale


def test_active_set_with_friction_gives_the_return_map_solution():
    """Capstan strip (fabricfem.verify.contact, mu = 0.3, theta = pi/2) pulled at one end into partial slip:
    the return-map Newton solve and the active-set solve (contact set and slip set fixed per Newton solve) from
    the same state and friction history agree to 1e-10 of the largest state component (both converged to
    round-off; see the frictionless test). The pull is chosen so that some but not all contact nodes slide, so
    the fixed slip set is exercised on both branches (measured: 2e-13; a larger pull, 1e-4 m, makes the plain
    return-map Newton cycle between two iterates, which the active-set solve does not)."""
    from fabricfem.solvers.loadstep import solve_load_path
    from fabricfem.solvers.newton import NewtonSolver
    from fabricfem.verify import contact as cases
    problem, pull, _ = cases.capstan_model(0.3, 0.5 * math.pi, nx=24, comm=MPI.COMM_SELF)
    solver = NewtonSolver(problem.system, TIGHT)
    solve_load_path(problem.system, 1.0, solver=solver, initial_step=0.5)
    problem.system.after_converged_step()
    start = problem.model.w.x.array.copy()
    for g, c in pull:
        g.x.array[:] = PULL * c
    states, slips = [], []
    for active_set in (False, True):
        problem.model.w.x.array[:] = start
        problem.active_set = active_set
        result = problem.solve(solver)
        assert result.converged, result.reason
        states.append(problem.model.w.x.array.copy())
        s = problem.evaluate()
        slips.append((int(np.sum(s.slip)), int(np.sum(s.pressure > 0))))
    solver.destroy()
    sliding, touching = slips[0]
    assert 0 < sliding < touching, slips
    scale = np.max(np.abs(states[0]))
    assert np.max(np.abs(states[1] - states[0])) <= 1e-10 * scale


PULL = 2e-5   # m: partial slip of the capstan strip at mu = 0.3 (measured: 108 of 147 contact nodes slide)


def test_frozen_segment_gap_is_that_segments_gap():
    """nearest_gap with a frozen segment assignment returns that segment's own gap and normal."""
    from fabricfem.body.ellipsoid import Ellipsoid
    from fabricfem.contact.nodal import nearest_gap
    a = Ellipsoid(np.zeros(3), np.eye(3), np.array([0.1, 0.05, 0.05]))
    b = Ellipsoid(np.array([0.2, 0.0, 0.0]), np.eye(3), np.array([0.1, 0.04, 0.04]))
    x = np.array([[0.1, 0.0, 0.06], [0.05, 0.0, 0.07], [0.25, 0.03, 0.03]])
    frozen = np.array([1, 1, 0])
    g, n, seg = nearest_gap(x, [a, b], frozen)
    for k, e in enumerate((a, b)):
        ge, ne = e.gap(x[frozen == k])
        np.testing.assert_array_equal(g[frozen == k], ge)
        np.testing.assert_array_equal(n[frozen == k], ne)
    np.testing.assert_array_equal(seg, frozen)


def test_step_limiter_scales_by_the_largest_increment():
    """s = min(1, max_rotation / |dtheta|_inf, max_displacement / |du|_inf) (closed form)."""
    from fabricfem.wear.quasistatic import StepLimiter
    problem = build_sleeve(QUICK, MPI.COMM_SELF)
    limiter = StepLimiter(problem.model, max_rotation=0.1, max_displacement=5e-3)
    step = np.zeros(problem.model.w.vector.getLocalSize())
    assert limiter.factor(step) == 1.0
    step[limiter._theta[3]] = -0.6
    step[limiter._u[7]] = 1e-3
    assert limiter.factor(step) == pytest.approx(0.1 / 0.6, rel=1e-15)
    step[limiter._u[7]] = 0.05
    assert limiter.factor(step) == pytest.approx(0.1, rel=1e-15)


def test_keep_ties_holds_the_status_of_nodes_on_the_switch():
    """nodal.keep_ties on hand-made trial pressures lambda - k g (k = 1e6 Pa/m, tie 1e-6 m, so k tie = 1 Pa):
    nodes within 1 Pa of the switch keep their previous status, the others follow the sign of the trial."""
    from fabricfem.contact.nodal import keep_ties
    k, tie = 1e6, 1e-6
    multiplier = np.array([0.0, 0.0, 5.0, 5.0, 0.0, 0.0])
    trial = np.array([0.5, -0.5, 4.0, -2.0, 1.5, -1.5])          # Pa
    gap = (multiplier - trial) / k
    previous = np.array([False, True, False, True, False, True])
    kept = keep_ties(previous, gap, multiplier, k, tie)
    assert kept.tolist() == [False, True, True, False, True, False]
    # the bounds of the docstring: a kept contact node pulls with at most k tie, a kept free node
    # penetrates at most tie
    held_contact, held_free = kept & (trial <= 0.0), ~kept & (trial > 0.0)
    assert np.all(trial[held_contact] >= -k * tie) and np.all(-gap[held_free] <= tie)


def test_tie_tolerance_solution_satisfies_the_law_within_the_tie():
    """Signorini plate with the active-set strategy and tie_tolerance delta = 1e-5 m: the converged state solves
    the unilateral law (no fixed set) up to the nodal forces of the kept ties, at most w_i k_N delta per node
    (nodal.keep_ties), plus the Newton tolerance; and it is the tie-free solution to within that force over the
    contact stiffness (delta, times 10 for the conditioning of the plate under a point-like contact)."""
    from fabricfem.solvers.newton import NewtonSolver
    from fabricfem.verify import contact as cases
    states = []
    for tie in (0.0, 1e-5):
        reference = cases.signorini_problem(n=6, comm=MPI.COMM_SELF)
        problem = type(reference)(reference.model, [cases.sphere()], active_set=True, tie_tolerance=tie)
        solver = NewtonSolver(problem.system, TIGHT)
        for lam in (0.5, 1.0):
            problem.system.set_load_factor(lam)
            result = problem.solve(solver)
            assert result.converged, result.reason
            if lam < 1.0:
                problem.system.after_converged_step()
        b = problem.model.create_vector()
        problem.system.residual(problem.model.w.vector, b)          # unilateral law: no fixed set after solve
        bound = np.max(problem.nodes.area) * problem.penalty * tie + 1e-9 * problem.F_ref.norm()
        assert np.max(np.abs(b.array)) <= bound
        assert np.count_nonzero(problem.evaluate().pressure > 0.0) >= 1
        states.append(problem.model.w.x.array.copy())
        solver.destroy()
    assert np.max(np.abs(states[1] - states[0])) <= 10 * 1e-5


def test_bad_active_set_cap_names_the_parameter():
    from fabricfem.verify import contact as cases
    problem = cases.signorini_problem(n=2, comm=MPI.COMM_SELF)
    with pytest.raises(ValueError, match="max_active_set_updates"):
        type(problem)(problem.model, [cases.sphere()], max_active_set_updates=0)
    with pytest.raises(ValueError, match="tie_tolerance"):
        type(problem)(problem.model, [cases.sphere()], tie_tolerance=-1e-6)
    with pytest.raises(ValueError, match="blend_width"):
        type(problem)(problem.model, [cases.sphere()], blend_width=-1e-3)
    with pytest.raises(ValueError, match="max_rotation_step"):
        SleeveConfig.of(max_rotation_step=0.0)


# ----------------------------------------------------------------------------- stored fabric (fabric_name)
def test_fabric_name_uses_the_stored_fabric_everywhere(tmp_path):
    """fabric_name replaces the E/G/nu12/thickness/density fields: the fabric, the wave speed of dynamic
    similarity, the explicit step estimate and the penalty default all follow the stored fabric.
    Independent reference: a fabric saved to a tmp file with moduli 4x fabric I's and density 436 kg/m^3
    (c = 2 c_I exactly, so the similarity factor is 2 and the membrane-limited critical step halves)."""
    from fabricfem.fabrics import save_fabric
    from fabricfem.materials import Fabric
    from fabricfem.wear.sleeve import build_explicit
    stored = Fabric(E1=4.8e6, E2=4.8e6, G12=4e5, nu12=0.0, thickness=1e-3, density=436.0, name="four-times")
    path = save_fabric(stored, tmp_path / "four-times.json")
    base = SleeveConfig.of(n_around=10, n_along=13, final_angle=2.0, dynamic_similarity=True,
                        method="penalty")
    named = base.with_(fabric_name=str(path))
    assert named.fabric.E1 == 4.8e6 and named.fabric.name == "four-times"
    # c = sqrt(E / rho): 4x E at the same rho gives twice the wave speed (exact up to rounding)
    assert named.similarity_factor == pytest.approx(2.0, rel=1e-12)
    assert named.flexion_speed == pytest.approx(2.0 * base.flexion_speed, rel=1e-12)
    p_base, p_named = build_explicit(base), build_explicit(named)
    try:
        assert p_named.model.fabric.E1 == 4.8e6
        # penalty default 10 E t / h^2 (fabricfem.contact.nodal.default_penalty) scales with E
        assert p_named.contact.penalty == pytest.approx(4.0 * p_base.contact.penalty, rel=1e-12)
        # every frequency of the step estimate (membrane, bending, shear, penalty) scales with sqrt(E / rho) at
        # equal geometry and thickness: the critical step halves (damping alpha c / c_ref scales likewise; 1e-5:
        # the largest eigenvalue is converged to SLEPc's rtol 1e-6)
        assert p_named.dt_estimate == pytest.approx(0.5 * p_base.dt_estimate, rel=1e-5)
    finally:
        p_base.destroy()
        p_named.destroy()


@pytest.mark.parametrize("key, value", [("E", 2.0e6), ("G", 2.0e5), ("nu12", 0.3), ("thickness", 2e-3),
                                        ("density", 500.0)])
def test_fabric_field_given_with_fabric_name_is_refused(key, value):
    """A fabric field next to fabric_name would be ignored (the stored fabric sets it): refused, naming it."""
    with pytest.raises(ValueError, match=rf"^{key}: given together with fabric_name"):
        SleeveConfig.of(n_around=10, n_along=13, fabric_name="two-layer-laminate", **{key: value})


def test_fabric_name_with_a_fitted_law_uses_its_small_strain_moduli():
    """The stored laminate (fitted membrane law): SleeveConfig.fabric is load_fabric's Fabric (membrane_law
    set, E1/E2/G12 = fitted_fabric's small-strain values), and the wave speed is the plane-stress one of those
    moduli (stability.plane_stress_wave_speed, eq. 2.87 with nu12)."""
    from fabricfem.fabrics import load_fabric
    cfg = SleeveConfig.of(n_around=10, n_along=13, final_angle=2.0, fabric_name="two-layer-laminate")
    ref = load_fabric("two-layer-laminate")
    f = cfg.fabric
    assert f.membrane_law is not None
    assert (f.E1, f.E2, f.G12, f.nu12, f.thickness, f.density) == (ref.E1, ref.E2, ref.G12, ref.nu12,
                                                                    ref.thickness, ref.density)
    c = math.sqrt(max(ref.E1, ref.E2) / (ref.density * (1.0 - ref.nu12 * ref.nu12 * ref.E2 / ref.E1)))
    assert cfg.wave_speed == pytest.approx(c, rel=1e-12)
    assert cfg.membrane_modulus == max(ref.E1, ref.E2)


def test_fitted_fabric_sleeve_flexes_a_few_degrees():
    """Mesh I, stored laminate, 2 degrees explicit: the run completes with finite torques (smoke test of the
    fitted-law sleeve; the law itself is verified in tests/test_fitted_law.py)."""
    cfg = SleeveConfig.of(n_around=10, n_along=13, final_angle=2.0, fabric_name="two-layer-laminate")
    history = run_sleeve(cfg)
    assert history.completed and len(history.motion_curve("elbow")[0]) == 3     # the start state, 1 and 2 deg
    assert np.all(np.isfinite(history.torque("elbow")))                         # every record


@pytest.mark.parametrize("name", ["no-such-fabric", "", 3])
def test_unknown_fabric_name_raises_naming_it(name):
    with pytest.raises(ValueError, match="fabric_name"):
        SleeveConfig.of(fabric_name=name)


def test_sleeve_settles_on_the_resting_arm_before_the_flexion():
    """Gravity on (the explicit default): during the 0.4 s rest the sleeve falls onto the arm and comes to
    rest. Reference: a twice longer rest (0.8 s) of the same model, i.e. the static state it tends to. The
    torque at rest (the weight the forearm carries) and the strain energy after 0.4 s must be within 5 % of
    those after 0.8 s: with mass damping alpha = 10 1/s every mode's amplitude decays at least like
    exp(-alpha t / 2), by exp(-2) = 14 % between 0.4 and 0.8 s, and the transient left at 0.4 s is itself a
    small part of the state (kinetic / strain energy 0.016 measured on mesh I), so the difference is a few
    per cent at most (measured: 1.6 % torque, 0.2 % strain energy)."""
    cfg = SleeveConfig.of(n_around=10, n_along=13, friction=0.5, final_angle=1.0)
    assert cfg.route.gravity and cfg.motion.settle_time == 0.4
    short = run_sleeve(cfg, MPI.COMM_SELF)
    long = run_sleeve(cfg.with_(settle_time=0.8), MPI.COMM_SELF)
    # the end of the rest: the last record of the settling (torque averaged over its interval, energies at its end)
    rest, long_rest = ([s for s in h.steps if s.phase == "settle"][-1] for h in (short, long))
    assert rest.time == pytest.approx(0.4, rel=1e-12) and long_rest.time == pytest.approx(0.8, rel=1e-12)
    assert short.motion_curve("elbow")[1][0] == rest.torques["elbow"]     # the flexion's start record
    assert rest.torques["elbow"] > 0.0          # the forearm carries part of the sleeve's weight at rest
    assert rest.torques["elbow"] == pytest.approx(long_rest.torques["elbow"], rel=0.05)
    assert rest.strain_energy == pytest.approx(long_rest.strain_energy, rel=0.05)
    assert rest.kinetic_energy < 0.05 * rest.strain_energy


def test_gravity_default_depends_on_the_route():
    """gravity=None resolves to on for the explicit route and off for the quasi-static one; an explicit value
    is kept; changing the solver re-resolves an unnamed gravity."""
    assert SleeveConfig().route.gravity is True
    assert SleeveConfig.of(solver="quasistatic").route.gravity is False
    assert SleeveConfig.of(gravity=False).route.gravity is False
    assert SleeveConfig().with_(solver="quasistatic").route.gravity is False
    with pytest.raises(ValueError, match="settle_time"):
        SleeveConfig.of(settle_time=-1.0)
