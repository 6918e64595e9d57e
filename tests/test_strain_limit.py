"""Continuum fast-projection strain limiting (fabricfem.dynamics.strain_limit, [Peng2022, sec. 3])."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.dynamics import CentralDifference
from fabricfem.dynamics.strain_limit import FastProjection, attach, project_step
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.newton import NewtonSolver

LIMIT = 0.01
FABRIC = Fabric.isotropic(1.0e4, 0.0, 1.0e-3, density=117.0)  # E t = 10 N/m, 0.117 kg/m^2 (SI)


def strip(model_kind: str = "naghdi", nx: int = 8, ny: int = 2, L: float = 1.0, b: float = 0.25) -> ShellModel:
    model = ShellModel(plate(L, b, nx, ny, cell="quadrilateral"), FABRIC, model=model_kind)
    model.compile()
    return model


def displacement_dofs(model):
    """(reference coordinates (n, 3), W indices (n, 3)) of the displacement nodes on this rank."""
    if model.model == "naghdi":
        V, to_parent = model.W.sub(0).collapse()
        return V.tabulate_dof_coordinates(), np.asarray(to_parent).reshape(-1, 3)
    x = model.V2.tabulate_dof_coordinates()
    return x, np.arange(3 * x.shape[0]).reshape(-1, 3)


def set_uniaxial_stretch(model, stretch: float):
    """u = (stretch - 1) x e_x: E_warp = (stretch^2 - 1) / 2 everywhere, E_weft = 0."""
    x, dofs = displacement_dofs(model)
    model.w.x.array[:] = 0.0
    model.w.x.array[dofs[:, 0]] = (stretch - 1.0) * x[:, 0]


def test_bad_input_raises():
    model = strip("membrane", 2, 1)
    for kwargs in (dict(strain_limit=0.0), dict(strain_limit=float("nan")), dict(strain_limit=0.01, tol=-1.0),
                   dict(strain_limit=0.01, max_iterations=0)):
        with pytest.raises(ValueError):
            FastProjection(model, **kwargs)


@pytest.mark.mpi
@pytest.mark.parametrize("model_kind", ["membrane", "naghdi"])
def test_uniform_overstretch_projects_to_uniform_scaling(model_kind):
    """E_warp = 0.05 everywhere -> the projection is the uniform stretch sqrt(1 + 2 limit) (closed form),
    and its Newton iteration follows C_{k+1} = C_k^2 / (2 s_k^2) exactly (s_k^2 = 1 + 2 (C_k + limit)):
    for a uniform state the correction is uniform, ds = -C / s, and E(s + ds) - E(s) + C = ds^2 / 2."""
    model = strip(model_kind)
    projection = FastProjection(model, LIMIT, tol=1e-12)
    set_uniaxial_stretch(model, math.sqrt(1.0 + 2.0 * 0.05))
    summary = projection.strain_summary()
    assert summary["max_warp"] == pytest.approx(0.05, abs=1e-12)
    res = projection.project(dt=1e-3)
    # tolerances: round-off of the assembled strains (~1e-14); the projection stops at C < 1e-12
    summary = projection.strain_summary()
    assert summary["max_warp"] == pytest.approx(LIMIT, abs=1e-11)
    assert abs(summary["max_weft"]) < 1e-12
    x, dofs = displacement_dofs(model)
    u = model.w.x.array[dofs]
    deformed_x = x[:, 0] + u[:, 0]
    # unique up to a rigid x translation (the sheet is free): compare after removing the mean offset
    offset = deformed_x - math.sqrt(1.0 + 2.0 * LIMIT) * x[:, 0]
    mean = model.comm.allreduce(offset.sum()) / model.comm.allreduce(offset.size)
    err = model.comm.allreduce(float(np.abs(offset - mean).max()), op=MPI.MAX)
    assert err < 1e-10  # m, on a 1 m strip: round-off of the converged Newton iterate
    assert model.comm.allreduce(float(np.abs(u[:, 1:]).max()), op=MPI.MAX) < 1e-12
    # convergence: quadratic with the closed-form constant: 0.04 -> 7e-4 -> 3e-7 -> ~1e-14, 3 iterations
    v = res.violations
    assert res.iterations == 3 and v[-1] < 1e-12
    for c0, c1 in zip(v[:-1], v[1:]):
        if c1 > 1e-12:  # above round-off
            expected = c0 ** 2 / (2.0 * (1.0 + 2.0 * (c0 + LIMIT)))
            assert c1 == pytest.approx(expected, rel=1e-6)


@pytest.mark.mpi
@pytest.mark.parametrize("model_kind, cell", [("membrane", "quadrilateral"), ("naghdi", "quadrilateral"),
                                              ("membrane", "triangle")])
def test_point_strain_sees_a_strain_confined_to_one_cell_column(model_kind, cell):
    """u_x = (s - 1)(x - a) clipped to the column a <= x <= a + L / nx (piecewise linear, nodal on Q2 / P2): inside
    the column E_warp = (s^2 - 1) / 2 exactly, outside 0. The largest quadrature-point strain is that closed form;
    the vertex strains average it over their patches: on quadrilaterals half of the patch is stretched,
    (s^2 - 1) / 4; on triangles the diagonals split it unevenly, below the closed form. Only the owned
    displacement entries are set (the ghosts are the method's to update). The points are the strain form's own:
    the quadrature sum of the evaluated strains per cell equals the assembled cell integral of E_warp."""
    model = ShellModel(plate(1.0, 0.25, 8, 2, cell=cell), FABRIC, model=model_kind)
    model.compile()
    projection = FastProjection(model, 1.0)
    s, a, width = 1.3, 0.5, 1.0 / 8
    x, dofs = displacement_dofs(model)
    owned = model.W.dofmap.index_map.size_local * model.W.dofmap.index_map_bs
    model.w.x.array[:] = 0.0
    values = (s - 1.0) * np.clip(x[:, 0] - a, 0.0, width)
    mine = dofs[:, 0] < owned
    model.w.x.array[dofs[mine, 0]] = values[mine]
    closed = (s * s - 1.0) / 2.0
    # rel 1e-10: round-off of the assembled and evaluated strains (measured up to 6e-12)
    assert projection.point_strain_max() == pytest.approx(closed, rel=1e-10)
    vertex = projection.strain_summary()["max_warp"]
    if cell == "quadrilateral":
        assert vertex == pytest.approx(closed / 2.0, rel=1e-10)
    else:
        assert 0.25 * closed < vertex < 0.75 * closed
    set_uniaxial_stretch(model, s)
    assert projection.point_strain_max() == pytest.approx(closed, rel=1e-10)
    assert projection.strain_summary()["max_warp"] == pytest.approx(closed, rel=1e-10)


def test_point_strains_are_the_strain_forms_quadrature_points():
    """Per cell, sum_q w_q |J_q| E_warp(x_q) over the evaluated points equals the assembled DG0 integral of E_warp
    (a curved, sheared state: the strain varies within the cells), to round-off."""
    import basix
    import ufl
    from dolfinx import fem
    model = strip("membrane", nx=4, ny=2)
    projection = FastProjection(model, 1.0)
    x, dofs = displacement_dofs(model)
    model.w.x.array[dofs[:, 0]] = 0.2 * x[:, 0] ** 2 + 0.1 * x[:, 1]
    model.w.x.array[dofs[:, 2]] = 0.05 * np.sin(3.0 * x[:, 0])
    projection.point_strain_max()                      # builds the Expression
    points, weights = basix.make_quadrature(basix.CellType.quadrilateral, 4)
    cells = np.arange(model.mesh.topology.index_map(2).size_local, dtype=np.int32)
    strain = ufl.as_vector(FastProjection.strain_expressions(model))
    values = fem.Expression(strain, points).eval(cells).reshape(len(cells), len(points), 2)[:, :, 0]
    area = fem.Expression(abs(ufl.JacobianDeterminant(model.mesh)), points)
    jacobian = area.eval(cells).reshape(len(cells), len(points))
    DG0 = fem.FunctionSpace(model.mesh, ("DG", 0))
    test = ufl.TestFunction(DG0)
    dx = ufl.Measure("dx", domain=model.mesh, metadata={"quadrature_degree": 4})
    assembled = fem.petsc.assemble_vector(fem.form(strain[0] * test * dx)).array[:len(cells)]
    summed = (values * jacobian * weights).sum(axis=1)
    assert np.allclose(summed, assembled, rtol=1e-12, atol=1e-15)


@pytest.mark.mpi
def test_state_inside_limit_is_identity():
    model = strip("naghdi")
    projection = FastProjection(model, LIMIT, tol=1e-8)
    set_uniaxial_stretch(model, math.sqrt(1.0 + 2.0 * 0.009))  # E = 0.009 < 0.01
    x, dofs = displacement_dofs(model)
    model.w.x.array[dofs[:, 2]] = 1e-3 * np.sin(3.0 * x[:, 0])  # plus a small bend (E changes by ~1e-6)
    model.w.x.scatter_forward()  # ghost coordinates differ from the owners' at 1e-18: take the owners' values
    before = model.w.x.array.copy()
    res = projection.project(dt=1e-3)
    assert res.iterations == 0 and res.violations[0] < 0
    assert np.array_equal(model.w.x.array, before)


def test_strip_pulled_by_load_is_projected_back():
    """Naghdi strip clamped at x = 0 under an axial body force f: N(x) = f (L - x), E_warp up to ~0.04 at the
    clamp (solved with Newton). The projection brings every vertex strain below limit + tol, moves neither the
    clamped dofs nor the rotations, and leaves the strain of the unloaded far end below the limit."""
    model = ShellModel(plate(1.0, 0.2, 10, 2, cell="quadrilateral"), FABRIC)
    model.clamp("left")
    model.add_body_force((0.4, 0.0, 0.0))  # N/m^2: N(0) = 0.4 N/m -> E ~ N / (E t) = 0.04
    model.compile()
    model.set_load_factor(1.0)
    solver = NewtonSolver(model)
    assert solver.solve().converged
    model.w.vector.copy(solver.x)
    projection = FastProjection(model, LIMIT, tol=1e-6)
    s0 = projection.strain_summary()
    assert s0["max_warp"] > 3 * LIMIT
    before = model.w.x.array.copy()
    res = projection.project(dt=1e-3)
    after = projection.strain_summary()
    assert max(after["max_warp"], after["max_weft"]) <= LIMIT + 1e-6
    theta = model.W.sub(1).collapse()[1]
    assert np.array_equal(model.w.x.array[theta], before[theta])
    clamped = np.unique(np.concatenate([bc.dof_indices()[0] for bc in model.bcs]))
    assert np.array_equal(model.w.x.array[clamped], before[clamped])
    assert 1 <= res.iterations <= 10
    print(f"strip: max E_warp {s0['max_warp']:.4f} -> {after['max_warp']:.6f} in {res.iterations} iterations, "
          f"violations {res.violations}")


def test_explicit_step_with_projection_keeps_limit():
    """Central differences on a membrane strip pinned at x = 0 and pulled by a large axial body force: with the
    projection attached every step ends with max strain <= limit + tol; without it the strain exceeds 3 x limit.
    The velocity correction is Delta q / dt on the free dofs (Goldenthal et al.)."""
    def run(limited: bool):
        model = ShellModel(plate(1.0, 0.2, 6, 1, cell="quadrilateral"), FABRIC, model="membrane")
        model.constrain("left", u=(0.0, 0.0, 0.0))
        model.add_body_force((1.0, 0.0, 0.0))
        model.compile()
        integrator = CentralDifference(model, 2e-3)
        projection = FastProjection(model, LIMIT, tol=1e-6)
        log = attach(projection, integrator) if limited else []
        integrator.run(100, output_every=100)
        return projection.strain_summary(), log
    free, _ = run(False)
    limited, log = run(True)
    assert free["max_warp"] > 3 * LIMIT
    assert limited["max_warp"] <= LIMIT + 1e-6
    assert any(r.iterations > 0 for r in log)


def test_project_step_velocity_correction():
    model = ShellModel(plate(1.0, 0.25, 4, 1, cell="quadrilateral"), FABRIC, model="membrane")
    model.compile()
    integrator = CentralDifference(model, 1e-3)
    set_uniaxial_stretch(model, math.sqrt(1.1))
    model.w.vector.copy(integrator.d)
    integrator.v.set(0.0)
    integrator.a.set(0.0)
    projection = FastProjection(model, LIMIT, tol=1e-10)
    d_before = integrator.d.copy()
    project_step(projection, integrator)
    dq = integrator.d.copy()
    dq.axpy(-1.0, d_before)
    # CD: v = v~ + dt/2 a_new with v~ = dq / dt (a_old = 0): remove the acceleration half step to get dq / dt
    v = integrator.v.copy()
    v.axpy(-0.5 * integrator.dt, integrator.a)
    dq.scale(1.0 / integrator.dt)
    v.axpy(-1.0, dq)
    assert v.norm() <= 1e-12 * dq.norm()


def test_rotary_inertia_scaling_keeps_the_swinging_shell():
    """The corner-pinned Naghdi shell with the bending law of [Peng2022, eq. 9], case (c) (k/rho = 100, no limit),
    4 x 4 Q2, t = 0.4 s: the run with the case's rotary-inertia scale (rule of shell_rotary_scale: s = 1.4e4,
    step 2.5e-3 s) against the same run with the physical rotary inertia s = 1 (step 2.3e-5 s, 17000 steps:
    the independent reference). Compared: the displacements of the free corners (1, 0), (1, 1) and of the
    free-edge midpoint at 20 times, and the max / mean vertex strains at the end.

    Tolerance 3 %: the scaling adds rotational kinetic energy s t^2 / 12 |theta'|^2 = (r_g / l)^2 times the
    translational one for a deformation of length l (r_g = t sqrt(s / 12) = 0.039 m); the shortest length the
    4 x 4 mesh resolves is its element size l = 0.25 m, (r_g / l)^2 = 2.4 %, an upper bound on the relative
    change of the inertia forces, hence of the displacements and the (dynamic) strains they drive."""
    from fabricfem.verify.strain_limit import corner_pinned_cloth, run_cloth, shell_rotary_scale
    rule = shell_rotary_scale(corner_pinned_cloth(100.0, 4, model="naghdi", comm=MPI.COMM_SELF))
    assert rule["s"] == rule["s_accuracy"] == 14000.0
    kwargs = dict(k_over_rho=100.0, strain_limit=None, dt_factor=0.9, n=4, t_end=0.4, comm=MPI.COMM_SELF,
                  model="naghdi", samples=20)
    scaled = run_cloth(rotary_inertia_scale=None, **kwargs)
    physical = run_cloth(rotary_inertia_scale=1.0, **kwargs)
    assert scaled["s"] == 14000.0 and physical["s"] == 1.0
    assert scaled["dt"] > 40 * physical["dt"]
    assert np.allclose(scaled["times"], physical["times"], rtol=0, atol=1e-12)
    ref = physical["trajectory"]
    scale = np.abs(ref).max()
    assert scale > 0.3  # the cloth has swung (m)
    err = np.abs(scaled["trajectory"] - ref).max() / scale
    strain_err = {q: abs(scaled[q] - physical[q]) / abs(physical[q])
                  for q in ("max_warp", "max_weft", "mean_warp", "mean_weft")}
    print(f"rotary scaling s = {scaled['s']:g}: dt {scaled['dt']:.3g} vs {physical['dt']:.3g} s, trajectory "
          f"error {err:.2%} of {scale:.3f} m, strain errors {strain_err}")
    assert err < 0.03
    for q, e in strain_err.items():
        assert e < 0.03, q


@pytest.mark.mpi
def test_corner_pinned_cases_same_on_all_ranks_as_serial():
    """The corner-pinned-strain-limit cases (a), (b), (c) of fabricfem.verify.strain_limit with the case's
    model, the Naghdi shell with the bending law (case lengths reduced to t = 0.3 s of the 0.6 s for the
    suite), on COMM_WORLD against the same runs on COMM_SELF in this test: steps, rotary-inertia scale, max
    and mean warp/weft vertex strains and the projection iteration counts equal within 1e-8 relative (the
    runs differ only in the order of floating-point sums and in the CG reductions at rtol 1e-12; s is rounded
    up to 2 digits from a SLEPc estimate, so the ranks' 1e-6 differences in it do not enter)."""
    from fabricfem.verify.strain_limit import CASES, run_cloth
    for key, (k_over_rho, limit, factor) in CASES.items():
        parallel = run_cloth(k_over_rho, limit, factor, t_end=0.3, comm=MPI.COMM_WORLD, model="naghdi")
        serial = run_cloth(k_over_rho, limit, factor, t_end=0.3, comm=MPI.COMM_SELF, model="naghdi")
        assert parallel["steps"] == serial["steps"] and parallel["s"] == serial["s"]
        assert parallel["projection_iterations"] == serial["projection_iterations"], key
        for q in ("max_warp", "max_weft", "mean_warp", "mean_weft"):
            assert parallel[q] == pytest.approx(serial[q], rel=1e-8), (key, q)
