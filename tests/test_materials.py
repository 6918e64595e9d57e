"""Bad input gives a ValueError naming the parameter; material matrices match their closed forms."""
import numpy as np
import pytest

from fabricfem.materials import Fabric, KawabataBending, SquareRootBending
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel


@pytest.mark.parametrize("kwargs, name", [
    (dict(E1=-1.0), "E1"), (dict(E2=0.0), "E2"), (dict(G12=-5.0), "G12"), (dict(thickness=0.0), "thickness"),
    (dict(thickness=float("nan")), "thickness"), (dict(nu12=0.9, E1=1.0, E2=2.0), "nu12"),
    (dict(nu12=-1.5), "nu12"), (dict(density=-1.0), "density"), (dict(bending_rigidity=(1.0, -1.0)),
                                                                   "bending_rigidity")])
def test_bad_fabric_parameters(kwargs, name):
    base = dict(E1=1e6, E2=1e6, G12=1e5, nu12=0.3, thickness=1e-3)
    base.update(kwargs)
    with pytest.raises(ValueError, match=name):
        Fabric(**base)


@pytest.mark.parametrize("nu", [0.5001, -1.0, 0.7])
def test_bad_isotropic_poisson_ratio(nu):
    with pytest.raises(ValueError, match="Poisson"):
        Fabric.isotropic(1e6, nu, 1e-3)


def test_bad_bending_laws():
    with pytest.raises(ValueError, match="alpha_1"):
        KawabataBending((-1.0, 2.0))
    with pytest.raises(ValueError, match="kappa0"):
        SquareRootBending(B0=1e-3, kappa0=0.0)


def test_plane_stress_matrix_isotropic():
    """Isotropic limit: Q = E/(1-nu^2) [[1, nu, 0], [nu, 1, 0], [0, 0, (1-nu)/2]]."""
    E, nu = 2.0e6, 0.3
    Q = Fabric.isotropic(E, nu, 1e-3).plane_stress_matrix
    expected = E / (1 - nu ** 2) * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])
    assert np.allclose(Q, expected, rtol=1e-14)


def test_orthotropic_compliance_is_inverse():
    """Q^-1 is the orthotropic compliance [[1/E1, -nu21/E2, 0], [-nu12/E1, 1/E2, 0], [0, 0, 1/G12]]."""
    f = Fabric(E1=3e6, E2=1e6, G12=2e5, nu12=0.4, thickness=1e-3)
    S = np.array([[1 / f.E1, -f.nu21 / f.E2, 0], [-f.nu12 / f.E1, 1 / f.E2, 0], [0, 0, 1 / f.G12]])
    assert np.allclose(np.linalg.inv(f.plane_stress_matrix), S, rtol=1e-12)


def test_bending_rigidity_override():
    f = Fabric(E1=3e6, E2=1e6, G12=2e5, nu12=0.4, thickness=1e-3, bending_rigidity=(2e-5, 1e-5))
    D = f.bending_matrix
    assert D[0, 0] == pytest.approx(2e-5) and D[1, 1] == pytest.approx(1e-5)
    assert np.all(np.linalg.eigvalsh(D) > 0)


def test_square_root_law_is_continuous():
    law = SquareRootBending(B0=3.3e-3, kappa0=30.0)
    k = np.array([30.0 - 1e-9, 30.0 + 1e-9])
    m = law.moment(k)
    assert m[0] == pytest.approx(m[1], rel=1e-6) and m[0] == pytest.approx(2 * 3.3e-3 * 30.0, rel=1e-6)


@pytest.fixture(scope="module")
def small_model():
    return ShellModel(plate(1.0, 0.1, 4, 1, cell="quadrilateral"), Fabric.isotropic(1e6, 0.0, 1e-3))


def test_unknown_boundary_tag(small_model):
    with pytest.raises(ValueError, match="unknown facet tag 'shoulder'"):
        small_model.clamp("shoulder")
    with pytest.raises(ValueError, match="tag"):
        small_model.add_edge_traction("nope", (1.0, 0.0, 0.0))


def test_unknown_model_and_point(small_model):
    with pytest.raises(ValueError, match="model"):
        ShellModel(small_model.fmesh, small_model.fabric, model="plate")
    with pytest.raises(ValueError, match="not a mesh node"):
        small_model.node_value((0.123, 0.05, 0.0))
    with pytest.raises(ValueError, match="gravity needs a positive fabric density"):
        small_model.add_gravity()
