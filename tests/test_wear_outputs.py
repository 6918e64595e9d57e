"""What a garment engineer reads: XDMF fields read back by name with meshio (h5py), joint
moments in OpenSim's storage format, contact pressure on the skin, its render, progress lines without "nan"."""
import importlib.util
import json
import math
import re

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.wear.outputs import (
    MMHG_PER_KPA,
    gather_contact,
    idw_at,
    render_skin_pressure,
    skin_pressure,
    write_sto,
)

HAS_PYVISTA = importlib.util.find_spec("pyvista") is not None
SPHERE = Ellipsoid(np.zeros(3), np.eye(3), np.full(3, 0.1))     # radius 0.1 m


# ---------------------------------------------------------------------------------------- XDMF + meshio
def test_xdmf_field_names_read_back_with_meshio(tmp_path):
    """Functions named "displacement" and "pressure_mmHg" written by dolfinx come back under those names: both in
    io.xdmf_fields; meshio's XDMF reader (HDF5 through h5py) reads the mesh and the last-written function (dolfinx
    writes one temporal collection per function, meshio reads the last); h5py reads the others by name."""
    h5py = pytest.importorskip("h5py")
    meshio = pytest.importorskip("meshio")
    from dolfinx import fem, io, mesh
    domain = mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
    u = fem.Function(fem.VectorFunctionSpace(domain, ("Lagrange", 1)), name="displacement")
    u.interpolate(lambda x: np.stack([x[0], 2.0 * x[1]]))
    p = fem.Function(fem.FunctionSpace(domain, ("Lagrange", 1)), name="pressure_mmHg")
    p.interpolate(lambda x: 3.0 + 0.0 * x[0])
    path = tmp_path / "tiny.xdmf"
    with io.XDMFFile(MPI.COMM_SELF, str(path), "w") as xdmf:
        xdmf.write_mesh(domain)
        for t in (0.0, 0.5):
            xdmf.write_function(u, t)
        xdmf.write_function(p, 0.0)
    assert fio.xdmf_fields(path) == {"displacement": [0.0, 0.5], "pressure_mmHg": [0.0]}
    with meshio.xdmf.TimeSeriesReader(str(path)) as reader:
        points, cells = reader.read_points_cells()
        t, point_data, _ = reader.read_data(0)
    assert len(points) == 9 and cells[0].type == "triangle" and t == 0.0
    assert list(point_data) == ["pressure_mmHg"] and np.allclose(point_data["pressure_mmHg"], 3.0)
    with h5py.File(path.with_suffix(".h5"), "r") as h5:
        assert set(h5["Function"]) == {"displacement", "pressure_mmHg"}
        assert set(h5["Function/displacement"]) == {"0", "0_5"}          # the times, "." written as "_"
        displacement = h5["Function/displacement/0_5"][:]
    assert np.allclose(displacement[:, :2], points[:, :2] * [1.0, 2.0])


# ---------------------------------------------------------------------------------------- OpenSim .sto
def read_sto(path) -> tuple[list[str], list[str], np.ndarray]:
    """(header lines up to endheader, column labels, data (rows, columns)) of a storage file."""
    lines = path.read_text().splitlines()
    end = lines.index("endheader")
    labels = lines[end + 1].split("\t")
    data = np.array([[float(v) for v in line.split("\t")] for line in lines[end + 2:]])
    return lines[:end + 1], labels, data


def test_sto_round_trip_and_header(tmp_path):
    """The header of OpenSim's Storage (.sto) files: name, version=1, nRows, nColumns (time included),
    inDegrees=no, comment lines, endheader; then the tab-separated table with time first."""
    times = np.linspace(0.0, 1.0, 5)
    columns = {"elbow_moment": np.sin(times), "knee_moment": -0.25 * times}
    note = "Units are S.I. units (second, N m)\nsign: positive moments resist flexion"
    path = tmp_path / "moments.sto"
    write_sto(path, times, columns, MPI.COMM_SELF, note)
    header, labels, data = read_sto(path)
    assert header == ["moments", "version=1", "nRows=5", "nColumns=3", "inDegrees=no",
                      "Units are S.I. units (second, N m)", "sign: positive moments resist flexion", "endheader"]
    assert labels == ["time", "elbow_moment", "knee_moment"]
    assert data.shape == (5, 3)
    assert np.allclose(data[:, 0], times) and np.allclose(data[:, 1], columns["elbow_moment"])
    assert np.allclose(data[:, 2], columns["knee_moment"])


@pytest.mark.parametrize("kwargs, name", [
    ({"times": [0.0, 1.0], "columns": {"elbow_moment": [1.0]}}, r"columns\['elbow_moment'\]"),
    ({"times": [1.0, 0.0], "columns": {"elbow_moment": [1.0, 2.0]}}, "times"),
    ({"times": [0.0, 1.0], "columns": {"elbow moment": [1.0, 2.0]}}, "columns"),
    ({"times": [0.0, 1.0], "columns": {"a_moment": [1.0, 2.0]}, "header_note": "positive = flexion"}, "header_note"),
])
def test_sto_refuses_bad_input_naming_the_parameter(tmp_path, kwargs, name):
    with pytest.raises(ValueError, match=name):
        write_sto(tmp_path / "x.sto", comm=MPI.COMM_SELF, **kwargs)


# ---------------------------------------------------------------------------------------- skin pressure
def ring(radius: float, n: int = 72) -> np.ndarray:
    """n points on the circle x = 0 of the given radius [m] around the x axis."""
    phi = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return np.column_stack([np.zeros(n), radius * np.cos(phi), radius * np.sin(phi)])


def test_skin_pressure_of_a_ring_of_nodes():
    """A ring of nodes at 800 Pa around the equator x = 0 of a sphere, and nodes out of contact (0 Pa) at its
    poles: the skin near the ring reads 800 Pa, the skin far from it 0."""
    nodes = np.vstack([ring(0.1), [[0.1, 0.0, 0.0], [-0.1, 0.0, 0.0]]])
    pressure = np.concatenate([np.full(72, 800.0), [0.0, 0.0]])
    points, triangles, values = skin_pressure([SPHERE], 25, nodes, pressure, radius=0.015)   # a ring at x = 0
    assert points.shape == (25 * 50, 3) and triangles.shape[1] == 3 and values.shape == (len(points),)
    near = np.abs(points[:, 0]) < 0.005
    far = np.abs(points[:, 0]) > 0.03
    assert near.any() and far.any()
    assert np.allclose(values[near], 800.0)
    assert np.all(values[far] == 0.0)
    assert values.min() >= 0.0 and values.max() <= 800.0 + 1e-9


def test_idw_is_weighted_towards_the_nearer_node():
    nodes = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    values = idw_at(np.array([[0.25, 0.0, 0.0], [0.5, 0.0, 0.0], [5.0, 0.0, 0.0]]), nodes, np.array([1.0, 3.0]),
                    radius=2.0)
    assert 1.0 < values[0] < 2.0 and values[1] == pytest.approx(2.0, rel=1e-9) and values[2] == 0.0


@pytest.mark.parametrize("kwargs, name", [
    ({"radius": 0.0}, "radius"),
    ({"node_pressure": np.ones(3)}, "node_pressure"),
    ({"node_positions": np.zeros((2, 2)), "node_pressure": np.ones(2)}, "node_positions"),
])
def test_skin_pressure_refuses_bad_input_naming_the_parameter(kwargs, name):
    args = {"node_positions": ring(0.1, 4), "node_pressure": np.ones(4), "radius": 0.01} | kwargs
    with pytest.raises(ValueError, match=name):
        skin_pressure([SPHERE], 8, **args)


@pytest.mark.mpi
def test_gather_contact_concatenates_on_rank_0():
    comm = MPI.COMM_WORLD
    gathered = gather_contact(np.full((2, 3), comm.rank), np.full(2, float(comm.rank)), comm)
    if comm.rank == 0:
        positions, pressures = gathered
        assert positions.shape == (2 * comm.size, 3) and np.array_equal(pressures, np.repeat(np.arange(comm.size), 2))
    else:
        assert gathered is None


@pytest.mark.skipif(not HAS_PYVISTA, reason="pyvista is not installed")
def test_render_skin_pressure_writes_a_png(tmp_path):
    nodes = ring(0.1)
    points, triangles, values = skin_pressure([SPHERE], 32, nodes, np.full(len(nodes), 2000.0), radius=0.02)
    garment = (nodes, np.array([[i, (i + 1) % len(nodes), (i + 2) % len(nodes)] for i in range(0, 70, 2)]))
    path = tmp_path / "skin.png"
    render_skin_pressure(path, points, triangles, values / 1e3, "ring on a sphere: contact pressure", (0.0, 2.5),
                         garment_surface=garment, camera="iso")
    assert path.stat().st_size > 10_000
    with pytest.raises(ValueError, match="clim"):
        render_skin_pressure(tmp_path / "bad.png", points, triangles, values / 1e3, "t", (1.0, 1.0))
    assert MMHG_PER_KPA == pytest.approx(7.50, abs=0.005)


@pytest.mark.skipif(not HAS_PYVISTA, reason="pyvista is not installed")
def test_render_field_takes_a_colour_range_and_unit(tmp_path):
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    fio.render_field(tmp_path / "f.png", (points, np.array([[0, 1, 2], [0, 2, 3]])), np.arange(4.0), "a title",
                     clim=(0.0, 5.0), scalar_bar_title="value [Pa]")
    assert (tmp_path / "f.png").stat().st_size > 5_000
    with pytest.raises(ValueError, match="camera"):
        fio.render_field(tmp_path / "g.png", (points, np.array([[0, 1, 2]])), np.arange(4.0), "t", camera="top")


# ---------------------------------------------------------------------------------------- progress and summary
def test_progress_prints_no_nan_and_reports_phases():
    clock = fio.Progress()
    lines = [clock(0.0), clock(0.5), clock(float("nan")), clock(0.0, "donning"), clock(0.25, "donning"),
             clock(0.1, "motion")]
    assert not any("nan" in line.lower() for line in lines), lines
    assert "estimating" in lines[0] and re.search(r"about +[\d.]+ s left", lines[1])
    assert lines[3].startswith("[donning  0.0%") and "estimating" in lines[3] and "s left" in lines[4]
    assert lines[5].startswith("[motion 10.0%") and "estimating" in lines[5]


def test_output_folder_add_survives_finish(tmp_path):
    folder = fio.OutputFolder(tmp_path, "sha", MPI.COMM_SELF)
    folder.add(peak_pressure_Pa=1200.0, peak_position_m=[0.1, 0.0, 0.04])
    folder.finish("completed")
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["peak_pressure_Pa"] == 1200.0 and summary["status"] == "completed"
