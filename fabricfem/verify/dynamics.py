"""Free vibration of a cantilever strip: implicit Newmark frequency and energy, explicit stability limit."""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fabricfem.dynamics import (
    CentralDifference,
    NewmarkIntegrator,
    critical_time_step,
    measured_critical_time_step,
    node_monitor,
)
from fabricfem.dynamics.explicit import runs_stably
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.newton import NewtonSolver
from fabricfem.verify import Timer, case, result

# A fabric-like strip (SI): L x width, thickness t, E t = 2.5 kN/m, 0.2 kg/m^2, nu = 0 (plate strip = beam)
STRIP = dict(L=0.2, width=0.02, t=0.5e-3, E=5e6, rho=400.0)


def euler_bernoulli_f1(L: float, width: float, t: float, E: float, rho: float) -> float:
    """First bending frequency [Hz] of a clamped-free beam: f1 = 1.8751^2 / (2 pi L^2) sqrt(EI / (rho A))."""
    EI = E * width * t ** 3 / 12.0
    return 1.8751 ** 2 / (2.0 * np.pi * L ** 2) * np.sqrt(EI / (rho * width * t))


def cantilever_strip(nx: int = 20, comm=MPI.COMM_WORLD, L: float = STRIP["L"], width: float = STRIP["width"],
                     t: float = STRIP["t"], E: float = STRIP["E"], rho: float = STRIP["rho"]) -> ShellModel:
    """Quadrilateral Naghdi strip clamped at x = 0 under a uniform transverse load q with static tip deflection
    about 4e-4 L (q L^4 / (8 EI) per unit width: small amplitude, linear regime)."""
    fabric = Fabric.isotropic(E, 0.0, t, density=rho)
    model = ShellModel(plate(L, width, nx, 1, cell="quadrilateral", comm=comm), fabric)
    model.clamp("left")
    EI_per_width = E * t ** 3 / 12.0
    q = 8.0 * EI_per_width * 4e-4 * L / L ** 4  # N/m^2
    model.add_body_force((0.0, 0.0, -q))
    model.compile()
    return model


def static_tip_deflection(model: ShellModel, tip: np.ndarray) -> float:
    """w [m] at `tip` of the static equilibrium under the full load (the centre of the free vibration); the
    model is reset to the undeformed state with load factor 1 afterwards (released from rest)."""
    model.set_load_factor(1.0)
    solver = NewtonSolver(model)
    if not solver.solve().converged:
        raise RuntimeError("static solve of the free-vibration strip failed")
    solver.destroy()
    w_static = float(model.node_value(tip)[2])
    model.w.x.array[:] = 0.0
    return w_static


def crossing_frequency(times: np.ndarray, signal: np.ndarray) -> float:
    """Frequency [Hz] from the linearly interpolated zero crossings of `signal` (first to last crossing)."""
    s = np.asarray(signal)
    idx = np.nonzero(np.signbit(s[:-1]) != np.signbit(s[1:]))[0]
    if len(idx) < 3:
        raise ValueError("fewer than 3 zero crossings: run longer")
    tc = times[idx] - s[idx] * (times[idx + 1] - times[idx]) / (s[idx + 1] - s[idx])
    return (len(tc) - 1) / (2.0 * (tc[-1] - tc[0]))


def _explicit_is_stable(model: ShellModel, dt: float, n_steps: int = 400) -> bool:
    """Run n_steps central-difference steps from rest under the step load; False if stopped as blown up."""
    return runs_stably(model, dt, n_steps, reset=False)


@case("free-vibration", mpi=True)
def free_vibration(nx: int = 20, steps_per_period: int = 40, n_steps: int = 200) -> list:
    """Cantilever strip (L = 0.2 m, 20 Q2 shells, t/L = 1/400) released from rest under a suddenly applied
    uniform load.

    * Newmark trapezoidal, consistent mass, dt = T1/40: the tip oscillates about the static deflection; its
      frequency (zero crossings over 5 periods) against Euler-Bernoulli within 2%. Expected error: period
      elongation (omega dt)^2 / 12 = 0.2% of the trapezoidal rule, FE error < 0.01% (Q2, 20 elements),
      shear/rotary inertia O((t/L)^2) = 1e-5.
    * kinetic + strain energy - work of the constant load is conserved by the undamped trapezoidal rule
      (exactly for a linear system): max drift over 200 steps / max strain energy < 1e-4; the geometric
      nonlinearity at 4e-4 L amplitude and the Newton tolerance (1e-9 relative) are far below.
    * central differences (lumped mass, eq. 2.82): dt = 0.9 dt_crit runs 400 steps, 1.1 dt_crit is refused
      (ValueError), 2 dt_crit with force=True is stopped by the blow-up check (DynamicsError). The largest
      stable step measured by bisection (0.5% resolution, 400-step runs) against the estimate dt_crit: within
      5% (and not below it: the estimate must be conservative).
    """
    out = []
    name = "free-vibration"
    with Timer() as timer:
        model = cantilever_strip(nx)
        tip = np.array([STRIP["L"], 0.0, 0.0])
        f1 = euler_bernoulli_f1(**STRIP)
        w_static = static_tip_deflection(model, tip)  # the centre of the oscillation
        dt = 1.0 / (f1 * steps_per_period)
        newmark = NewmarkIntegrator(model, dt, beta=0.25, gamma=0.5, load_factor=1.0)
        history = newmark.run(n_steps, monitors={"tip_w": node_monitor(model, tip, "u", 2)})
        newmark.destroy()
        times = np.asarray(history.time)
        f_measured = crossing_frequency(times, np.asarray(history.monitors["tip_w"]) - w_static)
        drift = float(np.abs(history.total - history.total[0]).max() / max(history.strain))
    ndofs = model.ndofs
    out.append(result(name, "first natural frequency [Hz], Newmark vs Euler-Bernoulli", f_measured, f1, 0.02,
                      ndofs, timer.elapsed))
    out.append(result(name, "max |E_kin + E_strain - W_ext drift| / max E_strain, 200 trapezoidal steps", drift,
                      0.0, 1e-4, ndofs, timer.elapsed, scale=1.0))

    with Timer() as timer:
        dt_crit = critical_time_step(model)
        stable_09 = _explicit_is_stable(model, 0.9 * dt_crit)
        try:
            CentralDifference(model, 1.1 * dt_crit)
            refused = False
        except ValueError:
            refused = True
        stopped_2 = not _explicit_is_stable(model, 2.0 * dt_crit)
        measured = measured_critical_time_step(lambda step: _explicit_is_stable(model, step),
                                               0.9 * dt_crit, 1.5 * dt_crit, rel_tol=0.005)
    for quantity, ok in (("explicit dt = 0.9 dt_crit stable over 400 steps (1 = yes)", stable_09),
                         ("explicit dt = 1.1 dt_crit refused with ValueError (1 = yes)", refused),
                         ("explicit dt = 2 dt_crit (force=True) stopped by DynamicsError (1 = yes)", stopped_2)):
        out.append(result(name, quantity, float(ok), 1.0, 0.0, ndofs, timer.elapsed))
    ratio = measured / dt_crit
    out.append(result(name, f"measured stable dt / dt_crit estimate (dt_crit = {dt_crit:.4g} s)", ratio, 1.0,
                      0.05, ndofs, timer.elapsed))
    out.append(result(name, "estimate conservative: max(0, 1 - measured / dt_crit)", max(0.0, 1.0 - ratio), 0.0,
                      0.0, ndofs, timer.elapsed, scale=1.0))
    return out
