"""The PSRI weight follows the actual bending and membrane stiffnesses (fabricfem.forms.shell.equivalent_thickness,
psri_weight; docs/shell.md, "Locking"), a scene chooses the quadrature ([model] quadrature), and the explicit step's
estimates use a bending rigidity given apart from the thickness (fabricfem.dynamics.stability)."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from dolfinx import fem
from mpi4py import MPI
from test_shell_reference import perturbed_state

from fabricfem.dynamics import critical_time_step, discrete_max_frequency, max_frequency_estimate
from fabricfem.forms.shell import equivalent_thickness
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.scenes.build import critical_time_step_estimate, validate
from fabricfem.scenes.dynamic import run_dynamic_scene
from fabricfem.scenes.schema import SceneError
from fabricfem.scenes.static import build_model
from fabricfem.shell import ShellModel
from fabricfem.verify.accuracy import CORNER_BENDING, CORNER_BENDING_UZ_REFERENCE

COMM = MPI.COMM_WORLD


def cloth(bending_rigidity=(0.02, 0.02)) -> Fabric:
    """The corner-pinned cloth (scenes/corner_pinned.toml) with a bending rigidity [N m] apart from E t^3 / 12."""
    return Fabric(E1=9940.52676295667, E2=9940.52676295667, G12=3976.210705182668, nu12=0.0, thickness=0.001177,
                  density=99.4052676295667, bending_rigidity=bending_rigidity)


def test_equivalent_thickness():
    """t_eq^2 = 12 max(D11 / A11, D22 / A22): the thickness itself when D = t^3 / 12 Q (ShellModel takes t exactly),
    12 B1 (1 - nu12 nu21) / (E1 t) for a given warp rigidity, the stiffer direction setting it."""
    sheet = Fabric(E1=5e6, E2=2e6, nu12=0.3, G12=3e5, thickness=5e-4, density=400.0)
    A, D = sheet.thickness * sheet.plane_stress_matrix, sheet.bending_matrix
    assert equivalent_thickness(A, D) == pytest.approx(5e-4, rel=1e-14)
    fabric = Fabric(E1=5e6, E2=2e6, nu12=0.3, G12=3e5, thickness=5e-4, density=400.0, bending_rigidity=(2e-5, 1e-4))
    A, D = fabric.thickness * fabric.plane_stress_matrix, fabric.bending_matrix
    weft = math.sqrt(12 * 1e-4 * (1 - 0.3 * 0.3 * 2e6 / 5e6) / (2e6 * 5e-4))
    assert equivalent_thickness(A, D) == pytest.approx(weft, rel=1e-12)
    assert float(ShellModel(plate(1.0, 1.0, 1, 1), cloth()).psri_thickness.value) == pytest.approx(
        math.sqrt(12 * 0.02 / (9940.52676295667 * 0.001177)), rel=1e-12)
    assert float(ShellModel(plate(1.0, 1.0, 1, 1), sheet).psri_thickness.value) == 5e-4


def _energy(model: ShellModel, state) -> float:
    model.set_state(state)
    return COMM.allreduce(fem.assemble_scalar(fem.form(model.energy)), op=MPI.SUM)


@pytest.mark.parametrize("internal_force", ["kernel", "ffcx"])
def test_weight_is_capped_at_one(internal_force):
    """Cells smaller than t_eq (0.143 m here; 8x8 cells of 0.177 m diameter are not, 16x16 of 0.088 m are) are
    integrated fully: with PSRI (4, 2) the energy and the internal force (hand-written kernel or FFCx) equal those of
    full quadrature (4, 4) to round-off. Before the cap, alpha = t_eq^2 / h^2 = 2.6 gave the reduced rule the weight
    -1.6."""
    values = {}
    for degrees in ((4, 2), (4, 4)):
        model = ShellModel(plate(1.0, 1.0, 16, 16), cloth(), psri_degrees=degrees, internal_force=internal_force)
        model.compile()
        state = perturbed_state(model)
        b = model.create_vector()
        model.internal_force(state, b)
        values[degrees] = (_energy(model, state), b.array.copy())
    (e_psri, f_psri), (e_full, f_full) = values[(4, 2)], values[(4, 4)]
    assert e_psri == pytest.approx(e_full, rel=1e-12)
    assert np.abs(f_psri - f_full).max() <= 1e-11 * np.abs(f_full).max()


def test_kernel_reads_the_weight_of_the_bending_rigidity():
    """The hand-written kernel packs alpha = min(1, t_eq^2 / h^2) per cell: its internal force equals FFCx's
    derivative of the energy on the P2 fields for the cloth with B = 0.02 N m on 4x4 cells (alpha = 0.16)."""
    forces = []
    for internal_force in ("kernel", "ffcx"):
        model = ShellModel(plate(1.0, 1.0, 4, 4), cloth(), internal_force=internal_force)
        model.compile()
        b = model.create_vector()
        model.internal_force(perturbed_state(model), b)
        forces.append(b.array.copy())
    assert np.abs(forces[0] - forces[1]).max() <= 1e-11 * np.abs(forces[1]).max()


def _corner_scene(n: int, **model) -> dict:
    """The verify case's bending cloth (fabricfem.verify.accuracy.CORNER_BENDING) on n x n cells, dt = 0.08 / n s."""
    data = copy.deepcopy(CORNER_BENDING)
    data.pop("accuracy")
    data["mesh"].update(nx=n, ny=n)
    data["dynamics"]["dt"] = 0.08 / n
    data["model"].update(model)
    return data


def test_coarse_shell_is_not_too_stiff(tmp_path):
    """The cloth with B = 0.02 N m swinging from two corners (Newmark, to 0.3 s) on 5x5 cells: the corner drop is
    within 0.5 % of the converged reference -0.33366 m (measured 0.18 %); with the weight t^2 / h^2 of the
    thickness it was -0.1317 m, 61 % short."""
    data = _corner_scene(5)
    data["output"] = {"dir": str(tmp_path / "cloth"), "render": False}
    uz = run_dynamic_scene(validate(data), COMM).summary["final_corner_uz"]
    assert uz == pytest.approx(CORNER_BENDING_UZ_REFERENCE, rel=5e-3)


def test_scene_chooses_the_quadrature():
    """[model] quadrature: [full, reduced] degrees (default [4, 2]) or "full" ([4, 4]); anything else is refused in
    one line naming the key."""
    assert build_model(validate(_corner_scene(2)), COMM).energy_options["degrees"] == (4, 2)
    assert build_model(validate(_corner_scene(2, quadrature="full")), COMM).energy_options["degrees"] == (4, 4)
    assert build_model(validate(_corner_scene(2, quadrature=[6, 3])), COMM).energy_options["degrees"] == (6, 3)
    for bad in ([2, 4], [4], "reduced", [4.0, 2], [0, 0]):
        with pytest.raises(SceneError, match=r"^model: quadrature: .*got") as info:
            validate(_corner_scene(2, quadrature=bad))
        assert "\n" not in str(info.value)


def test_explicit_step_estimates_use_the_bending_rigidity():
    """Explicit steps with B = 0.02 N m (1.5e4 x E t^3 / 12): the estimate before meshing (scene validation and the
    accuracy plan's levels) equals the model's, which counts B (it left bending out: 2.8x too long on 8x8 cells),
    and the model's estimate is above the discrete omega_max at rest (SLEPc) by at most 12 % on 4x4 and 8x8
    cells (measured 10.6 % / 1.6 %)."""
    for n in (4, 8):
        data = _corner_scene(n)
        data["dynamics"].update(integrator="explicit", dt="auto")
        model = build_model(validate(data), COMM)
        model.compile()
        assert critical_time_step_estimate(data) == pytest.approx(critical_time_step(model), rel=1e-12)
        estimate, discrete = max_frequency_estimate(model), discrete_max_frequency(model)
        assert discrete <= estimate <= 1.12 * discrete, (n, estimate, discrete)
