"""Options and state of the model and of the explicit integrator's layers:

* ShellModel(internal_force=...): the hand-written kernel, FFCx with the reference at the quadrature points and FFCx
  on the P2 fields give the same internal force (1e-11 relative in the max-norm: round-off, as in
  tests/test_shell_reference.py); another value is refused naming the parameter;
* CentralDifference.set_time_step: M + dt/2 C of the new step, the hooks that keep quantities of the step told
  (TimeStepListener: the seams' masses), the critical step still checked; a `contact` hook without forces/correct
  is refused (ExplicitHook);
* state() / restore() of the grips (their anchors) and the belts (nothing), as a checkpoint uses them.

Serial:  python -m pytest -q tests/test_model_options.py
"""
from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.contact.handles import Belt, EdgeGrip
from fabricfem.contact.seams import SeamSpec, SeamTies
from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.materials import Fabric, KawabataBending
from fabricfem.meshes import plate, tube
from fabricfem.meshes.pattern import Panel, Pattern, Stitch
from fabricfem.meshes.pattern_mesh import mesh_pattern
from fabricfem.shell import INTERNAL_FORCES, ShellModel

COMM = MPI.COMM_WORLD
ROUND_OFF = 1e-11
FABRIC = Fabric(E1=5e6, E2=2e6, nu12=0.3, G12=3e5, thickness=5e-4, density=400.0,
                bending_law=KawabataBending((2e-5, 1e-6, 3e-8)))
SQUARE = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]])


def deformed_state(model: ShellModel) -> PETSc.Vec:
    """Displacements ~1e-4 m and rotations ~0.05 rad, smooth functions of the dof coordinates."""
    x = model.create_vector()
    values, n_owned = x.getArray(), x.getLocalSize()
    k = np.random.default_rng(1).normal(size=(3, 3)) * 20.0
    for field, amplitude in ((0, 1e-4), (1, 0.05)):
        space, dofs = model.W.sub(field).collapse()
        coords = space.tabulate_dof_coordinates()
        bs = len(dofs) // len(coords)
        dofs = np.asarray(dofs).reshape(-1, bs)
        owned = dofs[:, 0] < n_owned
        values[dofs[owned].ravel()] = (amplitude * np.sin(coords @ k)[:, :bs])[owned].ravel()
    x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    return x


def internal_force(model: ShellModel) -> PETSc.Vec:
    """R_int at `deformed_state` [N, N m]."""
    model.compile()
    b = model.create_vector()
    model.internal_force(deformed_state(model), b)
    return b


def relative_difference(b: PETSc.Vec, reference: PETSc.Vec) -> float:
    diff = b.copy()
    diff.axpy(-1.0, reference)
    return diff.norm(PETSc.NormType.NORM_INFINITY) / reference.norm(PETSc.NormType.NORM_INFINITY)


def test_the_internal_force_choices_agree():
    """A curved Q2 tube with a Kawabata bending law and a symmetry plane (its penalty is part of the force): the three
    implementations of INTERNAL_FORCES against "ffcx" (the energy on the P2 fields, differentiated by UFL)."""
    forces = {}
    for choice in INTERNAL_FORCES:
        model = ShellModel(tube(0.1, 0.03, 8, 3, comm=COMM, order=2), FABRIC, internal_force=choice)
        model.symmetry("end0", (1.0, 0.0, 0.0), penalty=1.0)
        assert model.hand_kernel is (choice == "kernel")
        assert model.reference_at_quadrature is (choice != "ffcx")
        forces[choice] = internal_force(model)
    for choice in ("kernel", "ffcx-quadrature"):
        assert relative_difference(forces[choice], forces["ffcx"]) < ROUND_OFF, choice


def test_a_built_model_changes_its_internal_force():
    """use_internal_force on a model whose force is already compiled: the next evaluation is by the new choice, the
    same force to round-off; the membrane model has the FFCx force only."""
    model = ShellModel(plate(0.1, 0.05, 4, 2, cell="quadrilateral", comm=COMM), FABRIC)
    kernel = internal_force(model)
    assert model.internal_force_forms.prepacked and model.quadrature_reference is not None
    model.use_internal_force("ffcx")
    assert relative_difference(internal_force(model), kernel) < ROUND_OFF
    assert not model.internal_force_forms.prepacked and model.quadrature_reference is None
    membrane = ShellModel(plate(0.1, 0.05, 4, 2, cell="quadrilateral", comm=COMM), FABRIC, model="membrane")
    assert not membrane.hand_kernel and not membrane.reference_at_quadrature


def test_an_unknown_internal_force_is_refused():
    fmesh = plate(0.1, 0.05, 2, 1, cell="quadrilateral", comm=COMM)
    with pytest.raises(ValueError, match="internal_force"):
        ShellModel(fmesh, FABRIC, internal_force="hand")
    model = ShellModel(fmesh, FABRIC)
    with pytest.raises(ValueError, match="internal_force"):
        model.use_internal_force("FFCx")


class Silent:
    """An explicit hook that does nothing."""

    def forces(self, integrator, t: float, rhs) -> None:
        """No force."""

    def correct(self, integrator, t: float) -> None:
        """No correction."""


class Recorder(Silent):
    """An explicit hook that records the steps it is told."""

    def __init__(self):
        self.told: list[float] = []

    def on_time_step(self, dt: float) -> None:
        self.told.append(dt)


def test_set_time_step_rebuilds_the_diagonal_and_tells_the_hooks():
    """M + dt/2 C (mass damping a = 50 / s) of the new step, to round-off; a TimeStepListener hook is told, a plain
    ExplicitHook is not asked; a step above the critical one is refused naming dt; a hook without forces/correct
    is refused naming contact."""
    model = ShellModel(plate(0.1, 0.05, 4, 2, cell="quadrilateral", comm=COMM), FABRIC).clamp("left")
    listener = Recorder()
    integrator = CentralDifference(model, 1e-6, rayleigh=(50.0, 0.0), contact=[listener, Silent()])
    integrator.denominator                     # built for dt = 1e-6 s
    dt = 0.5 * integrator.dt_crit
    integrator.set_time_step(dt)
    assert integrator.dt == dt and listener.told == [dt]
    expected = integrator.ops.mass_diag.copy()
    expected.axpy(0.5 * dt, integrator.ops.damping_diag)
    expected.getArray()[integrator.bc_rows] = 1.0
    assert relative_difference(integrator.denominator, expected) < 1e-15
    with pytest.raises(ValueError, match="dt"):
        integrator.set_time_step(2.0 * integrator.dt_crit)
    integrator.destroy()
    with pytest.raises(TypeError, match="contact"):
        CentralDifference(model, dt, contact=[object()])


def _seamed_squares():
    """Two 0.1 m squares, one stitch between them (0.15 m apart), on this rank; (model, SeamSpecs, FabricMesh)."""
    pattern = Pattern({"l": Panel("l", SQUARE), "r": Panel("r", SQUARE, translation=(0.15, 0.0, 0.0))},
                      [Stitch(("l", 1), ("r", 3))])
    garment = mesh_pattern(pattern, 0.05, comm=MPI.COMM_SELF)
    seams = [SeamSpec(s.name, s.points_a, s.panel_tag_a, s.points_b, s.panel_tag_b, float(np.mean(s.lengths)))
             for s in garment.stitches]
    return ShellModel(garment.fabric, FABRIC), seams, garment


def test_seams_take_the_masses_of_the_new_step():
    """After set_time_step the seams' forces are those of seams built for the new step (their masses M + dt/2 C
    retaken); seams that are not a hook of the integrator keep the former step's masses (0.25 % apart here)."""
    model, seams, _ = _seamed_squares()
    ties, untold = SeamTies(model, seams, sewing_time=0.05), SeamTies(model, seams, sewing_time=0.05)
    integrator = CentralDifference(model, 1e-4, rayleigh=(50.0, 0.0), contact=[ties], force=True)

    def seam_force(hook) -> np.ndarray:
        integrator.a.set(0.0)
        hook.correct(integrator, 0.0)
        return hook.force.copy()

    seam_force(ties), seam_force(untold)           # masses of dt = 1e-4 s
    integrator.set_time_step(2e-4)
    fresh = seam_force(SeamTies(model, seams, sewing_time=0.05))
    np.testing.assert_allclose(seam_force(ties), fresh, rtol=1e-14)
    assert np.max(np.abs(seam_force(untold) - fresh)) > 1e-3 * np.max(np.abs(fresh))
    integrator.destroy()


def test_grips_and_belts_keep_their_state():
    """A grip's state is its anchors (None before its pull): a grip restored from it pulls as the saved one; a belt
    keeps nothing."""
    square = mesh_pattern(Pattern({"p": Panel("p", SQUARE)}, []), 0.05, comm=MPI.COMM_SELF)
    model = ShellModel(square.fabric, FABRIC)
    edge = [("p.2", square.panel_tags["p"], square.edge_points("p", 2))]
    integrator = CentralDifference(model, 1e-4, force=True)
    grips = [EdgeGrip(model, edge, [[0, 0, 0], [0, 0, 0.05]], 0.0, 0.05) for _ in range(2)]
    assert grips[0].state() == {"anchor": None}
    grips[0].correct(integrator, 0.0)                # the pull starts: the anchors are taken
    grips[1].restore(grips[0].state())
    integrator.d.getArray()[:] = 1e-3                # somewhere else: a fresh grip would anchor there
    forces = []
    for grip in grips:
        integrator.a.set(0.0)
        grip.correct(integrator, 0.01)
        forces.append(grip.force)
    np.testing.assert_array_equal(forces[0], forces[1])
    assert np.any(forces[0] != 0.0)
    belt = Belt(model, edge, tension=1.0, start=0.0, ramp=0.0)
    assert belt.state() == {}
    belt.restore(belt.state())
    integrator.destroy()
