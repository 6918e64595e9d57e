"""Time integration (fabricfem.dynamics) against closed forms and conservation laws."""
import csv

import numpy as np
import pytest
from modal import first_mode
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.dynamics import (
    CentralDifference,
    DynamicsError,
    NewmarkIntegrator,
    consistent_mass,
    critical_time_step,
    discrete_max_frequency,
    lumped_mass,
    material_stiffness_form,
    max_frequency_estimate,
    node_monitor,
)
from fabricfem.dynamics.mass import assemble_matrix
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.verify.dynamics import STRIP, cantilever_strip, crossing_frequency, euler_bernoulli_f1


def _component_indicator(model, field, i):
    sub = model.W.sub(0 if field == "u" else 1).sub(i) if model.model == "naghdi" else model.W.sub(i)
    _, to_parent = sub.collapse()
    e = model.create_vector()
    with e.localForm() as local:
        local.set(0.0)
        local.array[np.asarray(to_parent)] = 1.0
    return e


@pytest.mark.mpi
@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_mass_totals(cell):
    """Lumped (eq. 2.82) and consistent mass carry rho t A per displacement component and rho t^3/12 A per
    rotation (closed form; 1e-12: sums of quadrature-exact integrals); every lumped entry is positive."""
    L, b, t, rho = 0.3, 0.1, 2e-3, 300.0
    model = ShellModel(plate(L, b, 6, 2, cell=cell), Fabric.isotropic(1e6, 0.3, t, density=rho))
    model.compile()
    mL, M = lumped_mass(model), consistent_mass(model)
    assert mL.min()[1] > 0
    for field, n, expected in (("u", 3, rho * t * L * b), ("theta", 2, rho * t ** 3 / 12 * L * b)):
        for i in range(n):
            e = _component_indicator(model, field, i)
            Me = e.duplicate()
            M.mult(e, Me)
            assert mL.dot(e) == pytest.approx(expected, rel=1e-12)
            assert Me.dot(e) == pytest.approx(expected, rel=1e-12)


@pytest.mark.mpi
def test_material_stiffness_is_the_tangent_when_stress_free():
    """K_M of eq. 2.85 equals the full tangent at the stress-free reference state (the geometric part is
    stress times the second strain variation, zero there); 1e-10 relative: round-off of two assemblies."""
    model = cantilever_strip(nx=6)
    model.w.x.array[:] = 0.0
    K = model.create_matrix()
    model.jacobian(model.w.vector, K)
    from dolfinx import fem
    KM = assemble_matrix(material_stiffness_form(model, fem.Function(model.W)), model.bcs)
    KM.axpy(-1.0, K)
    assert KM.norm(PETSc.NormType.FROBENIUS) < 1e-10 * K.norm(PETSc.NormType.FROBENIUS)


def _prestressed_string(nx=16, L=1.0, width=0.1, E=1e6, t=1e-3, rho=1000.0, strain=0.01, amplitude=1e-3):
    """Membrane strip pulled to strain eps between fixed ends (exact homogeneous stretch for nu = 0), with a
    transverse initial displacement A sin(pi x / L); f1 = sqrt(S11 / rho) / (2 L), S11 = E (eps + eps^2/2)."""
    model = ShellModel(plate(L, width, nx, 1, cell="quadrilateral"), Fabric.isotropic(E, 0.0, t, density=rho),
                       model="membrane")
    model.constrain("left", u=(0.0, 0.0, 0.0))
    model.constrain("right", u=(strain * L, 0.0, 0.0))
    model.compile()
    model.set_load_factor(1.0)
    for i, values in ((0, lambda x: strain * x[0]), (2, lambda x: amplitude * L * np.sin(np.pi * x[0] / L))):
        V, to_parent = model.W.sub(i).collapse()
        X = V.tabulate_dof_coordinates()
        model.w.x.array[np.asarray(to_parent)] = values(X.T)
    f1 = np.sqrt(E * (strain + strain ** 2 / 2) / rho) / (2.0 * L)
    return model, f1, np.array([L / 2, 0.0, 0.0])


@pytest.mark.mpi
@pytest.mark.parametrize("lumped", [False, True])
def test_prestressed_string_newmark(lumped):
    """Transverse frequency of a pre-stretched membrane string (consistent or lumped mass, trapezoidal,
    dt = T/80) against the closed form within 0.5%: period elongation (omega dt)^2/12 = 0.05%, FE error of
    16 Q2 cells for a sine ~1e-5 (consistent) / ~1e-3 (lumped), tension change from the 1e-3 L amplitude
    ~ (pi A/L)^2/4 / eps = 2.5e-4."""
    model, f1, mid = _prestressed_string()
    integrator = NewmarkIntegrator(model, 1.0 / (80 * f1), lumped=lumped)
    history = integrator.run(200, monitors={"w": node_monitor(model, mid, "u", 2)})
    f = crossing_frequency(np.asarray(history.time), np.asarray(history.monitors["w"]))
    assert f == pytest.approx(f1, rel=5e-3)
    assert max(history.newton_iterations) <= 4  # Newton stays quadratic (exact effective tangent)


def test_prestressed_string_explicit():
    """Same string with central differences and lumped mass at 0.9 dt_crit: frequency within 0.5%
    (period shortening (omega dt)^2/24 < 1e-6; lumped-mass dispersion of the 16-cell sine ~1e-3)."""
    model, f1, mid = _prestressed_string()
    dt = 0.9 * critical_time_step(model)
    n = int(np.ceil(1.6 / (f1 * dt)))
    integrator = CentralDifference(model, dt)
    history = integrator.run(n, monitors={"w": node_monitor(model, mid, "u", 2)}, output_every=4)
    f = crossing_frequency(np.asarray(history.time), np.asarray(history.monitors["w"]))
    assert f == pytest.approx(f1, rel=5e-3)


def _decay_rate(times, signal):
    """-slope of ln |local extrema| against time [1/s]."""
    s = np.abs(signal)
    peaks = np.nonzero((s[1:-1] > s[:-2]) & (s[1:-1] >= s[2:]))[0] + 1
    return -np.polyfit(times[peaks], np.log(s[peaks]), 1)[0]


@pytest.mark.parametrize("kind", ["mass", "stiffness"])
def test_rayleigh_damping_decay(kind):
    """Free decay of the first mode of the cantilever strip with C = a M (or b K_M): decay rate zeta omega1
    against the closed form zeta = a / (2 omega) + b omega / 2 with omega = Euler-Bernoulli omega1, within 3%:
    the trapezoidal rule changes the discrete damping by O((omega dt)^2) = 1% at dt = T/60, omega1(FE) vs
    Euler-Bernoulli 0.01%, peak sampling +-0.15% per peak."""
    model = cantilever_strip(nx=8)
    model.w.x.array[:] = 0.0
    omega_fe, mode = first_mode(model)
    omega = 2 * np.pi * euler_bernoulli_f1(**STRIP)
    zeta = 0.03
    rayleigh = (2 * zeta * omega, 0.0) if kind == "mass" else (0.0, 2 * zeta / omega)
    tip = np.array([STRIP["L"], 0.0, 0.0])
    mode.scale(1e-4 * STRIP["L"] / abs(mode.getArray()[model.owned_node_dof(tip, "u", 2)]))
    dt = 2 * np.pi / (60 * omega_fe)
    integrator = NewmarkIntegrator(model, dt, load_factor=0.0, rayleigh=rayleigh)
    integrator.initialize(displacement=mode)
    history = integrator.run(180, monitors={"w": node_monitor(model, tip, "u", 2)})
    sigma = _decay_rate(np.asarray(history.time), np.asarray(history.monitors["w"]))
    a, b = rayleigh
    reference = (a / (2 * omega) + b * omega / 2) * omega
    assert sigma == pytest.approx(reference, rel=0.03)
    # energy balance with damping: E_kin + E_strain + dissipated = E0 (trapezoidal bookkeeping of C v . dd;
    # 1% of E0: C is frozen per step and v is averaged over the step)
    total = np.asarray(history.kinetic) + np.asarray(history.strain) + np.asarray(history.dissipated)
    assert np.abs(total - total[0]).max() < 0.01 * total[0]


@pytest.mark.mpi
@pytest.mark.parametrize("scheme", ["newmark", "explicit"])
def test_air_drag_rigid_translation(scheme):
    """A free sheet moving rigidly with v0 under air drag f = -eta v decays as v0 exp(-eta t / (rho t))
    ([Peng2022] drag, closed form; 1e-4: the trapezoidal/central-difference error per step is
    (eta dt / rho t)^3 / 12 ~ 1e-9, strain energy stays zero)."""
    rho, t, eta = 500.0, 1e-3, 0.25  # eta / (rho t) = 0.5 1/s
    model = ShellModel(plate(0.2, 0.2, 2, 2, cell="quadrilateral"), Fabric.isotropic(1e5, 0.3, t, density=rho),
                       model="membrane")
    model.compile()
    v0 = model.create_vector()
    V, to_parent = model.W.sub(2).collapse()
    v0.set(0.0)
    owned = np.asarray(to_parent)
    v0.getArray()[owned[owned < v0.getLocalSize()]] = 0.1
    dt = 0.01 if scheme == "newmark" else min(0.01, 0.9 * critical_time_step(model))
    cls = NewmarkIntegrator if scheme == "newmark" else CentralDifference
    integrator = cls(model, dt, load_factor=0.0, air_drag=eta)
    integrator.initialize(velocity=v0)
    n = int(round(1.0 / dt))
    history = integrator.run(n, output_every=n)
    expected_ke = 0.5 * rho * t * 0.2 * 0.2 * (0.1 * np.exp(-eta / (rho * t) * history.time[-1])) ** 2
    assert history.kinetic[-1] == pytest.approx(expected_ke, rel=2e-4)  # KE ~ v^2: twice the 1e-4 on v
    assert abs(history.strain[-1]) < 1e-12 * expected_ke


@pytest.mark.mpi
def test_energy_balance_with_time_varying_load():
    """Undamped trapezoidal rule: E_kin + E_strain - int F . dd (trapezoidal in time) stays constant for a
    load ramped and oscillated in time (exact for linear systems; 1e-6 of the max strain energy covers the
    4e-4 L amplitude geometric nonlinearity and the Newton tolerance)."""
    model = cantilever_strip(nx=6)
    f1 = euler_bernoulli_f1(**STRIP)
    integrator = NewmarkIntegrator(model, 1 / (30 * f1), load_factor=lambda time: np.sin(1.7 * f1 * time) ** 2)
    history = integrator.run(60)
    drift = np.abs(history.total - history.total[0]).max()
    assert drift < 1e-6 * max(history.strain)
    assert max(history.strain) > 0


def test_critical_time_step_estimate_is_conservative_and_close():
    """The estimate of eqs. 2.86-2.87 (extended to Q2/P2 elements and thickness shear) against the largest
    discrete frequency of K vs M_L (SLEPc): conservative and within 5% on quads and triangles."""
    for cell in ("quadrilateral", "triangle"):
        model = ShellModel(plate(0.2, 0.02, 20, 1, cell=cell),
                           Fabric.isotropic(STRIP["E"], 0.0, STRIP["t"], density=STRIP["rho"])).clamp("left")
        model.compile()
        estimate, discrete = max_frequency_estimate(model), discrete_max_frequency(model)
        assert discrete <= estimate <= 1.05 * discrete, (cell, estimate, discrete)


def test_bad_input():
    model = cantilever_strip(nx=4)
    dt_crit = critical_time_step(model)
    with pytest.raises(ValueError, match="dt"):
        NewmarkIntegrator(model, -1e-3)
    with pytest.raises(ValueError, match="dt"):
        CentralDifference(model, float("nan"))
    with pytest.raises(ValueError, match="gamma"):
        NewmarkIntegrator(model, 1e-3, gamma=0.4)
    with pytest.raises(ValueError, match="beta"):
        NewmarkIntegrator(model, 1e-3, beta=0.1, gamma=0.5)
    with pytest.raises(ValueError, match=r"critical time step.*\d"):
        CentralDifference(model, 1.1 * dt_crit)
    with pytest.raises(ValueError, match="rayleigh"):
        NewmarkIntegrator(model, 1e-3, rayleigh=(-1.0, 0.0))
    with pytest.raises(ValueError, match="air_drag"):
        NewmarkIntegrator(model, 1e-3, air_drag=-0.1)
    with pytest.raises(ValueError, match="n_steps"):
        NewmarkIntegrator(model, 1e-3).run(0)
    massless = ShellModel(plate(0.1, 0.1, 2, 2), Fabric.isotropic(1e6, 0.0, 1e-3))
    with pytest.raises(ValueError, match="density"):
        NewmarkIntegrator(massless, 1e-3)


def test_blow_up_is_stopped_with_step_and_time():
    """Above the limit (force=True) the run stops with DynamicsError naming step and time, not NaN."""
    model = cantilever_strip(nx=4)
    integrator = CentralDifference(model, 3.0 * critical_time_step(model), force=True)
    with pytest.raises(DynamicsError, match=r"step \d+ \(t = ") as info:
        integrator.run(500)
    assert 0 < info.value.step < 500 and np.isfinite(integrator.d.norm())


def test_outputs(tmp_path, capsys):
    """XDMF time series, CSV of the monitored quantities and a progress line with the time left."""
    model = cantilever_strip(nx=4)
    f1 = euler_bernoulli_f1(**STRIP)
    integrator = NewmarkIntegrator(model, 1 / (20 * f1))
    tip = node_monitor(model, (STRIP["L"], 0.0, 0.0), "u", 2)
    integrator.run(10, monitors={"tip_w": tip}, xdmf=tmp_path / "run.xdmf", csv=tmp_path / "run.csv",
                   output_every=2, progress=True)
    if MPI.COMM_WORLD.rank == 0:
        assert (tmp_path / "run.xdmf").exists() and (tmp_path / "run.h5").exists()
        rows = list(csv.reader(open(tmp_path / "run.csv")))
        assert rows[0] == ["time", "kinetic", "strain", "external_work", "dissipated", "total", "tip_w"]
        assert len(rows) == 1 + 6
        assert "left ~" in capsys.readouterr().out


def test_critical_time_step_estimate_includes_the_nonlinear_bending_tangent():
    """[Peng2022]'s cloth with the regularised square-root bending law (initial tangent 2 B0 sqrt(kappa0 / eps)
    = 63 B0): its rotational modes set the step (the shear-and-membrane estimate alone was 7x too high).
    The estimate must be conservative and within 12% of the largest discrete frequency (SLEPc) on Q2 and
    P2 + bubble meshes, without and with rotary-inertia scaling. 12%: the three frequency terms are added
    in quadrature although they belong to partly different modes (measured 1.3-11%)."""
    from fabricfem.verify.strain_limit import cloth_fabric
    for cell in ("quadrilateral", "triangle"):
        for k_over_rho in (100.0, 1000.0):
            model = ShellModel(plate(1.0, 1.0, 6, 6, cell=cell), cloth_fabric(k_over_rho), model="naghdi",
                               psri_degrees=(4, 4)).clamp("left")
            model.compile()
            for s in (1.0, 1e3):
                estimate = max_frequency_estimate(model, rotary_inertia_scale=s)
                discrete = discrete_max_frequency(model, rotary_inertia_scale=s, iterations=1000)
                assert discrete <= estimate <= 1.12 * discrete, (cell, k_over_rho, s, estimate, discrete)


@pytest.mark.mpi
def test_mass_scaling_keeps_the_physical_weight_and_damping():
    """Mass scaling S [Belytschko2000, ch. 6]: a free membrane sheet falling under its weight with C = a M of the
    physical mass, all lumped masses x S: S dv/dt = g - a v, so v(t) = (g / a)(1 - exp(-a t / S)) and the
    fall z(t) = -(g / a)(t - S / a (1 - exp(-a t / S))) (closed form; the displacement update d + dt v +
    dt^2 a / 2 leaves out dt^3 / 6 of the jerk -(a / S)(g / S) per step: t dt^2 (a / S)(g / S) / 6 = 3.2e-7 m
    (1.1e-6 relative) at t = 1 s, dt = 5 ms; tolerance 3e-6); the critical step grows by sqrt(S) exactly
    (undamped)."""
    rho, t, g, a, S = 500.0, 1e-3, 9.81, 2.0, 16.0
    model = ShellModel(plate(0.2, 0.2, 2, 2, cell="quadrilateral"), Fabric.isotropic(1e5, 0.3, t, density=rho),
                       model="membrane")
    model.add_gravity((0.0, 0.0, -g))
    model.compile()
    assert critical_time_step(model, mass_scale=S) == pytest.approx(np.sqrt(S) * critical_time_step(model),
                                                                     rel=1e-14)
    dt = 0.005
    integrator = CentralDifference(model, dt, rayleigh=(a, 0.0), mass_scale=S)
    physical = lumped_mass(model)
    assert integrator.ops.mass_diag.norm() == pytest.approx(S * physical.norm(), rel=1e-14)
    n = 200
    corner = node_monitor(model, np.array([0.0, 0.0, 0.0]), "u", 2)
    history = integrator.run(n, monitors={"z": corner}, output_every=n)
    time_ = history.time[-1]
    expected = -(g / a) * (time_ - S / a * (1.0 - np.exp(-a * time_ / S)))
    assert history.monitors["z"][-1] == pytest.approx(expected, rel=3e-6)
    with pytest.raises(ValueError, match="mass_scale"):
        CentralDifference(model, dt, mass_scale=0.5)


def test_eigenvalue_critical_step_is_the_dense_eigenvalue_and_the_stability_limit():
    """The critical step of the explicit routes by default (stability.max_frequency "eigenvalue"): SLEPc's largest
    omega of K vs M_L (rotary-inertia scale 100, as the wear engine) bounds the dense generalized eigenvalue of
    the free dofs (scipy) from above by at most sqrt(1 + rtol) - 1 = 5e-5 relative (the Ritz value within rtol = 1e-4
    of an eigenvalue, times 1 + rtol [Parlett1998, thm. 4.5.1]), and central differences [Man2006, eq. 2.86] of
    the same sheet under its weight (undamped, amplitudes ~1e-6 m: linear) stay bounded at 0.97 x 2 / omega and
    blow up at 1.03 x (their exact limit dt omega = 2, growth 1.3 per step at 1.03: past the energy bound within
    the 400 steps run)."""
    import scipy.linalg

    from fabricfem.dynamics.explicit import runs_stably
    from fabricfem.dynamics.stability import max_frequency
    model = ShellModel(plate(0.2, 0.05, 6, 2, cell="quadrilateral"),
                       Fabric.isotropic(STRIP["E"], 0.3, STRIP["t"], density=STRIP["rho"])).clamp("left")
    model.add_gravity()
    model.compile()
    s = 100.0
    omega = max_frequency(model, s, "eigenvalue")
    K = model.create_matrix()
    model.jacobian(model.w.vector, K)
    m = lumped_mass(model, rotary_inertia_scale=s).getArray()
    free = np.setdiff1d(np.arange(m.size), np.concatenate([bc.dof_indices()[0] for bc in model.bcs]))
    Kd = K.convert("dense").getDenseArray()[np.ix_(free, free)]
    dense = np.sqrt(scipy.linalg.eigh(Kd, np.diag(m[free]), eigvals_only=True)[-1])
    assert dense * (1.0 - 1e-12) <= omega <= dense * (1.0 + 1e-4)
    assert omega < max_frequency(model, s, "estimate")
    assert runs_stably(model, 0.97 * 2.0 / omega, 400, rotary_inertia_scale=s)
    assert not runs_stably(model, 1.03 * 2.0 / omega, 400, rotary_inertia_scale=s)
    with pytest.raises(ValueError, match="critical_step"):
        max_frequency(model, s, "guess")
