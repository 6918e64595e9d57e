"""`fabricfem sweep`: variants validated before anything runs, the batch on sub-communicators gives the table of
the variants run one by one (1e-12), and an interrupted sweep resumes without rerunning finished variants."""
import csv
import json
import math
import tempfile
from pathlib import Path

import pytest
from mpi4py import MPI

from fabricfem import cli
from fabricfem.scenes import run as scene_run
from fabricfem.scenes import sweep
from fabricfem.scenes.build import validate
from fabricfem.scenes.schema import SceneError

# a 4 x 4 membrane cloth pinned at two corners, 0.1 s of explicit dynamics (about 0.5 s a run)
TINY = {
    "scene": {"name": "tiny", "kind": "dynamic"},
    "mesh": {"type": "plate", "lx": 1.0, "ly": 1.0, "nx": 4, "ny": 4},
    "model": {"kind": "membrane"},
    "fabric": {"E1": 9940.5, "E2": 9940.5, "G12": 3976.2, "nu12": 0.0, "thickness": 0.001177, "density": 99.405},
    "support": [{"point": [0.0, 0.0, 0.0], "u": [0, 0, 0]}, {"point": [0.0, 1.0, 0.0], "u": [0, 0, 0]}],
    "dynamics": {"integrator": "explicit", "dt": "auto", "end_time": 0.1, "air_drag": 0.351,
                 "gravity": [0.0, 0.0, -9.81],
                 "monitors": [{"name": "corner_uz", "point": [1.0, 1.0, 0.0], "component": 2}]},
    "output": {"render": False},
}
VARY = [("fabric.E1", [5000.0, 10000.0]), ("dynamics.dt_fraction", [0.5, 0.9])]
# entries of a run's summary that depend on the machine or the clock, not on the result
VOLATILE = {"wall_s", "time_integration_wall_s", "started", "finished", "scene_sha256", "variant"}


def _numeric(row: dict) -> dict:
    return {k: float(v) for k, v in row.items() if k not in VOLATILE and not k.startswith("peak_memory")
            and _is_number(v)}


def _is_number(v) -> bool:
    try:
        float(v)
        return True
    except (TypeError, ValueError):
        return False


def _read_table(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_parse_vary_reads_toml_values():
    assert sweep.parse_vary("fabric.E1=1e6,2e6") == ("fabric.E1", [1e6, 2e6])
    assert sweep.parse_vary("dynamics.gravity=[0, 0, -9.81],[0, 0, -1]") == (
        "dynamics.gravity", [[0, 0, -9.81], [0, 0, -1]])
    assert sweep.parse_vary('mesh.cell="triangle",quadrilateral') == ("mesh.cell", ["triangle", "quadrilateral"])
    with pytest.raises(ValueError, match="--vary"):
        sweep.parse_vary("fabric.E1")


@pytest.mark.parametrize("vary, text", [
    (("fabric.E7", [1.0]), "fabric: unknown key 'E7'"),
    (("fabric.E1", [-1.0]), "fabric.E1"),
    (("dynamics.monitors.3.name", ["x"]), "dynamics.monitors"),
    (("mesh", [1]), "section.key"),
])
def test_bad_variant_is_refused_before_anything_runs(vary, text, monkeypatch, tmp_path):
    monkeypatch.setattr(sweep, "run_scene", lambda *a, **k: pytest.fail("a variant ran"))
    base = validate(json.loads(json.dumps(TINY)))
    with pytest.raises(SceneError, match=text) as info:
        sweep.run_sweep(base, [("dynamics.dt_fraction", [0.5]), vary], tmp_path, comm=MPI.COMM_SELF)
    assert "variant dynamics.dt_fraction=0.5_" in str(info.value)


def test_cli_refuses_unknown_key_naming_it(tmp_path, capsys):
    from toml_text import dumps
    path = tmp_path / "tiny.toml"
    path.write_text(dumps(TINY))
    code = cli.main(["sweep", str(path), "--vary", "fabrik.E1=1,2", "--out", str(tmp_path / "s")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "fabrik" in err and len(err.splitlines()) == 1


def test_interrupted_sweep_resumes_without_rerunning(monkeypatch, tmp_path):
    """First pass: one variant raises (a killed run); the second reruns only that one, the others are read back
    (their summary.json untouched)."""
    base = validate(json.loads(json.dumps(TINY)))
    calls = []
    real = scene_run.run_scene

    def flaky(scene, comm):
        calls.append(Path(scene["output"]["dir"]).name)
        if "E1=10000.0_dynamics.dt_fraction=0.9" in calls[-1] and len(calls) <= 4:
            raise RuntimeError("killed")
        return real(scene, comm)

    monkeypatch.setattr(sweep, "run_scene", flaky)
    rows = sweep.run_sweep(base, VARY, tmp_path, comm=MPI.COMM_SELF)
    assert len(calls) == 4
    assert [r["status"] for r in rows].count("completed") == 3
    assert rows[-1]["status"] == "failed: killed"
    stamps = {r["variant"]: (tmp_path / r["variant"] / "summary.json").stat().st_mtime_ns for r in rows[:3]}
    rows = sweep.run_sweep(base, VARY, tmp_path, comm=MPI.COMM_SELF)
    assert calls[4:] == [rows[-1]["variant"]]                       # only the failed variant ran again
    assert all(r["status"] == "completed" for r in rows)
    assert stamps == {v: (tmp_path / v / "summary.json").stat().st_mtime_ns for v in stamps}
    assert (tmp_path / "sweep.png").is_file()
    table = _read_table(tmp_path / "sweep.csv")
    assert [r["variant"] for r in table] == [r["variant"] for r in rows]
    assert all(math.isfinite(float(r["final_corner_uz"])) for r in table)


def test_changed_scene_is_rerun(monkeypatch, tmp_path):
    """A completed folder of another scene (another hash) is not read back."""
    base = validate(json.loads(json.dumps(TINY)))
    sweep.run_sweep(base, [("fabric.E1", [5000.0])], tmp_path, comm=MPI.COMM_SELF)
    changed = json.loads(json.dumps(TINY))
    changed["dynamics"]["end_time"] = 0.05
    calls = []
    monkeypatch.setattr(sweep, "run_scene", lambda scene, comm: calls.append(1) or scene_run.run_scene(scene, comm))
    sweep.run_sweep(validate(changed), [("fabric.E1", [5000.0])], tmp_path, comm=MPI.COMM_SELF)
    assert calls == [1]


@pytest.mark.mpi
def test_sweep_on_all_ranks_gives_the_serial_table():
    """4 variants on every rank of COMM_WORLD (one rank each) against the same 4 run one by one on COMM_SELF:
    every numeric entry of sweep.csv equal to 1e-12 (relative)."""
    comm = MPI.COMM_WORLD
    out = Path(comm.bcast(tempfile.mkdtemp(prefix="sweep_") if comm.rank == 0 else None, root=0))
    base = validate(json.loads(json.dumps(TINY)))
    sweep.run_sweep(base, VARY, out / "batch", comm=comm)
    if comm.rank == 0:
        serial = []
        for variant in sweep.variants(base, VARY, out / "serial"):
            scene_run.run_scene(variant.scene, MPI.COMM_SELF)
            summary = sweep.read_summary(out / "serial" / variant.name)
            serial.append({**variant.values, **sweep.scalar_entries(summary)})
        batch = _read_table(out / "batch" / "sweep.csv")
        assert len(batch) == 4 and all(r["status"] == "completed" for r in batch)
        for b, s in zip(batch, serial):
            b, s = _numeric(b), _numeric(s)
            assert set(b) == set(s)
            for key in b:
                assert abs(b[key] - s[key]) <= 1e-12 * max(abs(s[key]), 1e-30), key
    comm.barrier()


def test_a_wear_summary_gives_its_monitors_as_sweep_columns():
    """A wear run's per-monitor tables become dotted columns (the names accuracy targets use); lists of windows
    and the verdict's table of checks do not."""
    from fabricfem.scenes.sweep import scalar_entries
    row = scalar_entries({"records": 3, "torque_elbow": {"peak_Nm": 0.05, "window_mean_Nm": 0.04, "peak_at": 6.0},
                          "pressure": {"peak_Pa": 150.0, "peak_position_m": [0.0, 0.1, 0.0]},
                          "verdict": {"status": "plausible", "checks": []}, "statistics": {"windows": [[3.0, 6.0]]}})
    assert row == {"records": 3, "torque_elbow.peak_Nm": 0.05, "torque_elbow.window_mean_Nm": 0.04,
                   "torque_elbow.peak_at": 6.0, "pressure.peak_Pa": 150.0}
