"""The system contract (fabricfem.solvers.system): CompositeSystem = model + ResidualTerms, the backward-Euler
inertia term (fabricfem.dynamics.backward_euler) and the order of the after-step hooks."""
import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact.problem import ContactProblem
from fabricfem.dynamics.backward_euler import BackwardEulerInertia
from fabricfem.dynamics.mass import lumped_mass
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.system import CompositeSystem, NonlinearSystem, ResidualTerm, owned_dirichlet_rows


def _model() -> ShellModel:
    model = ShellModel(plate(1.0, 1.0, 2, 2, cell="quadrilateral", comm=MPI.COMM_SELF),
                       Fabric.isotropic(1e6, 0.3, 1e-3, density=500.0))
    model.constrain("left", u=(0.0, 0.0, 0.0), theta=(0.0, 0.0))
    model.add_body_force((0.0, 0.0, -1.0))
    model.compile()
    model.set_load_factor(1.0)
    return model


def _random_state(model: ShellModel, scale: float = 1e-3) -> PETSc.Vec:
    x = model.create_vector()
    x.getArray()[:] = scale * np.random.default_rng(0).standard_normal(x.getLocalSize())
    x.getArray()[owned_dirichlet_rows(model)] = 0.0
    return x


class _Spring:
    """A trivial ResidualTerm: r = k (x - x0) on every row, tangent k I (records its calls)."""

    def __init__(self, k: float, log: list, name: str = "spring"):
        self.k, self.log, self.name = k, log, name

    def add_residual(self, x, b):
        b.axpy(self.k, x)

    def add_jacobian(self, x, A):
        diag = x.duplicate()
        diag.set(self.k)
        A.setDiagonal(diag, addv=PETSc.InsertMode.ADD_VALUES)
        A.assemble()
        diag.destroy()

    def commit(self):
        self.log.append(self.name)


def test_composite_residual_and_jacobian_are_model_plus_term():
    model = _model()
    system = CompositeSystem(model, [_Spring(7.0, [])])
    assert isinstance(model, NonlinearSystem) and isinstance(system, NonlinearSystem)
    assert system.w is model.w and system.F_ref is model.F_ref and system.bcs is model.bcs
    x = _random_state(model)
    b_model, b_system = model.create_vector(), system.create_vector()
    model.residual(x, b_model)
    system.residual(x, b_system)
    b_model.axpy(7.0, x)
    assert np.array_equal(b_system.getArray(), b_model.getArray())
    A_model, A_system = model.create_matrix(), system.create_matrix()
    model.jacobian(x, A_model)
    system.jacobian(x, A_system)
    A_model.shift(7.0)
    A_system.axpy(-1.0, A_model)
    assert A_system.norm() == 0.0


def test_after_converged_step_runs_the_model_hook_then_the_terms_in_order(monkeypatch):
    model = _model()
    log = []
    monkeypatch.setattr(model, "after_converged_step", lambda: log.append("model"))
    system = CompositeSystem(model, [_Spring(1.0, log, "first"), _Spring(1.0, log, "second")])
    system.after_converged_step()
    assert log == ["model", "first", "second"]


def test_a_term_must_have_the_term_interface():
    with pytest.raises(TypeError, match="terms"):
        CompositeSystem(_model(), [object()])


def test_backward_euler_inertia_jacobian_matches_central_differences():
    """The term is affine in x: central differences of its residual reproduce the tangent (1/dt^2 + c/dt) M to
    round-off (relative 1e-7 at h = 1e-6 of the state scale), off the Dirichlet rows, and zero on them."""
    model = _model()
    mass = lumped_mass(model)
    inertia = BackwardEulerInertia(model, mass, 3.0, 0.01)
    inertia.v.getArray()[:] = np.random.default_rng(1).standard_normal(inertia.v.getLocalSize())
    x = _random_state(model)
    A = model.create_matrix()
    model.jacobian(x, A)     # the sparsity with its diagonal allocated
    A.zeroEntries()
    inertia.add_jacobian(x, A)
    diag = A.getDiagonal().getArray()
    n, h = x.getLocalSize(), 1e-6
    rng = np.random.default_rng(2)
    for i in rng.choice(n, 8, replace=False):
        plus, minus = x.copy(), x.copy()
        plus.getArray()[i] += h
        minus.getArray()[i] -= h
        rp, rm = model.create_vector(), model.create_vector()
        rp.set(0.0)
        rm.set(0.0)
        inertia.add_residual(plus, rp)
        inertia.add_residual(minus, rm)
        column = (rp.getArray() - rm.getArray()) / (2 * h)
        expected = np.zeros(n)
        expected[i] = diag[i]
        assert np.allclose(column, expected, rtol=1e-7, atol=1e-7 * np.abs(diag).max())
    bc = owned_dirichlet_rows(model)
    assert np.all(diag[bc] == 0.0) and np.all(diag[np.setdiff1d(np.arange(n), bc)] > 0.0)
    inertia.destroy()
    mass.destroy()


def test_backward_euler_commit_and_predict():
    """commit: v^{n+1} = (x - x^n) / dt and x^n <- x; predict: x = x^n + dt v^n off the Dirichlet rows."""
    model = _model()
    mass = lumped_mass(model)
    inertia = BackwardEulerInertia(model, mass, 0.0, 0.5)
    x = _random_state(model)
    x.copy(model.w.vector)
    inertia.commit()
    assert np.allclose(inertia.v.getArray(), 2.0 * x.getArray(), rtol=1e-15)
    assert np.array_equal(inertia.d.getArray(), x.getArray())
    inertia.predict()
    assert np.allclose(model.w.vector.getArray(), 2.0 * x.getArray(), rtol=1e-15)
    inertia.destroy()
    mass.destroy()


def test_contact_problem_is_a_term_and_not_a_system():
    model = _model()
    far = Ellipsoid(center=np.array([0.5, 0.5, -10.0]), rotation=np.eye(3), radii=np.array([0.1, 0.1, 0.1]))
    problem = ContactProblem(model, [far])
    assert isinstance(problem, ResidualTerm)
    assert problem.system.terms == [problem] and problem.system.model is model
    assert problem.w is model.w                       # the model's data read through the problem
    with pytest.raises(AttributeError, match="ContactProblem.system.residual"):
        problem.residual                              # noqa: B018 (not silently the shell's residual)
