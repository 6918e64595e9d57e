"""The studies run their variants through the sweep's batch (fabricfem.scenes.batch): longest first to the least
loaded group, a variant that fails is reported after the others have run and saved, and a rerun of a killed study
reads the finished variants back instead of running them again. Stub runners (no finite elements): seconds."""
import json
from pathlib import Path

import pytest
from mpi4py import MPI

from fabricfem import cli
from fabricfem.scenes import batch
from fabricfem.studies import pants, sleeve
from fabricfem.studies import unit_cell as unit_cell_study
from fabricfem.wear.contract import WearHistory, WearStep


def test_schedule_gives_the_longest_first_to_the_least_loaded_group():
    costs = [1.0, 5.0, None, 3.0, 3.0]
    assert batch.longest_first(costs) == [1, 3, 4, 0, 2]
    # 5 -> g0; 3 -> g1; 3 -> g1 (3 < 5); 1 -> g0 (loads 5 < 6); unknown (1) -> g0 (6 = 6, the first)
    assert batch.schedule(costs, 2) == [0, 0, 0, 1, 1]
    assert batch.schedule(costs, 1) == [0] * 5


def test_run_batch_skips_done_jobs_and_goes_on_after_a_failure():
    ran, done = [], {"b"}

    def job(name, cost):
        def run(comm):
            ran.append(name)
            if name == "c":
                raise RuntimeError("killed\nhere")
            done.add(name)
        return batch.Job(name, cost, run, lambda: name in done)
    jobs = [job("a", 1.0), job("b", 9.0), job("c", 5.0), job("d", None)]
    assert batch.run_batch(jobs, MPI.COMM_SELF) == {"c": "failed: killed here"}
    assert ran == ["c", "a", "d"]                          # longest first, unknown cost last, b read back
    assert batch.run_batch(jobs, MPI.COMM_SELF) == {"c": "failed: killed here"} and ran[3:] == ["c"]
    with pytest.raises(ValueError, match="--ranks-per-variant"):
        batch.run_batch(jobs, MPI.COMM_SELF, ranks_per_job=2)


def _stub_step(angle: float, tau: float) -> WearStep:
    """A record at elbow angle `angle` [deg] (the start state at 0): elbow torque tau x angle, both segments' tau
    [N m], contact force 1 N, 10 time steps, wall 0.1 s."""
    return WearStep(phase="motion" if angle > 0.0 else "settle", time=0.0,
                    torques={"elbow": tau * angle, "elbow_both_segments": tau}, peak_pressure=0.0, peak_segment="",
                    peak_position=(0.0, 0.0, 0.0), mean_pressure=0.0, max_penetration=0.0, contact_force=1.0,
                    seam_gap=0.0, seam_forces={}, max_strain=0.0, time_steps=10, kinetic_energy=0.0,
                    strain_energy=0.0, wall=0.1, axis_value=angle)


def _stub_sleeve(calls: list, kill: set):
    """run_sleeve without finite elements: a two-record history whose torque encodes the configuration."""
    def run_sleeve(cfg, comm, on_step=None, stop_on_failure=True):
        calls.append(cfg.tube.n_around)
        if len(calls) in kill:
            raise RuntimeError("killed")
        tau = 1e-3 * cfg.tube.n_around + cfg.contact.friction
        h = WearHistory(cfg.name, steps=[_stub_step(a, tau) for a in (0.0, 3.0)])
        h.wall = 0.1
        return h
    return run_sleeve


def test_killed_sleeve_study_resumes_longest_first(monkeypatch, tmp_path):
    """Mesh series I, II, III at mu = 0.1 and the friction figure on mesh II (4 distinct variants, one shared):
    run longest first (III, II, II mu 0.5, I); the third variant is killed (the study raises naming it, after
    the others are saved); the rerun runs that one only and writes the figures from the saved variants."""
    calls = []
    monkeypatch.setattr(sleeve, "run_sleeve", _stub_sleeve(calls, kill={3}))
    options = dict(quick=False, comm=MPI.COMM_SELF, fine="II", meshes=("I", "II", "III"), fabrics=("I",),
                   mesh_frictions=(0.1,), only=("mesh_mu0.1", "friction"))
    with pytest.raises(batch.BatchError, match="1 variant.*failed.*killed"):
        sleeve.run_study(tmp_path, **options)
    assert calls == [20, 15, 15, 10]
    assert len(list((tmp_path / "variants").glob("*.csv"))) == 3
    results = sleeve.run_study(tmp_path, **options)
    assert calls[4:] == [15]                               # only the killed variant ran again
    assert results["friction"]["mu = 0.5"].steps[-1].torques["elbow"] == pytest.approx(3 * (0.015 + 0.5))
    rows = (tmp_path / "mesh_mu0.1.csv").read_text().splitlines()
    assert len(rows) == 1 + 3 * 2 and rows[1].startswith("mesh I (10x13),0.0,")


def test_killed_unit_cell_study_resumes(monkeypatch, tmp_path):
    """The quick study's six load cases with a stub solver: contact cases first (shear, with its pre-stretch step,
    before all), the case without contact last; a killed case is reported after the others are saved to
    variants/*.json, and the rerun solves that one only; the figure CSVs hold the saved rows."""
    calls = []

    def run_case(key, steps, scale=1.0, weave=None, comm=None, time_budget=None, snapshot=None):
        calls.append(key)
        if len(calls) == 2:
            raise RuntimeError("killed")
        if snapshot is not None:
            for ext in (".xdmf", ".npz"):
                Path(snapshot + ext).write_text("")
        rows = [dict(E11=0.01 * k, E22=0.0, E12=0.0, S11=1e6 * k + 0.1, S22=0.0, S12=0.0, newton=k) for k in (1, 2)]
        return unit_cell_study.Run(key, rows, "", 0.1, 100, "table")

    monkeypatch.setattr(unit_cell_study, "run_case", run_case)
    monkeypatch.setattr(unit_cell_study, "render_configuration", lambda *a: "none")
    monkeypatch.setattr(unit_cell_study, "_plot", lambda *a: None)
    with pytest.raises(batch.BatchError, match="1 variant.*failed"):
        unit_cell_study.run_study(str(tmp_path), quick=True, comm=MPI.COMM_SELF)
    first = calls[:]
    assert first[0] == unit_cell_study.RunKey("ti", "shear") and not first[-1].contact and len(first) == 6
    assert len(list((tmp_path / "variants").glob("*.json"))) == 5
    runs = unit_cell_study.run_study(str(tmp_path), quick=True, comm=MPI.COMM_SELF)
    assert calls[6:] == [first[1]]
    assert runs[first[1]].rows[1]["S11"] == 2e6 + 0.1 and len(runs) == 6
    assert "2000000.1" in (tmp_path / "fig21.csv").read_text()
    unit_cell_study.run_study(str(tmp_path), quick=True, comm=MPI.COMM_SELF, steps=4)   # other steps: solved again
    assert len(calls) == 13


def test_killed_pants_study_resumes(monkeypatch, tmp_path, capsys):
    """Three variants with a stub run (a completed summary.json of the variant's scene hash): the coarser mesh
    (h = 10 cm, the cheaper) runs last; a killed variant is reported after the others, the rerun runs only it."""
    calls = []

    def run_variant(data, out, comm):
        calls.append(out.name)
        if len(calls) == 1:
            raise RuntimeError("killed")
        folder = pants.fio.OutputFolder(out, pants.scene_sha256(pants.Scene(data, None, "wear")), comm)
        folder.finish("completed")
        return "completed"

    monkeypatch.setattr(pants, "_run_variant", run_variant)
    monkeypatch.setattr(pants, "_read_variant", lambda out: out.name)
    monkeypatch.setattr(pants, "write_study", lambda out, curves, quick, crossing: {"curves": curves, "lines": []})
    monkeypatch.setattr(pants, "crossing_window", lambda data: None)
    chosen = {k: pants.VARIANTS[k] for k in ("1mm_mu0.1_h10cm", "1mm_mu0.1", "2mm_mu0.1")}
    with pytest.raises(batch.BatchError, match="1 variant.*failed.*1mm_mu0.1: failed: killed"):
        pants.run_pants_study(tmp_path, comm=MPI.COMM_SELF, variants=chosen)
    assert calls == ["1mm_mu0.1", "2mm_mu0.1", "1mm_mu0.1_h10cm"]
    summary = pants.run_pants_study(tmp_path, comm=MPI.COMM_SELF, variants=chosen)
    assert calls[3:] == ["1mm_mu0.1"]
    calls.clear()                                        # the command line: exit 1 naming the killed variant
    assert cli.main(["study", "pants", "--out", str(tmp_path / "cli")]) == 1
    assert "pants study: 1 variant(s) failed" in capsys.readouterr().err and len(calls) == len(pants.VARIANTS)
    assert list(summary["curves"]) == list(chosen)
    assert json.loads((tmp_path / "1mm_mu0.1" / "summary.json").read_text())["status"] == "completed"


@pytest.mark.mpi
def test_sleeve_study_on_all_ranks_gives_the_serial_figures(monkeypatch, tmp_path_factory):
    """The stub sleeve study on every rank of COMM_WORLD (groups of one rank: under mpirun -n 2 each rank runs its
    share) writes the figure CSVs of the study run on COMM_SELF, and ranks_per_variant = size runs all on one
    group."""
    calls = []
    monkeypatch.setattr(sleeve, "run_sleeve", _stub_sleeve(calls, kill=set()))
    comm = MPI.COMM_WORLD
    root = Path(comm.bcast(str(tmp_path_factory.mktemp("batch")) if comm.rank == 0 else None, root=0))
    options = dict(fine="II", meshes=("I", "II", "III"), fabrics=("I",), mesh_frictions=(0.1,),
                   only=("mesh_mu0.1", "friction"))
    sleeve.run_study(root / "world", comm=comm, **options)
    assert sum(comm.allgather(len(calls))) == 4              # each distinct variant ran once, on one group
    sleeve.run_study(root / "group", comm=comm, ranks_per_variant=comm.size, **options)
    if comm.rank == 0:
        sleeve.run_study(root / "self", comm=MPI.COMM_SELF, **options)
        for name in ("mesh_mu0.1.csv", "friction.csv"):
            assert (root / "world" / name).read_text() == (root / "self" / name).read_text()
            assert (root / "group" / name).read_text() == (root / "self" / name).read_text()
    comm.barrier()


def test_killed_sleeve_methods_resume_implicit_first(monkeypatch, tmp_path):
    """The three contact methods with a stub run: the implicit route (the longest) first; a killed method is
    named after the others are saved, the rerun runs only it, and the table keeps the order asked for."""
    calls = []

    def run_method(method, base, comm, al_budget):
        calls.append(method)
        if len(calls) == 2:
            raise RuntimeError("killed")
        return {"method": method, "route": sleeve.METHODS[method], "ranks": comm.size, "torque_57_Nm": 0.1,
                "max_penetration_m": float("nan")}

    monkeypatch.setattr(sleeve, "_run_method", run_method)
    monkeypatch.setattr(sleeve, "methods_markdown", lambda rows: "")
    out = tmp_path / "methods.csv"
    with pytest.raises(batch.BatchError, match="lagrange on mesh I: failed: killed"):
        sleeve.run_methods(out, mesh="I", comm=MPI.COMM_SELF)
    assert calls == ["augmented", "lagrange", "penalty"]
    rows = sleeve.run_methods(out, mesh="I", comm=MPI.COMM_SELF)
    assert calls[3:] == ["lagrange"] and [r["method"] for r in rows] == ["lagrange", "penalty", "augmented"]
    assert out.read_text().splitlines()[1].startswith("lagrange,")
    sleeve.run_methods(out, mesh="I", comm=MPI.COMM_SELF, al_budget=60.0)     # another budget: run again
    assert calls[4:] == ["augmented", "lagrange", "penalty"]
