"""fabricfem.wear.compression: Laplace's law in its small-strain limit, bad input, and a failed donning step
leaving the last converged state (the physics check against the FE model is the verify case
compression-laplace)."""
import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact.problem import ContactProblem
from fabricfem.solvers.newton import SolverError
from fabricfem.verify import compression as case
from fabricfem.wear.compression import don, grown, laplace_pressure


def test_laplace_small_strain_limit():
    """lambda -> 1: T -> E t eps with E = Q22 (axial held) or E2 (axial free), p = T / R0."""
    eps = 1e-6
    fabric = case.KNIT
    held = laplace_pressure(fabric, 0.04, 0.04 * (1 + eps), "held")
    free = laplace_pressure(fabric, 0.04, 0.04 * (1 + eps), "free")
    q22 = fabric.E2 / (1 - fabric.nu12 * fabric.nu21)
    assert held.pressure == pytest.approx(q22 * fabric.thickness * eps / 0.04, rel=1e-5)
    assert free.pressure == pytest.approx(fabric.E2 * fabric.thickness * eps / 0.04, rel=1e-5)
    assert free.axial_stretch == pytest.approx(1 - fabric.nu21 * eps, rel=1e-9)


@pytest.mark.parametrize("kwargs, name", [(dict(relaxed_radius=-0.04), "relaxed_radius"),
                                          (dict(radius=0.0), "radius"), (dict(axial="fixed"), "axial")])
def test_laplace_bad_input(kwargs, name):
    args = dict(fabric=case.KNIT, relaxed_radius=0.04, radius=0.05, axial="held") | kwargs
    with pytest.raises(ValueError, match=name):
        laplace_pressure(**args)


def test_grown_scales_transverse_radii_only():
    limb = Ellipsoid(np.zeros(3), np.eye(3), np.array([0.2, 0.05, 0.04]))
    assert np.allclose(grown(limb, 0.5).radii, [0.2, 0.025, 0.02])


def test_failed_donning_step_restores_last_state(monkeypatch):
    """The second increment fails at every size: after 4 halvings SolverError names the factors, and the model
    holds the first step's state (as committed after it, director re-based)."""
    from fabricfem.materials import Fabric
    from fabricfem.meshes import tube
    from fabricfem.shell import ShellModel
    model = ShellModel(tube(0.05, 0.04, 8, 2, order=2, comm=MPI.COMM_WORLD),
                       Fabric(E1=2e5, E2=1e5, G12=3e4, nu12=0.2, thickness=5e-4))
    model.constrain("end0", u=(0.0, None, None))
    model.constrain(lambda x: np.isclose(x[1], 0.0, atol=1e-9) & (x[2] > 0.0), u=(None, 0.0, None))
    limb = Ellipsoid(np.zeros(3), np.eye(3), np.array([1.0, 0.044, 0.044]))
    problem = ContactProblem(model, [limb], method="augmented")
    with pytest.raises(ValueError, match="start"):
        don(problem, [limb], start=1.5)
    original = problem.solve_augmented
    states = []

    def second_fails(*args, **kwargs):
        if states:
            model.w.x.array[:] = np.nan
            raise SolverError("Newton DIVERGED_MAX_IT", reason="DIVERGED_MAX_IT")
        return original(*args, **kwargs)

    monkeypatch.setattr(problem, "solve_augmented", second_fails)
    with pytest.raises(SolverError, match=r"grown to 0.95 .* to 0.9516 failed after 4 cuts") as err:
        don(problem, [limb], start=0.925, steps=3, on_step=lambda step: states.append(model.w.x.array.copy()))
    assert err.value.reason == "DIVERGED_MAX_IT"
    assert np.array_equal(model.w.x.array, states[0])
