"""Generalized-alpha (PETSc TS ALPHA2) and step halving of the implicit integrators, against closed forms and
conservation laws."""
import numpy as np
import pytest
from modal import first_mode
from mpi4py import MPI

from fabricfem.dynamics import DynamicsError, GeneralizedAlphaIntegrator, NewmarkIntegrator, node_monitor
from fabricfem.verify.dynamics import STRIP, cantilever_strip, crossing_frequency, euler_bernoulli_f1
from fabricfem.verify.ts_cases import strip_free_vibration

TIP = np.array([STRIP["L"], 0.0, 0.0])


def chung_hulbert_amplification(rho_inf: float, omega_dt: float) -> np.ndarray:
    """Eigenvalues of the generalized-alpha amplification matrix for u'' + omega^2 u = 0 (Chung & Hulbert 1993,
    eqs. 10-16 and 25 in their convention: alpha weights the OLD state), independent of PETSc.

    State (d, dt v, dt^2 a); the three equations d1 = d0 + v0 + (1/2 - beta) a0 + beta a1, v1 = v0 + (1 - gamma)
    a0 + gamma a1 and (1 - alpha_m) a1 + alpha_m a0 + x^2 ((1 - alpha_f) d1 + alpha_f d0) = 0 with x = omega dt.
    """
    alpha_m = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
    alpha_f = rho_inf / (rho_inf + 1.0)
    gamma = 0.5 - alpha_m + alpha_f
    beta = 0.25 * (1.0 - alpha_m + alpha_f) ** 2
    x2 = omega_dt ** 2
    lhs = np.array([[1.0, 0.0, -beta], [0.0, 1.0, -gamma], [(1.0 - alpha_f) * x2, 0.0, 1.0 - alpha_m]])
    rhs = np.array([[1.0, 1.0, 0.5 - beta], [0.0, 1.0, 1.0 - gamma], [-alpha_f * x2, 0.0, -alpha_m]])
    return np.linalg.eigvals(np.linalg.solve(lhs, rhs))


def _two_root_fit(signal: np.ndarray) -> complex:
    """Principal root lambda of a sampled signal s_{n+1} = 2 Re(lambda) s_n - |lambda|^2 s_{n-1} (least squares,
    Prony's method): exact for a combination of one complex-conjugate root pair."""
    s = np.asarray(signal)
    A = np.column_stack([s[1:-1], s[:-2]])
    (p1, p2), *_ = np.linalg.lstsq(A, s[2:], rcond=None)
    modulus = np.sqrt(-p2)
    return modulus * np.exp(1j * np.arccos(p1 / (2.0 * modulus)))


def test_parameters_and_bad_input():
    """rho_inf = 1 gives the mid-step trapezoidal rule (1/2, 1/2, 1/2, 1/4); bad input raises ValueError."""
    from fabricfem.dynamics import generalized_alpha_parameters
    assert generalized_alpha_parameters(1.0) == pytest.approx((0.5, 0.5, 0.5, 0.25), abs=1e-15)
    model = cantilever_strip(nx=4)
    with pytest.raises(ValueError, match="rho_inf"):
        GeneralizedAlphaIntegrator(model, 1e-3, rho_inf=1.5)
    with pytest.raises(ValueError, match="dt"):
        GeneralizedAlphaIntegrator(model, -1e-3)
    with pytest.raises(ValueError, match="min_dt"):
        NewmarkIntegrator(model, 1e-3, min_dt=2e-3)
    with pytest.raises(ValueError, match="grow_after"):
        GeneralizedAlphaIntegrator(model, 1e-3, grow_after=0)


@pytest.mark.mpi
def test_free_vibration_no_dissipation():
    """rho_inf = 1 on the cantilever strip (10 Q2 shells), dt = T1/40, 200 steps from rest under the suddenly applied
    load: frequency vs Euler-Bernoulli within 2% (period elongation (omega dt)^2/12 = 0.2%, FE error of 10 Q2
    cells < 0.1%) and energy drift / max strain energy < 1e-4 (exact for a linear system; the 4e-4 L geometric
    nonlinearity enters at ~1e-6)."""
    times, tip_w, history, _ = strip_free_vibration(nx=10)
    f1 = euler_bernoulli_f1(**STRIP)
    assert crossing_frequency(times, tip_w) == pytest.approx(f1, rel=0.02)
    assert np.abs(history.total - history.total[0]).max() < 1e-4 * max(history.strain)
    assert history.time[-1] == pytest.approx(200 / (40 * f1), rel=1e-12)


@pytest.mark.parametrize("rho_inf", [0.5, 0.0])
def test_numerical_dissipation_matches_spectral_radius(rho_inf):
    """The strip released from its first mode (amplitude 1e-6 L: linear) with rho_inf < 1 at omega1 dt = 1: the
    principal root of the tip history (two-root Prony fit after 20 steps, when the spurious root excited by the
    start-up, |lambda_3| <= 0.41, has decayed below 1e-7) against the closed-form amplification matrix of
    Chung & Hulbert at omega1 (FE) dt. Decay per step 1 - |lambda| within 1% relative and the phase per step
    within 1e-4 relative: the signal is a single discrete mode up to the geometric nonlinearity ((1e-6)^2) and
    the Newton tolerance (1e-9 relative per step)."""
    model = cantilever_strip(nx=8)
    model.w.x.array[:] = 0.0
    omega, mode = first_mode(model)
    mode.scale(1e-6 * STRIP["L"] / abs(mode.getArray()[model.owned_node_dof(TIP, "u", 2)]))
    omega_dt = 1.0
    integrator = GeneralizedAlphaIntegrator(model, omega_dt / omega, rho_inf=rho_inf, load_factor=0.0)
    integrator.initialize(displacement=mode)
    history = integrator.run(80, monitors={"w": node_monitor(model, TIP, "u", 2)})
    root = _two_root_fit(np.asarray(history.monitors["w"])[20:])
    roots = chung_hulbert_amplification(rho_inf, omega_dt)
    principal = roots[np.argmax(np.abs(roots.imag))]
    decay_measured, decay_expected = 1.0 - abs(root), 1.0 - abs(principal)
    print(f"rho_inf {rho_inf}: |lambda| measured {abs(root):.8f}, closed form {abs(principal):.8f}; amplitude ratio "
          f"per period {abs(root) ** (2 * np.pi / np.angle(root)):.6f} vs "
          f"{abs(principal) ** (2 * np.pi / abs(np.angle(principal))):.6f}")
    assert decay_expected > 0.01  # the case really measures dissipation
    assert decay_measured == pytest.approx(decay_expected, rel=0.01)
    assert np.angle(root) == pytest.approx(abs(np.angle(principal)), rel=1e-4)


def test_consistent_with_trapezoidal_newmark():
    """Extra consistency check (not an independent reference): rho_inf = 1 and Newmark trapezoidal give the same tip
    history on the strip; the two differ only by where the geometric nonlinearity is evaluated (mid-step
    displacement vs mean of the end forces: O((4e-4)^2) of the amplitude) and the Newton tolerances -> 1e-4."""
    f1 = euler_bernoulli_f1(**STRIP)
    histories = []
    for cls in (GeneralizedAlphaIntegrator, NewmarkIntegrator):
        model = cantilever_strip(nx=6)
        integrator = cls(model, 1 / (30 * f1), load_factor=1.0)
        histories.append(np.asarray(integrator.run(60, monitors={"w": node_monitor(model, TIP, "u", 2)}).monitors["w"]))
    assert np.abs(histories[0] - histories[1]).max() < 1e-4 * np.abs(histories[1]).max()


def _large_load_run(cls, min_dt=None, n_steps=10):
    """Strip (8 Q2) under a suddenly applied load 300 x the linear-regime one (tip swings to ~0.24 L, rotations
    ~0.7 rad) at dt = T1/20 with Newton limited to 6 iterations: the full step does not converge."""
    model = cantilever_strip(nx=8)
    model.w.x.array[:] = 0.0
    dt = 1 / (20 * euler_bernoulli_f1(**STRIP))
    integrator = cls(model, dt, load_factor=300.0, newton_options={"snes_max_it": 6}, min_dt=min_dt)
    history = integrator.run(n_steps, monitors={"w": node_monitor(model, TIP, "u", 2)})
    return integrator, history, dt


@pytest.mark.mpi
@pytest.mark.parametrize("cls", [NewmarkIntegrator, GeneralizedAlphaIntegrator])
def test_step_halving_recovers(cls):
    """Without halving (min_dt = dt) the large load step fails with DynamicsError naming time, dt and the Newton
    reason; with halving (default min_dt = dt/64) the run completes, outputs stay on the user grid (k dt), the
    sub-step grows back (never above dt), and energy is conserved (undamped, constant load: E_kin + E_strain - W =
    const, exactly for linear problems; on this geometrically nonlinear swing the trapezoidal / mid-point rules
    err by O((omega1 dt)^2) = (2 pi / 20)^2 = 0.1 of the energy scale)."""
    with pytest.raises(DynamicsError, match=r"t = .* s with dt = .* s .*DIVERGED_MAX_IT|DIVERGED_MAX_IT.*dt = "):
        _large_load_run(cls, min_dt=1.0 / (20 * euler_bernoulli_f1(**STRIP)))
    integrator, history, dt = _large_load_run(cls)
    assert integrator.halvings > 0 and integrator.substeps > 10
    assert np.allclose(history.time, dt * np.arange(11), rtol=0, atol=1e-12 * dt)
    assert integrator.doublings > 0 and integrator.current_dt <= dt  # grows back, never above dt
    assert min(history.monitors["w"]) < -0.2 * STRIP["L"]  # really a large swing
    drift = np.abs(history.total - history.total[0]).max()
    print(f"{cls.__name__}: {integrator.halvings} halvings, {integrator.substeps} sub-steps, energy drift "
          f"{drift / max(history.strain):.3e} of max strain energy")
    assert drift < 0.1 * max(history.strain)


@pytest.mark.mpi
@pytest.mark.parametrize("cls", [NewmarkIntegrator, GeneralizedAlphaIntegrator])
def test_failure_restores_last_converged_state(cls):
    """A load factor that turns NaN right after t = 2 dt (a contrived Newton failure at every sub-step down to
    min_dt): DynamicsError names the time, dt and Newton reason, and integrator and model.w hold exactly the state
    of t = 2 dt (a large but finite load jump is no such case: at small sub-steps inertia keeps Newton converging)."""
    model = cantilever_strip(nx=4)
    f1 = euler_bernoulli_f1(**STRIP)
    dt = 1 / (20 * f1)
    integrator = cls(model, dt, load_factor=lambda t: 1.0 if t <= 2 * dt * (1 + 1e-9) else float("nan"))
    integrator.run(2)
    state = model.w.x.array.copy()
    velocity = integrator.v.getArray().copy()
    with pytest.raises(DynamicsError) as info:
        integrator.run(3)
    error = info.value
    assert error.last_converged_time == pytest.approx(2 * dt, rel=1e-12)
    assert error.dt == pytest.approx(dt / 64, rel=1e-12) and error.reason
    assert error.step == 3 and error.time == pytest.approx(2 * dt + dt / 64, rel=1e-12)
    assert "dt = " in str(error) and error.reason in str(error)
    assert integrator.t == pytest.approx(2 * dt, rel=1e-12)
    assert np.array_equal(model.w.x.array, state)
    assert np.array_equal(integrator.v.getArray(), velocity)
    assert float(model.load_factor.value) == 1.0
    # a finite state, and the integrator can go on from it with a sane load (no stale solver state)
    assert np.isfinite(state).all()
    assert MPI.COMM_WORLD.allreduce(int(np.isfinite(integrator.d.getArray()).all()), op=MPI.MIN) == 1


def test_refused_newton_state_halves_the_newmark_step():
    """A sub-step whose Newton solve the solver guard refuses (SolverError, an absurd "converged" state: see
    fabricfem.solvers.newton) is a failed sub-step like a diverged one: halved and retried, not the end of the
    run. The first solve is made to raise; the run must complete on the user grid with one halving, and its
    tip history must equal an undisturbed run to the integrator's own accuracy (the halved first step only
    changes the time discretisation of that step: 1e-2 of the amplitude is the O((omega dt)^2) bound)."""
    from fabricfem.solvers.newton import SolverError

    f1 = euler_bernoulli_f1(**STRIP)
    runs = []
    for refuse_first in (False, True):
        model = cantilever_strip(nx=6)
        integrator = NewmarkIntegrator(model, 1 / (30 * f1), load_factor=1.0)
        if refuse_first:
            solve, calls = integrator.solver.solve, []

            def refusing_solve():
                calls.append(1)
                if len(calls) == 1:
                    raise SolverError("ABSURD_INCREMENT: constructed", reason="ABSURD_INCREMENT")
                return solve()
            integrator.solver.solve = refusing_solve
        history = integrator.run(10, monitors={"w": node_monitor(model, TIP, "u", 2)})
        runs.append((integrator, np.asarray(history.monitors["w"])))
    (plain, w_plain), (refused, w_refused) = runs
    assert plain.halvings == 0 and refused.halvings == 1
    assert np.abs(w_refused - w_plain).max() < 1e-2 * np.abs(w_plain).max()


def test_mumps_options_reach_the_factorization():
    """Options read when TS's LU factor is set up (MUMPS ICNTL(14)) are in the database during the step: they
    used to be removed after setFromOptions and silently ignored (MUMPS default ICNTL(14) = 20 or 30)."""
    model = cantilever_strip(nx=4)
    integrator = GeneralizedAlphaIntegrator(model, 1e-4, load_factor=1.0, newton_options={"mat_mumps_icntl_14": 50})
    integrator.initialize()
    integrator.run(1)
    assert integrator.ts.getSNES().getKSP().getPC().getFactorMatrix().getMumpsIcntl(14) == 50
