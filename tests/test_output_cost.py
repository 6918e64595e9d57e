"""Output off the time loop: the bulk-written XDMF series equal dolfinx's own files (the same XML text, the same
datasets to round-off), the body frames written without VTK equal pyvista's, the peak skin frame computed when it is
final equals the one computed at its record, and summary.json carries the run's wall split (setup, time loop,
output in the loop, after)."""
import importlib.util
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from dolfinx import fem
from dolfinx import io as dio
from mpi4py import MPI
from test_checkpoint import SCENE, SQUARES

from fabricfem import io as fio
from fabricfem import scenes as scene_module
from fabricfem.meshes.tube import tube
from fabricfem.scenes.run import run_scene
from fabricfem.wear import recorder as recorder_module
from fabricfem.wear.outputs import body_surface, skin_pressure
from fabricfem.wear.writer import BackgroundWriter, FieldSeries, write_vtp

HAS_PYVISTA = importlib.util.find_spec("pyvista") is not None
TIMES = (0.0, 0.02222222222222225, 0.4, 1e-5, 1.0 / 45.0 * 7.0)


def _datasets(path: Path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as h5:
        out = {}
        h5.visititems(lambda name, item: out.__setitem__(name, item[()]) if isinstance(item, h5py.Dataset) else None)
    return out


@pytest.fixture(scope="module")
def fields():
    """A vector and a scalar Q2 field on a small Q2 tube (the garment's geometry degree)."""
    mesh = tube(0.2, 0.05, 6, 3, order=2, comm=MPI.COMM_SELF).mesh
    u = fem.Function(fem.VectorFunctionSpace(mesh, ("Lagrange", 2), dim=3), name="displacement")
    p = fem.Function(fem.FunctionSpace(mesh, ("Lagrange", 2)), name="contact_pressure")
    return u, p


def _set(f: fem.Function, k: int) -> None:
    bs = f.function_space.dofmap.index_map_bs
    f.interpolate(lambda x: np.vstack([x[0] * (k + 1) + x[1] ** 2, x[2] - k, x[1] * x[0]])[:bs])


@pytest.mark.parametrize("which", [0, 1])
def test_bulk_series_equal_dolfinx_files(tmp_path, fields, which):
    """FieldSeries (kept in memory, flushed every 2 records on the writer thread, then appended to after a reopen
    as a resumed run does) writes the XML text of dolfinx's write_function and its datasets to 1e-14 (dolfinx
    evaluates the field at the nodes, the series copies the nodal values)."""
    f = fields[which]
    writer = BackgroundWriter()
    series = FieldSeries(tmp_path / "new.xdmf", f, "w", writer, flush_every=2)
    with dio.XDMFFile(MPI.COMM_SELF, str(tmp_path / "ref.xdmf"), "w") as ref:
        ref.write_mesh(f.function_space.mesh)
        for k, t in enumerate(TIMES):
            if k == 3:                       # a checkpoint and a resume: written, reopened, appended to
                series.flush()
                writer.wait()
                series = FieldSeries(tmp_path / "new.xdmf", f, "a", writer, flush_every=2)
            _set(f, k)
            ref.write_function(f, t)
            series.add(t)
    series.flush()
    writer.close()
    assert (tmp_path / "new.xdmf").read_text().replace("new.h5", "X.h5") == \
        (tmp_path / "ref.xdmf").read_text().replace("ref.h5", "X.h5")
    new, ref = _datasets(tmp_path / "new.h5"), _datasets(tmp_path / "ref.h5")
    assert list(new) == list(ref) and len(ref) == 2 + len(TIMES)
    for name, values in ref.items():
        assert new[name].shape == values.shape and new[name].dtype == values.dtype, name
        assert np.abs(new[name] - values).max() <= 1e-14 * max(np.abs(values).max(), 1.0), name
    assert fio.xdmf_fields(tmp_path / "new.xdmf") == {f.name: list(TIMES)}


def test_writer_thread_reports_a_failed_job():
    """An error of a job on the writer thread is raised by wait() on the caller's thread."""
    writer = BackgroundWriter()
    writer.submit(lambda: 1 / 0)
    with pytest.raises(RuntimeError, match="writing the outputs failed"):
        writer.wait()
    writer.close()


@pytest.mark.skipif(not HAS_PYVISTA, reason="pyvista is optional")
def test_body_frame_equals_pyvista_save(tmp_path):
    """write_vtp's file reads back (VTK) with the points and triangles pyvista's PolyData.save wrote before."""
    import pyvista as pv

    from fabricfem.body.ellipsoid import Ellipsoid
    points, triangles = body_surface([Ellipsoid(np.array([0.1, 0.0, 0.0]), np.eye(3), np.array([0.2, 0.05, 0.04]))],
                                     6)
    pv.PolyData(points, np.hstack([np.full((len(triangles), 1), 3), triangles]).ravel()).save(tmp_path / "ref.vtp")
    write_vtp(tmp_path / "new.vtp", points, triangles)
    ref, new = pv.read(tmp_path / "ref.vtp"), pv.read(tmp_path / "new.vtp")
    assert np.array_equal(new.points, ref.points) and np.array_equal(new.faces, ref.faces)
    assert new.n_cells == ref.n_cells == len(triangles)


@pytest.fixture(scope="module")
def squares_run(tmp_path_factory):
    """The sewn squares of tests/test_checkpoint.py with renders on (the PNGs not drawn): the recorder's final peak
    frame and the frame computed at each new peak's record, as before."""
    folder = tmp_path_factory.mktemp("squares")
    (folder / "squares.toml").write_text(SQUARES)
    (folder / "scene.toml").write_text(SCENE.replace("render = false", "render = true"))
    at_record, kept = {}, {}
    record, close = recorder_module.WearRecorder.record, recorder_module.WearRecorder.close

    def record_and_compare(self, step):
        record(self, step)
        if self.peak_frame is not None and self.peak_frame[0] is step:   # a new peak: the frame as it was made
            run = self.run
            points, cells = fio.gather_surface(run.model.mesh, run.model.displacement())
            values = fio.gather_field(run.model.mesh, run.pressure_field())
            spacing = float(np.median(np.linalg.norm(points[cells[:, 0]] - points[cells[:, 1]], axis=1)))
            at_record["peak"] = skin_pressure(run.posed_bodies(step.coordinate), 2 * self.samples, points, values,
                                              2.0 * max(spacing, 1e-6))

    def close_and_keep(self, history):
        self._keep_peak_frame()
        self._flush()
        kept.update({f[0]: f[2] for f in self.skin_frames})
        self.skin_frames = []            # the renders are not drawn here
        close(self, history)

    patch = pytest.MonkeyPatch()
    patch.setattr(recorder_module.WearRecorder, "record", record_and_compare)
    patch.setattr(recorder_module.WearRecorder, "close", close_and_keep)
    try:
        outcome = run_scene(scene_module.load(folder / "scene.toml"), MPI.COMM_SELF, out=folder / "out")
    finally:
        patch.undo()
    return outcome, at_record, kept


def test_deferred_peak_frame_equals_the_frame_at_its_record(squares_run):
    """The pressure on the skin of pressure_peak.png, computed once no later record replaced it, equals the one
    computed at the record of the peak (points, triangles, values [Pa])."""
    _, at_record, kept = squares_run
    assert "peak" in at_record and "pressure_peak.png" in kept
    for a, b in zip(at_record["peak"], kept["pressure_peak.png"]):
        assert np.array_equal(a, b)


def test_summary_carries_the_wall_split(squares_run):
    """summary.json: wall_split with setup, time loop, output in the loop and after [s], their total and shares;
    the records are all in the XDMF files and the body frames."""
    outcome, _, _ = squares_run
    out = outcome.out
    split = json.loads((out / "summary.json").read_text())["wall_split"]
    for key in ("setup_s", "loop_s", "output_in_loop_s", "after_s", "total_s"):
        assert np.isfinite(split[key]) and split[key] >= 0.0, key
    assert split["total_s"] == pytest.approx(split["setup_s"] + split["loop_s"] + split["after_s"])
    assert 0.0 < split["output_in_loop_s"] < split["loop_s"]
    assert split["setup_from"] in ("process start", "run start")
    assert split["output_share_of_loop"] == pytest.approx(split["output_in_loop_s"] / split["loop_s"])
    assert split["outside_loop_share"] == pytest.approx((split["setup_s"] + split["after_s"]) / split["total_s"])
    records = len(outcome.result.steps)
    assert all(len(times) == records for times in fio.xdmf_fields(out / "cloth.xdmf").values())
    assert len(list(out.glob("body_*.vtp"))) == records
    assert not list(out.glob("*.partial"))
