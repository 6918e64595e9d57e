"""Woven unit cell with yarn contact (fabricfem.weave.unit_cell), the study driver and the benchmark."""
import csv
import os

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.contact.yarn import YarnContact
from fabricfem.materials.yarn import THESIS_ISOTROPIC, THESIS_TRANSVERSELY_ISOTROPIC
from fabricfem.meshes.unit_cell import MeshResolution, unit_cell
from fabricfem.meshes.yarn_geometry import PlainWeave
from fabricfem.weave.unit_cell import ContactUnitCell, default_contact_parameters, symmetry_pins

WEAVE = PlainWeave.balanced()
BIAXIAL = np.diag([1.04, 1.04, 1.0])


def _cell(comm=MPI.COMM_WORLD, option="quarter"):
    return unit_cell(WEAVE, option, "coarse", comm)


def _min_gap(cell, model: ContactUnitCell) -> float:
    """Smallest signed gap [m] of the warp surface nodes against the weft surface at the current state,
    measured by an independent YarnContact (geometry only, never assembled)."""
    probe = YarnContact(model.problem.u, cell.facet_tags,
                        [(cell.tag("warp0_surface"), cell.tag("weft0_surface"))],
                        default_contact_parameters(model.material, cell))
    probe.Phi = model.Phi
    st = probe.evaluate()
    return float(np.min(st["gap"]))


@pytest.mark.mpi
def test_biaxial_with_contact_two_ranks_equals_serial():
    """Biaxial Phi11 = Phi22 = 1.04, isotropic yarns with contact: the distributed cell (all ranks)
    gives the S of a serial copy (COMM_SELF) within 1e-6 relative (the brief's bound; both runs
    stop Newton at |R| <= 1e-6 of the force scale, and MUMPS' pivoting differs between the
    partitions, so agreement beyond the solver tolerance is not expected)."""
    dist = ContactUnitCell(_cell(MPI.COMM_WORLD), THESIS_ISOTROPIC, contact=True)
    S_dist = dist.solve(BIAXIAL, 1)[-1].S
    if MPI.COMM_WORLD.rank == 0:
        serial = ContactUnitCell(_cell(MPI.COMM_SELF), THESIS_ISOTROPIC, contact=True)
        S_serial = serial.solve(BIAXIAL, 1)[-1].S
    else:
        S_serial = None
    S_serial = MPI.COMM_WORLD.bcast(S_serial, root=0)
    assert np.linalg.norm(S_dist - S_serial) <= 1e-6 * np.linalg.norm(S_serial)


def test_contact_stops_interpenetration():
    """TI yarns under biaxial extension: without contact the yarns pass through each other (negative
    gap, measured independently of the solve); with contact the largest penetration is below the
    augmentation tolerance (1e-3 of the yarn semi-height, the brief's bound), and contact stiffens
    the cell (the crossing yarn resists the decrimping)."""
    cell = _cell(MPI.COMM_SELF)
    free = ContactUnitCell(cell, THESIS_TRANSVERSELY_ISOTROPIC, contact=None)
    S_free = free.solve(BIAXIAL, 2)[-1].S
    assert _min_gap(cell, free) < -0.05 * WEAVE.warp.semi_height  # overlap of several % of b (measured ~-30%)
    cell_c = _cell(MPI.COMM_SELF)
    touching = ContactUnitCell(cell_c, THESIS_TRANSVERSELY_ISOTROPIC, contact=True)
    steps = touching.solve(BIAXIAL, 2)
    report = steps[-1].contact
    assert report.active > 0 and report.normal_force > 0
    assert report.max_penetration <= 1e-3 * WEAVE.warp.semi_height
    assert _min_gap(cell_c, touching) >= -1e-3 * WEAVE.warp.semi_height
    assert steps[-1].S[0, 0] > S_free[0, 0]


def test_balanced_weave_without_contact_is_symmetric_and_pins_are_free():
    """Balanced weave, biaxial Phi: warp and weft are the same yarn turned by 90 degrees, so S11 = S22
    (an exact symmetry of the discrete problem: the mesh sweeps the same section; 1e-8 relative is
    Newton's tolerance 1e-6 of the force scale times the S/force ratio, well below), S12 = 0, and
    the symmetry pins carry no reaction (their residual below 1e-8 of the force scale: zero at the
    exact symmetric solution, round-off otherwise)."""
    model = ContactUnitCell(_cell(MPI.COMM_SELF), THESIS_TRANSVERSELY_ISOTROPIC, contact=None)
    step = model.solve(BIAXIAL, 1)[-1]
    S = step.S
    assert abs(S[0, 0] - S[1, 1]) <= 1e-8 * abs(S[0, 0])
    assert abs(S[0, 1]) <= 1e-8 * abs(S[0, 0])
    assert step.pin_reaction <= 1e-8


def test_full_cell_pins_and_bad_input():
    cell = _cell(MPI.COMM_SELF, "full")
    pins = symmetry_pins(cell)
    assert len(pins) == 3 * 4  # crossing (x, y), rotation, inflection z per yarn
    with pytest.raises(ValueError, match="volume_fraction"):
        ContactUnitCell(cell, THESIS_ISOTROPIC, volume_fraction=1.5)
    with pytest.raises(ValueError, match="material"):
        ContactUnitCell(cell, "kevlar")
    odd = unit_cell(WEAVE, "quarter", MeshResolution(along=3, core=2, ring=1), MPI.COMM_SELF)
    with pytest.raises(ValueError, match="along"):
        symmetry_pins(odd)
    model = ContactUnitCell(_cell(MPI.COMM_SELF), THESIS_ISOTROPIC, contact=None)
    with pytest.raises(ValueError, match="steps"):
        model.solve(BIAXIAL, 0)


def test_quick_study_writes_figures(tmp_path):
    """The --quick study writes one CSV + PNG per figure (21, 24, 25, 26) with converged rows, all with
    the thesis' end faces u_z = 0, and the renders of Figs. 20 and 23 (PNG + XDMF of the deformed
    cell). The snapshot surface is checked against the applied load: closed (every edge shared by two
    faces: the yarns are closed bodies) and its stored Phi is the end of the quick biaxial path
    (1 + 0.2 / 4, exact). A second call with reuse=True solves nothing (every key is found in the
    CSVs, matched by RunKey) and returns the same rows."""
    import time

    import pyvista

    from fabricfem.studies.unit_cell import RENDERS, RunKey, run_study
    runs = run_study(str(tmp_path), quick=True)
    for fig in ("fig21", "fig24", "fig25", "fig26"):
        assert os.path.getsize(tmp_path / f"{fig}.png") > 0
        with open(tmp_path / f"{fig}.csv") as f:
            rows = list(csv.DictReader(f))
        assert rows and all(np.isfinite(float(r["S11"])) for r in rows)
        assert {r["end_faces"] for r in rows} == {"uz_fixed"}
    assert all(len(r.rows) > 0 for r in runs.values())
    for fig, (_, key) in RENDERS.items():
        assert os.path.getsize(tmp_path / f"{fig}.png") > 0
        snap = tmp_path / "snapshots" / key.slug
        assert os.path.getsize(str(snap) + ".xdmf") > 0
        data = np.load(str(snap) + ".npz")
        np.testing.assert_allclose(np.diag(data["Phi"]), [1.05, 1.05, 1.0], rtol=0, atol=1e-14)
        surf = pyvista.PolyData(data["points"] + data["displacement"], data["faces"])
        assert surf.n_open_edges == 0 and surf.n_cells > 0
        assert len(np.unique(data["yarn"])) == 2  # warp and weft, one tag each
    t0 = time.perf_counter()
    again = run_study(str(tmp_path), quick=True, reuse=True)
    assert time.perf_counter() - t0 < 20.0  # reading CSVs and re-rendering only (a solve costs > 1 s a step)
    for key, run in runs.items():
        assert [r["S11"] for r in again[key].rows] == pytest.approx([r["S11"] for r in run.rows], rel=1e-9)
    assert RunKey("ti", "biaxial").end_faces == "uz_fixed"


def test_geometry_sensitivity_reports_infeasible_crimp(tmp_path):
    """crimp 0.04 with phi = 0.4 and section ratio 1.5 needs yarns that interpenetrate at the crossing
    (2 A < 2 b; PlainWeave.balanced raises): geometry_sensitivity records it as infeasible (nan checks,
    reason in `stopped`) instead of failing or dropping it, and still writes the CSV."""
    from fabricfem.studies.unit_cell import geometry_sensitivity
    rows = geometry_sensitivity(str(tmp_path), crimps=(0.04,), end_faces=("uz_fixed",))
    assert len(rows) == 2 and all(np.isnan(r["secant_spread"]) for r in rows)
    assert all(r["stopped"].startswith("geometry infeasible") for r in rows)
    assert os.path.getsize(tmp_path / "geometry_sensitivity.csv") > 0


def test_fe2_paragraph_arithmetic():
    from fabricfem.benchmarks.unit_cell_perf import GAUSS_POINTS, SLEEVE_CELLS, fe2_paragraph
    text = fe2_paragraph(2.0, newton_shell=5, load_steps=20)
    assert f"{SLEEVE_CELLS * GAUSS_POINTS}" in text
    assert f"{SLEEVE_CELLS * GAUSS_POINTS * 5 * 20 * 2.0:.3g}" in text


def test_full_cell_equals_quarter_cell_without_contact():
    """Independent check of the anti-symmetric periodicity: for an in-plane Phi the infinite fabric's
    solution has the glide symmetry (x + p, y, -z) with u*_z -> -u*_z, so the quarter cell (option B,
    that relation on its end faces) and the full cell (option A, plain translations, four yarns) must
    give the same homogenized S (same phi, same S per yarn volume). Tolerance 1e-8 relative: without
    contact Newton converges quadratically and is run to |R| <= 1e-10 of the force scale; the two
    meshes are the same sweep, so no discretisation difference enters."""
    Phi = np.diag([1.02, 1.01, 1.0])
    S = {}
    for option in ("quarter", "full"):
        model = ContactUnitCell(_cell(MPI.COMM_SELF, option), THESIS_TRANSVERSELY_ISOTROPIC, contact=None,
                                rtol=1e-10)
        S[option] = model.solve(Phi, 1)[-1].S
    assert np.linalg.norm(S["full"] - S["quarter"]) <= 1e-8 * np.linalg.norm(S["quarter"])


def test_thesis_end_faces_are_a_variational_upper_bound():
    """Quarter cell, TI yarns, no contact, biaxial Phi = 1.04: the thesis' end-face condition (u*_z = 0
    on the yarn end faces, end_faces="uz_fixed") minimizes the same energy over a subset of the
    periodic fluctuations, so its cell energy is >= that of the exact periodicity (minimum principle;
    tolerance 1e-9 relative for the Newton residual 1e-5 of the force scale, whose energy error is
    quadratic in it) and the pins still carry no load (they sit on symmetry points of both variants;
    1e-6 of the force scale, as in the periodic test above); bad end_faces raise ValueError."""
    import ufl
    from dolfinx import fem

    from fabricfem.forms.yarn import yarn_energy
    energies = {}
    for end_faces in ("periodic", "uz_fixed"):
        cell = _cell()
        model = ContactUnitCell(cell, THESIS_TRANSVERSELY_ISOTROPIC, contact=None, end_faces=end_faces)
        step = model.solve(BIAXIAL, 2)[-1]
        assert step.pin_reaction < 1e-6
        F = model.problem.Phi + ufl.grad(model.problem.u)
        psi = yarn_energy(F.T * F, cell.yarn_axis, THESIS_TRANSVERSELY_ISOTROPIC)
        energies[end_faces] = cell.mesh.comm.allreduce(fem.assemble_scalar(fem.form(psi * ufl.dx(metadata={"quadrature_degree": 2}))), op=MPI.SUM)
    assert energies["uz_fixed"] >= energies["periodic"] * (1.0 - 1e-9)
    assert energies["uz_fixed"] > energies["periodic"]  # the restriction is active (stiffer quarter cell)
    with pytest.raises(ValueError, match="end_faces"):
        ContactUnitCell(_cell(), THESIS_TRANSVERSELY_ISOTROPIC, contact=None, end_faces="clamped")


def test_recompute_stopped_selects_the_stopped_curves(tmp_path, monkeypatch, capsys):
    """`fabricfem study unit-cell --recompute-stopped [--coarse-only | --fine-only] [--budget S]` hands run_study
    the keys of the curves that stopped in --out's CSVs (a hand-written fig CSV: one finished, one stopped coarse,
    one stopped fine) and the budget; a non-positive budget is refused naming the option."""
    import fabricfem.studies.unit_cell as study
    from fabricfem.cli import main
    from fabricfem.studies.unit_cell import RunKey
    columns = ["curve", "material", "load", "contact", "option", "refinement", "end_faces", "stopped", "E11", "S11",
               "wall_s"]
    rows = [("a", "ti", "uniaxial", 1, "quarter", "coarse", "uz_fixed", ""),
            ("b", "ti", "biaxial", 1, "quarter", "coarse", "uz_fixed", "yarn contact: diverged"),
            ("c", "ti", "biaxial", 1, "quarter", "fine", "uz_fixed", "time budget 300 s used up")]
    with open(tmp_path / "fig99.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for r in rows:
            w.writerow(list(r) + [0.01, 1e6, 1.0])
    seen = []
    monkeypatch.setattr(study, "run_study", lambda out, quick=False, recompute=None, time_budget=None, ranks_per_variant=1:
                        seen.append((set(recompute), time_budget)))
    assert main(["study", "unit-cell", "--out", str(tmp_path), "--recompute-stopped"]) == 0
    assert main(["study", "unit-cell", "--out", str(tmp_path), "--recompute-stopped", "--coarse-only"]) == 0
    assert main(["study", "unit-cell", "--out", str(tmp_path), "--recompute-stopped", "--fine-only",
                 "--budget", "1500"]) == 0
    assert main(["study", "unit-cell", "--out", str(tmp_path)]) == 0
    coarse, fine = RunKey("ti", "biaxial"), RunKey("ti", "biaxial", refinement="fine")
    assert seen == [({coarse, fine}, None), ({coarse}, None), ({fine}, 1500.0), (set(), None)]
    assert main(["study", "unit-cell", "--out", str(tmp_path), "--budget", "-5"]) == 2
    assert "--budget" in capsys.readouterr().err


def test_trends_ratios_from_synthetic_csvs(tmp_path):
    """unit-cell-trends reads the study CSVs by key columns: on linear synthetic curves S = k E the
    full/quarter and fine/coarse ratios are k_full / k_quarter and k_fine / k_coarse, taken at the last
    strain both curves reached (interpolation of straight lines is exact, so 1e-12)."""
    from fabricfem.studies.unit_cell import Run, RunKey, _write_csv
    from fabricfem.verify.unit_cell_trends import trends

    def run(key, k, last):
        E = np.linspace(0.02, last, 5)
        return Run(key, [dict(E11=e, E22=e, E12=e, S11=k * e, S22=k * e, S12=k * e, normal_force=1.0) for e in E],
                   "", 0.0, 0, "")
    K = RunKey
    _write_csv(str(tmp_path / "fig27.csv"), [run(K("ti", "biaxial"), 2.0, 0.22),
                                             run(K("ti", "biaxial", option="full"), 1.5, 0.13)])
    _write_csv(str(tmp_path / "fig32.csv"), [run(K("ti", "uniaxial"), 4.0, 0.22),
                                             run(K("ti", "uniaxial", refinement="fine"), 4.4, 0.06)])
    _write_csv(str(tmp_path / "fig33.csv"), [run(K("ti", "shear"), 1.0, 0.2),
                                             run(K("ti", "shear", refinement="fine"), 1.25, 0.2)])
    v = trends(str(tmp_path))
    assert v["full_over_quarter"] == pytest.approx(0.75, rel=1e-12)
    assert v["full_over_quarter_common_E11"] == pytest.approx(0.13, rel=1e-12)
    assert v["fine_over_coarse_uniaxial"] == pytest.approx(1.1, rel=1e-12)
    assert v["fine_over_coarse_uniaxial_common_E11"] == pytest.approx(0.06, rel=1e-12)
    assert v["fine_over_coarse_shear"] == pytest.approx(1.25, rel=1e-12)
    assert np.isnan(v["fine_over_coarse_biaxial"]) and np.isnan(v["iso_uniaxial_S22_S11"])  # curves missing


def test_quick_benchmark_writes_csv_with_ratio(tmp_path):
    """`fabricfem bench unit-cell --quick`: one run of the coarse quarter cell, CSV + PNG + FE2 text; its time
    ratio against the baseline (itself) is 1 and the times are positive."""
    from fabricfem.benchmarks.unit_cell_perf import unit_cell_perf
    rows = unit_cell_perf(str(tmp_path), quick=True)
    assert len(rows) == 1 and rows[0]["step_over_baseline"] == 1.0 and rows[0]["step_s"] > 0.0
    with open(tmp_path / "unit_cell_perf.csv") as f:
        assert float(next(csv.DictReader(f))["step_over_baseline"]) == 1.0
    assert os.path.getsize(tmp_path / "unit_cell_perf.png") > 0
    assert "FE2 costing" in (tmp_path / "fe2_costing.txt").read_text()


def test_stop_probe_without_a_stop_tries_no_remedy(tmp_path):
    """benchmarks.unit_cell_stop on a short path that converges (coarse quarter cell, 1/10 of the biaxial
    strain in 2 steps): one row, converged, at the end strain E11 = ((1.02)^2 - 1) / 2 = 0.0202 exactly."""
    from fabricfem.benchmarks.unit_cell_stop import probe_stop
    rows = probe_stop("quarter", steps=2, scale=0.1, out=str(tmp_path))
    assert [r["remedy"] for r in rows] == ["study settings"] and rows[0]["converged"] == 1
    assert rows[0]["E11"] == pytest.approx(0.0202, rel=1e-12)
    assert (tmp_path / "unit_cell_stop_quarter.csv").exists()


def test_stop_probe_tries_remedies_until_one_converges(tmp_path, monkeypatch):
    """The probe's control flow with a scripted stop: solves beyond Phi11 = 1.012 fail unless Newton may take
    80 iterations. The study path stops there, the first remedy (max_it 80) converges, is kept, and the path
    goes on to its end (E11 = 0.0202), so no further remedy is tried."""
    import fabricfem.weave.unit_cell as ucc
    from fabricfem.benchmarks.unit_cell_stop import probe_stop
    from fabricfem.solvers.newton import SolverError
    solve = ucc.ContactUnitCell.solve

    def scripted(self, Phi, steps=1):
        if Phi[0, 0] > 1.012 and self.problem.newton.max_it != 80:
            raise SolverError("scripted stop", reason="SCRIPTED")
        return solve(self, Phi, steps)
    monkeypatch.setattr(ucc.ContactUnitCell, "solve", scripted)
    rows = probe_stop("quarter", steps=2, scale=0.1, out=str(tmp_path))
    assert [(r["remedy"], r["converged"]) for r in rows] == [("study settings", 0), ("max_it 80", 1)]
    assert rows[0]["message"] == "scripted stop" and rows[1]["E11"] == pytest.approx(0.0202, rel=1e-12)


def test_stop_probe_refuses_bad_steps(tmp_path):
    from fabricfem.benchmarks.unit_cell_stop import probe_stop
    for bad in (0, -3, 2.5, True):
        with pytest.raises(ValueError, match="steps"):
            probe_stop("quarter", steps=bad, out=str(tmp_path))
