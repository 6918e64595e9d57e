"""Bonet-Burton yarn law [Man2006, sec. 4.3.4]: verify cases, thesis parameter sets, conversion, bad input."""
import numpy as np
import pytest

from fabricfem.materials.yarn import THESIS_ISOTROPIC, THESIS_TRANSVERSELY_ISOTROPIC, EngineeringConstants, YarnMaterial
from fabricfem.verify.yarn import PointwiseYarnLaw, YarnBlock, bonet_burton_constants, bonet_burton_stress

GPA = 1e9


def _assert_passed(results):
    failed = [r for r in results if not r.passed]
    assert results and not failed, "\n".join(f"{r.quantity}: {r.value} vs {r.reference} (rel {r.rel_error:.2e})"
                                            for r in failed)


def test_stress_case():
    _assert_passed(bonet_burton_stress())


@pytest.mark.mpi
def test_constants_case():
    _assert_passed(bonet_burton_constants())


def _rounding_bound(quantity, material: YarnMaterial, half_units: dict) -> float:
    """Linear bound on |quantity change| when each parameter moves by half a unit of its last printed digit."""
    base = quantity(material)
    bound = 0.0
    for name, half in half_units.items():
        params = {k: getattr(material, k) for k in ("lmbda", "mu", "alpha", "beta", "gamma")}
        params[name] += half
        bound += abs(quantity(YarnMaterial(**params)) - base)
    return bound


def test_thesis_transversely_isotropic_parameters_give_kevlar_axial_modulus():
    """Sec. 4.3.5.2: the parameters are deduced from a KM2 fiber, whose E = 84.62 GPa (sec. 4.3.5.1).
    Tolerance: the effect of rounding the printed parameters (4 significant digits) on E_L."""
    m = THESIS_TRANSVERSELY_ISOTROPIC
    half_units = {"lmbda": 5e-5 * GPA, "mu": 5e-5 * GPA, "alpha": 5e-5 * GPA, "beta": 5e-6 * GPA, "gamma": 5e-3 * GPA}
    E_L = lambda mat: mat.engineering_constants().E_L  # noqa: E731
    assert abs(E_L(m) - 84.62 * GPA) <= _rounding_bound(E_L, m, half_units) + 0.005 * GPA  # + rounding of 84.62
    # and the reduced axial shear modulus the thesis describes: G_LT = mu - alpha (exact arithmetic on the inputs)
    assert m.engineering_constants().G_LT == pytest.approx(0.244 * GPA, rel=1e-12)


def test_isotropic_limit_matches_thesis():
    """Sec. 4.3.5.1: E = 84.62 GPa, nu = 0.3 <-> lambda = 48.82, mu = 32.55 GPa (printed to 4 digits:
    tolerance half a unit of the last digit, 0.005 GPa), and alpha = beta = gamma = 0."""
    iso = YarnMaterial.isotropic(84.62 * GPA, 0.3)
    assert abs(iso.lmbda - 48.82 * GPA) <= 0.005 * GPA
    assert abs(iso.mu - 32.55 * GPA) <= 0.005 * GPA
    conv = YarnMaterial.from_engineering_constants(84.62 * GPA, 84.62 * GPA, 84.62 * GPA / 2.6, 0.3, 0.3)
    # round-off only: a few operations on O(E) numbers
    for name in ("alpha", "beta", "gamma"):
        assert abs(getattr(conv, name)) <= 1e-12 * 84.62 * GPA, name
    assert conv.lmbda == pytest.approx(iso.lmbda, rel=1e-12) and conv.mu == pytest.approx(iso.mu, rel=1e-12)
    ec = THESIS_ISOTROPIC.engineering_constants()
    # inverse direction: the printed lambda, mu carry +-0.005 GPa, i.e. ~1e-4 relative on E and nu
    assert ec.E_L == pytest.approx(84.62 * GPA, rel=2e-4) and ec.E_T == pytest.approx(84.62 * GPA, rel=2e-4)
    assert ec.nu_LT == pytest.approx(0.3, rel=2e-4) and ec.nu_TT == pytest.approx(0.3, rel=2e-4)


def test_conversion_round_trip():
    """Closed-form conversion against numerical inversion of the 6x6 stiffness (round-off: 1e-12)."""
    target = dict(E_L=100 * GPA, E_T=10 * GPA, G_LT=5 * GPA, nu_LT=0.3, nu_TT=0.3)
    back = YarnMaterial.from_engineering_constants(**target).engineering_constants()
    for name, value in target.items():
        assert getattr(back, name) == pytest.approx(value, rel=1e-12), name


def test_small_strain_stiffness_is_the_linearised_eq_4_69():
    """6x6 stiffness (hand derivation) against central differences of the numpy eq. 4.69 at C = I.
    Step 1e-6: truncation O(h^2) = 1e-12, round-off eps / h ~ 1e-10 of the stiffness, tolerance 1e-8."""
    m = YarnMaterial.from_engineering_constants(100 * GPA, 10 * GPA, 5 * GPA, 0.3, 0.3)
    voigt = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    h = 1e-6
    D = np.zeros((6, 6))
    for col, (i, j) in enumerate(voigt):
        E = np.zeros((3, 3))
        E[i, j] = E[j, i] = 1.0 if i == j else 0.5  # engineering shear strain = 1
        # F = sqrt(I + 2 h E) (symmetric) so that the Green strain is exactly h E
        w, Q = np.linalg.eigh(np.eye(3) + 2 * h * E)
        Fp = Q @ np.diag(np.sqrt(w)) @ Q.T
        w, Q = np.linalg.eigh(np.eye(3) - 2 * h * E)
        Fm = Q @ np.diag(np.sqrt(w)) @ Q.T
        dS = (m.stress(Fp, [1.0, 0.0, 0.0]) - m.stress(Fm, [1.0, 0.0, 0.0])) / (2 * h)
        D[:, col] = [dS[a, b] for a, b in voigt]
    assert np.abs(D - m.small_strain_stiffness).max() <= 1e-8 * np.abs(D).max()


def test_ufl_law_is_objective_and_follows_the_axis():
    """S(Q F, A) = S(F, A) (frame indifference) and S(F R^T, R A) = R S(F, A) R^T (the axis is material),
    for the UFL law; round-off tolerance 1e-12 of |S|."""
    law = PointwiseYarnLaw(THESIS_TRANSVERSELY_ISOTROPIC)
    rng = np.random.default_rng(7)
    F = np.eye(3) + 0.2 * rng.standard_normal((3, 3))
    A = np.array([0.6, 0.0, 0.8])
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    S = law.stress(F, A)
    assert np.abs(law.stress(Q @ F, A) - S).max() <= 1e-12 * np.abs(S).max()
    assert np.abs(law.stress(F @ Q.T, Q @ A) - Q @ S @ Q.T).max() <= 1e-12 * np.abs(S).max()


@pytest.mark.parametrize("kwargs, name", [
    (dict(lmbda=1e9, mu=-1e9), "mu"),
    (dict(lmbda=1e9, mu=0.0), "mu"),
    (dict(lmbda=1e9, mu=1e9, alpha=1e9), "alpha"),
    (dict(lmbda=-1.5e9, mu=1e9), "lmbda"),
    (dict(lmbda=1e9, mu=1e9, beta=1e9, gamma=-1e9), "gamma"),
    (dict(lmbda=float("nan"), mu=1e9), "lmbda"),
    (dict(lmbda=1e9, mu=1e9, beta=float("inf")), "beta"),
])
def test_bad_parameters(kwargs, name):
    with pytest.raises(ValueError, match=name):
        YarnMaterial(**kwargs)


@pytest.mark.parametrize("kwargs, name", [
    (dict(E_L=-1.0, E_T=1.0, G_LT=1.0, nu_LT=0.3, nu_TT=0.3), "E_L"),
    (dict(E_L=1.0, E_T=0.0, G_LT=1.0, nu_LT=0.3, nu_TT=0.3), "E_T"),
    (dict(E_L=1.0, E_T=1.0, G_LT=-1.0, nu_LT=0.3, nu_TT=0.3), "G_LT"),
    (dict(E_L=1.0, E_T=1.0, G_LT=1.0, nu_LT=0.3, nu_TT=1.0), "nu_TT"),
    (dict(E_L=1.0, E_T=1.0, G_LT=1.0, nu_LT=0.6, nu_TT=0.3), "nu_LT"),  # 2 nu_LT^2 = 0.72 > 1 - nu_TT
    (dict(E_L=1.0, E_T=10.0, G_LT=1.0, nu_LT=0.2, nu_TT=0.3), "nu_LT"),  # 2 nu_LT^2 E_T/E_L = 0.8 > 0.7
])
def test_bad_engineering_constants(kwargs, name):
    with pytest.raises(ValueError, match=name):
        YarnMaterial.from_engineering_constants(**kwargs)
    with pytest.raises(ValueError, match=name):
        EngineeringConstants(**kwargs)


def test_bad_axis_and_deformation():
    m = THESIS_TRANSVERSELY_ISOTROPIC
    with pytest.raises(ValueError, match=r"A \(yarn axis\)"):
        m.stress(np.eye(3), [1.0, 1.0, 0.0])
    with pytest.raises(ValueError, match="det F"):
        m.stress(np.diag([1.0, 1.0, -1.0]), [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"A \(yarn axis\)"):
        PointwiseYarnLaw(m).stress(np.eye(3), [0.0, 0.0, 2.0])
    with pytest.raises(ValueError, match=r"A \(yarn axis\)"):
        YarnBlock(m, axis=(0.0, 0.5, 0.0))
