"""The arm of the sleeve study as a SleeveConfig field (fabricfem.wear.sleeve) and the fit-sensitivity study
(fabricfem.studies.sleeve_fit): the arm reaches the ellipsoids and the fit check, scene girths reach the config,
the summary-table arithmetic on synthetic curves, and the membrane / bending split of the strain energy
against closed forms for an inflated tube."""
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem import scenes as scene_module
from fabricfem.body.arm import DEFAULT_ARM, ArmDimensions
from fabricfem.scenes.build import sleeve_config
from fabricfem.scenes.schema import SceneError
from fabricfem.studies.sleeve_fit import (
    FIT_CASES,
    energy_split,
    energy_split_forms,
    fit_configs,
    fit_ratio,
    scaled_arm,
    summary_row,
    thickness_ratio,
)
from fabricfem.wear.config import SleeveConfig, check_fit
from fabricfem.wear.quasistatic import build_sleeve

ROOT = Path(__file__).resolve().parents[1]
THICK_ARM = ArmDimensions(upper_arm_girth=0.36, forearm_girth=0.31)   # radii 0.0573 m, 0.0493 m: fits R = 0.06 m


def sleeve_data() -> dict:
    """The sleeve as a wear scene on its quasi-static route (the scene that sleeve_config reads)."""
    return tomllib.loads((ROOT / "tests" / "data" / "sleeve_quasistatic.toml").read_text())


def test_arm_field_reaches_the_ellipsoids():
    """build_sleeve poses the config's arm: semi-axes (L / 2, C / (2 pi), C / (2 pi)) of each segment."""
    cfg = SleeveConfig.of(n_around=6, n_along=4, solver="quasistatic", arm=THICK_ARM)
    body = build_sleeve(cfg, MPI.COMM_SELF).body
    for name, length, girth in (("upper_arm", 0.335, 0.36), ("forearm", 0.267, 0.31)):
        radii = body.segments[name].radii
        # exact arithmetic of the definition r = C / (2 pi): rounding only
        np.testing.assert_allclose(radii, (length / 2, girth / (2 * math.pi), girth / (2 * math.pi)), rtol=1e-14)
    assert cfg.arm is THICK_ARM and SleeveConfig().arm == DEFAULT_ARM


def test_arm_field_is_validated_and_checked_for_fit():
    with pytest.raises(ValueError, match=r"arm must be a fabricfem.body.ArmDimensions"):
        SleeveConfig.of(arm=(0.335, 0.267, 0.35, 0.30))
    # 0.40 / (2 pi) = 0.0637 m > R = 0.06 m: named parameter in the message
    with pytest.raises(ValueError, match=r"radius: .*arm.upper_arm_girth = 0.4 m"):
        SleeveConfig.of(arm=ArmDimensions(upper_arm_girth=0.40))
    with pytest.raises(ValueError, match=r"arm.forearm_girth"):
        SleeveConfig.of(radius=0.06, arm=ArmDimensions(upper_arm_girth=0.30, forearm_girth=0.39))
    # clearance = R - C / (2 pi) of the thickest segment
    assert check_fit(0.06, THICK_ARM) == pytest.approx(0.06 - 0.36 / (2 * math.pi), rel=1e-14)
    assert check_fit(0.06) == pytest.approx(0.06 - 0.35 / (2 * math.pi), rel=1e-14)


def test_scene_girths_reach_the_config():
    data = sleeve_data()
    data["body"].update(upper_arm_girth=0.36, forearm_girth=0.31, forearm_length=0.25)
    cfg = sleeve_config(scene_module.validate(data).parsed)
    assert cfg.arm == ArmDimensions(upper_arm_length=DEFAULT_ARM.upper_arm_length, forearm_length=0.25,
                                    upper_arm_girth=0.36, forearm_girth=0.31)
    assert sleeve_config(scene_module.validate(sleeve_data()).parsed).arm == DEFAULT_ARM
    data = sleeve_data()
    data["body"].update(upper_arm_girth=0.40)
    with pytest.raises(SceneError, match=r"garment.radius: .*must exceed .*arm.upper_arm_girth"):
        scene_module.validate(data)


def test_fit_study_arms():
    """The study's arms: girths times s, lengths unchanged; the snug arm leaves 1 um (0.06 - 0.35 x 1.0771 /
    (2 pi) = 9.7e-7 m) at the thickest upper-arm section."""
    configs = fit_configs(mesh="I")
    assert sorted(configs) == [1.0, 1.04, 1.0771]
    arm = configs[1.0771]["R=0.06 t=1mm"].arm
    assert arm.upper_arm_length == DEFAULT_ARM.upper_arm_length
    assert arm.upper_arm_girth == pytest.approx(0.35 * 1.0771, rel=1e-14)
    assert 0.0 < check_fit(0.06, arm) == pytest.approx(9.74e-7, rel=1e-2)
    assert check_fit(0.06, scaled_arm(1.04)) == pytest.approx(2.07e-3, rel=1e-2)
    assert {(c.tube.radius, c.material.thickness, c.contact.friction, c.route.gravity) for c in configs[1.0].values()} == {
        (0.06, 1e-3, 0.5, True), (0.07, 1e-3, 0.5, True), (0.06, 2e-3, 0.5, True)}
    with pytest.raises(ValueError, match="scale"):
        scaled_arm(-1.0)


def test_summary_arithmetic_on_synthetic_curves():
    """Closed-form curves: base 0.01 + 1e-3 a, loose = base x (1.5 - a / 100) (ratio 1.5 - a / 100, largest
    at the first angle above 20 deg, 21 deg: 1.29), thick = 2.5 x base (ratio 2.5 exactly)."""
    a = np.arange(0.0, 58.0)
    base = 0.01 + 1e-3 * a
    curves = {"R=0.06 t=1mm": (a, base), "R=0.07 t=1mm": (a, base * (1.5 - a / 100)),
              "R=0.06 t=2mm": (a, 2.5 * base)}
    assert fit_ratio(curves["R=0.06 t=1mm"], curves["R=0.07 t=1mm"]) == pytest.approx(1.29, rel=1e-12)
    assert thickness_ratio(curves["R=0.06 t=1mm"], curves["R=0.06 t=2mm"], 57.0) == pytest.approx(2.5, rel=1e-12)
    row = summary_row(1.0, DEFAULT_ARM, curves)
    assert row["angle_of_max_ratio_deg"] == 21.0
    # mean of 1.5 - a / 100 over a = 21 ... 57: 1.5 - 39 / 100
    assert row["mean_ratio_R007_R006_20_57"] == pytest.approx(1.11, rel=1e-12)
    assert row["clearance_m"] == pytest.approx(0.06 - 0.35 / (2 * math.pi), rel=1e-14)
    assert row["torque_rest_Nm[R=0.07 t=1mm]"] == pytest.approx(0.015, rel=1e-12)
    assert set(FIT_CASES) == {k[len("torque_rest_Nm["):-1] for k in row if k.startswith("torque_rest")}
    # a curve that stopped at 10 deg: no thickness ratio at 57 deg, no fit ratio above 20 deg
    short = (a[:11], base[:11])
    assert math.isnan(thickness_ratio(short, curves["R=0.06 t=2mm"], 57.0))
    assert math.isnan(fit_ratio(short, curves["R=0.07 t=1mm"]))


@pytest.mark.mpi
def test_energy_split_of_an_inflated_tube():
    """Tube of radius R inflated by u = delta n0 (theta = 0): hoop Green strain E22 = ((R + delta)^2 / R^2 - 1) / 2,
    change of curvature K22 = -delta / R^2 (d = n0, F = F0 + delta grad n0), no shear (grad n0^T n0 = 0), so

        U_membrane = 1/2 E t E22^2 2 pi R L,   U_bending = 1/2 E t^3 / 12 K22^2 2 pi R L   (nu = 0)

    Tolerance 1 %: the only error is the P2 interpolation of the circle and of n0 (20 elements around,
    node spacing pi / 20 rad: derivative error ~ (pi / 20)^2 / 12 = 2e-3, doubled in a quadratic energy)."""
    from fabricfem.wear.sleeve import sleeve_shell
    R, L, t, E, delta = 0.06, 0.5, 1e-3, 1.2e6, 2e-3
    cfg = SleeveConfig.of(n_around=20, n_along=4, solver="quasistatic", gravity=False, E=E, G=E / 200,
                       thickness=t, radius=R, length=L)
    model = sleeve_shell(cfg, MPI.COMM_WORLD)
    V = model.W.sub(0).collapse()
    u_space, u_dofs = V
    x = u_space.tabulate_dof_coordinates()
    n = np.zeros_like(x)
    n[:, 1:] = x[:, 1:] / np.linalg.norm(x[:, 1:], axis=1, keepdims=True)
    model.w.x.array[np.asarray(u_dofs)] = (delta * n).reshape(-1)
    parts = energy_split(model, energy_split_forms(model, cfg.tube.quadrature))
    area = 2 * math.pi * R * L
    E22 = ((R + delta) ** 2 / R ** 2 - 1) / 2
    assert parts["membrane"] == pytest.approx(0.5 * E * t * E22 ** 2 * area, rel=1e-2)
    assert parts["bending"] == pytest.approx(0.5 * E * t ** 3 / 12 * (delta / R ** 2) ** 2 * area, rel=1e-2)
    # the three parts are a split of the model's own energy (same PSRI weights): their sum equals it to rounding
    from dolfinx import fem
    total = model.comm.allreduce(fem.assemble_scalar(fem.form(model.energy)))
    assert parts["membrane"] + parts["bending"] + parts["shear"] == pytest.approx(total, rel=1e-12)
    # shear: zero up to the interpolation of n0 (|n0| = 1 only at the nodes): below 1e-4 of the total
    assert abs(parts["shear"]) < 1e-4 * (parts["membrane"] + parts["bending"])


# ------------------------------------------------------------------------ elbow taper (task B2): r1 = f L
def test_long_semi_axis_reaches_the_ellipsoids():
    """r1 = f L: the posed ellipsoids of the study's arm (fit_configs -> SleeveConfig.arm -> default_arm) have
    semi-axes (f L, r, r), centres at the joint midpoints [Man2006, sec. 5.1], and their far tips lie on the
    surface: f(x^c +- r1 e1) = 0 (implicit function of the ellipsoid, [Man2006, eq. 3.61]; rounding only)."""
    from fabricfem.body.arm import default_arm
    cfg = fit_configs((1.0,), mesh="I", long_axis_factor=0.7)[1.0]["R=0.06 t=1mm"]
    assert cfg.arm.long_axis_factor == 0.7 and cfg.arm.upper_arm_girth == DEFAULT_ARM.upper_arm_girth
    posed = default_arm(dimensions=cfg.arm).pose(0.0)
    for name, start, length, girth in (("upper_arm", 0.0, 0.335, 0.35), ("forearm", 0.335, 0.267, 0.30)):
        e = posed[name]
        np.testing.assert_allclose(e.radii, (0.7 * length, girth / (2 * math.pi), girth / (2 * math.pi)), rtol=1e-14)
        np.testing.assert_allclose(e.center, (start + length / 2, 0.0, 0.0), atol=1e-14)
        tips = e.center + np.outer((-1.0, 1.0), 0.7 * length * e.rotation[:, 0])
        np.testing.assert_allclose(e.implicit(tips), 0.0, atol=1e-12)
    assert cfg.arm.upper_arm_long_semi_axis == pytest.approx(0.7 * 0.335, rel=1e-15)
    assert cfg.arm.forearm_long_semi_axis == pytest.approx(0.7 * 0.267, rel=1e-15)


@pytest.mark.parametrize("factor", [0.5, 0.6, 0.7, 1.0])
def test_elbow_radius_against_the_ellipsoid_surface(factor):
    """ArmDimensions.elbow_radius = max r sqrt(1 - (L / 2 / r1)^2) against a direct evaluation: the root in y of
    the posed ellipsoids' implicit function f(x_elbow, y, 0) = 0 [Man2006, eq. 3.61], largest over the two
    segments, found by bisection (brentq, xtol 1e-13 m: the 1e-9 relative tolerance is its resolution)."""
    from scipy.optimize import brentq

    from fabricfem.body.arm import default_arm
    arm = ArmDimensions(long_axis_factor=factor)
    posed = default_arm(dimensions=arm).pose(0.0)
    elbow = arm.upper_arm_length
    radii = []
    for e in posed.values():
        f = lambda y: float(e.implicit(np.array([[elbow, y, 0.0]]))[0])  # noqa: E731
        radii.append(0.0 if f(0.0) >= 0.0 else brentq(f, 0.0, 0.1, xtol=1e-13))
    assert arm.elbow_radius == pytest.approx(max(radii), rel=1e-9, abs=1e-12)
    if factor == 0.5:                                    # the tips meet at the elbow centre: no girth there
        assert arm.elbow_radius == 0.0
    # the ANSUR arm: 30.8 mm at f = 0.6, 39.0 mm at f = 0.7 (upper arm, r = 0.35 / (2 pi)), as documented
    expected = {0.6: 0.0308, 0.7: 0.0390}
    if factor in expected:
        assert arm.elbow_radius == pytest.approx(expected[factor], abs=5e-5)


@pytest.mark.parametrize("factor", [0.49, 1.01, math.nan, -0.6, "0.6"])
def test_bad_long_axis_factor_is_refused(factor):
    with pytest.raises(ValueError, match="long_axis_factor"):
        ArmDimensions(long_axis_factor=factor)
    with pytest.raises(ValueError, match="long_axis_factor"):
        fit_configs((1.0,), mesh="I", long_axis_factor=factor)


def test_bad_long_axis_factor_on_the_command_line(capsys):
    from fabricfem.cli import main
    assert main(["study", "sleeve-fit", "--scales", "1", "--long-axis-factors", "0.6,0.4"]) == 2
    assert "long_axis_factor" in capsys.readouterr().err


@pytest.mark.parametrize("speed", ["0", "-22.5", "nan"])
def test_bad_angular_velocity_on_the_command_line(speed, capsys):
    from fabricfem.cli import main
    assert main(["study", "sleeve-fit", "--scales", "1", "--angular-velocity", speed]) == 2
    assert "angular_velocity" in capsys.readouterr().err


def test_default_factor_gives_the_old_segments_and_checkpoints():
    """f = 0.5 is the arm as it was: the segments of the former formula (0.5 L, r, r), compared exactly, and
    the study's configuration items unchanged (`_key` leaves the default factor out). The hash below is the file
    name of the committed mesh II run (results/sleeve_fit/runs) of the ANSUR arm, R = 0.06 m, t = 1 mm, written
    before the factor existed, with the element-formula critical step: the same configuration asking for that step
    (`critical_step = "estimate"`, left out of the key like every parameter added at its former value) still has
    those items (the sha1 of their repr is that name); its checkpoint key now names the engine (the garment engine
    replaced the sleeve's own explicit program, other answers), so that run and every run of the removed program
    are rerun, not read back; the route's default (the eigenvalue step) gets yet another name."""
    import hashlib

    from fabricfem.body.pose import Segment
    from fabricfem.studies.sleeve_fit import _checkpoint, _key
    r_u, r_f = 0.35 / (2 * math.pi), 0.30 / (2 * math.pi)
    old = (Segment("upper_arm", "shoulder", "elbow", "upper_arm_marker", (0.5 * 0.335, r_u, r_u)),
           Segment("forearm", "elbow", "wrist", "forearm_marker", (0.5 * 0.267, r_f, r_f)))
    assert ArmDimensions().segments() == old
    assert ArmDimensions(long_axis_factor=0.5) == DEFAULT_ARM
    cfg = fit_configs((1.0,), mesh="II")[1.0]["R=0.06 t=1mm"]
    assert "long_axis_factor" not in _key(cfg)
    estimate = cfg.with_(critical_step="estimate")
    items = sorted(estimate.key_items().items())
    items = [(k, {a: v for a, v in value.items() if a != "long_axis_factor"} if k == "arm" else value)
             for k, value in items]
    assert hashlib.sha1(repr(items).encode()).hexdigest()[:16] == "c3df774b0f2f3969"    # the items of that run
    assert _key(estimate) == repr(("engine, blended skin w = 0.05", items))
    assert _checkpoint(Path("out"), estimate).name != "c3df774b0f2f3969.json"          # rerun on the engine
    assert _checkpoint(Path("out"), cfg) not in (_checkpoint(Path("out"), estimate),
                                                 Path("out") / "runs" / "c3df774b0f2f3969.json")
    tapered = fit_configs((1.0,), mesh="II", long_axis_factor=0.6)[1.0]["R=0.06 t=1mm"]
    assert summary_row(1.0, tapered.arm, {c: (np.array([0.0, 57.0]), np.ones(2)) for c in FIT_CASES})[
        "elbow_radius_m"] == tapered.arm.elbow_radius > 0.0
    assert "'long_axis_factor': 0.6" in _key(tapered) and _checkpoint(Path("out"), tapered) != _checkpoint(
        Path("out"), cfg)
