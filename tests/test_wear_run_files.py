"""The files of a wear run as a user reads them: torque.sto with the motion's own time
and OpenSim coordinate names (read by a plain reader, and by OpenSim's own Storage and TimeSeriesTable when the
`opensim` package is installed), torque.png against time with the phases and the summary's records marked, and
`--resume` of a completed run. One short sleeve run (6 degrees of flexion after 0.4 s of settling) serves them."""
import csv
import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from shipped_scenes import scene_data
from toml_text import dumps

from fabricfem import scenes as scene_module
from fabricfem.launch import child_environment
from fabricfem.scenes.run import run_scene
from fabricfem.wear import recorder as recorder_module
from fabricfem.wear.garment import TorqueSpec

ROOT = Path(__file__).resolve().parents[1]
OMEGA = 45.0          # deg/s: the sleeve scene's angular velocity
SETTLE = 0.4          # s: its settling before the flexion
HAS_OPENSIM = importlib.util.find_spec("opensim") is not None


@pytest.fixture(scope="module")
def sleeve_run(tmp_path_factory):
    """(output folder, scene file, history, the Figure of torque.png) of scenes/sleeve.toml flexed to 6 degrees
    (records every 3 degrees, no renders)."""
    folder = tmp_path_factory.mktemp("sleeve")
    data = scene_data("sleeve.toml")
    data["motion"].update(final_angle=6.0, output_angle_step=3.0)
    data["output"] = {"dir": str(folder / "out"), "render": False}
    path = folder / "sleeve.toml"
    path.write_text(dumps(data))
    figures = []
    plot = getattr(recorder_module, "plot_wear_history", None)

    def keep(*args, **kwargs):
        figures.append(plot(*args, **kwargs))
        return figures[-1]
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(recorder_module, "plot_wear_history", keep, raising=False)
        outcome = run_scene(scene_module.load(path))
    assert outcome.exit_code == 0, outcome.status
    return folder / "out", path, outcome.result, figures[0] if figures else None


def _plain_sto(path: Path) -> tuple[dict, list[str], np.ndarray]:
    """({header key: value}, column labels, data) of a storage file read line by line."""
    lines = path.read_text().splitlines()
    end = lines.index("endheader")
    keys = dict(line.split("=", 1) for line in lines[1:end] if "=" in line)
    labels = lines[end + 1].split("\t")
    return keys, labels, np.array([[float(v) for v in line.split("\t")] for line in lines[end + 2:]])


def test_sto_has_the_motion_time_and_opensim_names(sleeve_run):
    """torque.sto (plain reader): time is the body time of torque.csv; motion_time is the flexion's own clock
    (angle = 45 deg/s x motion_time on the motion's records, body time - 0.4 s of settling); beside the monitors'
    columns, elbow_flex_r_moment is the garment's moment about the elbow's flexion axis, positive in flexion: minus
    the resisting torque of the forearm monitor (the first one about the elbow; no duplicate column)."""
    out, _, history, _ = sleeve_run
    keys, labels, data = _plain_sto(out / "torque.sto")
    assert labels == ["time", "motion_time", "elbow_moment", "elbow_both_segments_moment", "elbow_flex_r_moment"]
    assert keys["nColumns"] == str(len(labels)) and keys["nRows"] == str(len(data)) == str(len(history.steps))
    rows = list(csv.DictReader(open(out / "torque.csv")))
    column = dict(zip(labels, data.T))
    np.testing.assert_allclose(column["time"], [float(r["time_s"]) for r in rows], rtol=1e-9)
    np.testing.assert_allclose(column["motion_time"], column["time"] - SETTLE, atol=1e-9)
    motion = np.array([r["phase"] == "motion" for r in rows])
    np.testing.assert_allclose(OMEGA * column["motion_time"][motion],
                               [float(r["axis"]) for r, m in zip(rows, motion) if m], atol=1e-6)
    np.testing.assert_allclose(column["elbow_moment"], [float(r["elbow_torque_Nm"]) for r in rows], rtol=1e-9)
    np.testing.assert_allclose(column["elbow_flex_r_moment"], -column["elbow_moment"], rtol=1e-12)


@pytest.mark.skipif(not HAS_OPENSIM, reason="needs the optional opensim package (pip install --no-deps opensim; "
                                            "scripts/bootstrap.sh tries it)")
def test_opensim_reads_the_sto(sleeve_run, tmp_path, monkeypatch):
    """OpenSim's own readers: Storage gets every row and column (time first), TimeSeriesTable the body times as
    its independent column and the same values under the OpenSim coordinate's name."""
    monkeypatch.chdir(tmp_path)      # OpenSim writes opensim.log into the working folder
    import opensim
    out, _, history, _ = sleeve_run
    _, labels, data = _plain_sto(out / "torque.sto")
    storage = opensim.Storage(str(out / "torque.sto"))
    names = storage.getColumnLabels()
    assert storage.getSize() == len(history.steps) and [names.get(i) for i in range(names.getSize())] == labels
    table = opensim.TimeSeriesTable(str(out / "torque.sto"))
    assert list(table.getColumnLabels()) == labels[1:]
    np.testing.assert_allclose(list(table.getIndependentColumn()), data[:, 0], rtol=1e-12)
    np.testing.assert_allclose(table.getDependentColumn("elbow_flex_r_moment").to_numpy(), data[:, -1], rtol=1e-12)


def test_opensim_names_follow_the_flexion_axes():
    """A monitor about a joint's flexion axis gets the OpenSim coordinate (the knee: +y, the lower body's frame),
    with the sign -1 when its axis points the other way; other axes and unknown joints get none; the first monitor
    of a coordinate takes it."""
    from fabricfem.wear.outputs import opensim_coordinates
    monitors = [TorqueSpec("knee", "knee_r", (0.0, 2.0, 0.0), ("shank_r",)),
                TorqueSpec("knee_x", "knee_r", (1.0, 0.0, 0.0), ("shank_r",)),
                TorqueSpec("knee_again", "knee_r", (0.0, 1.0, 0.0), ("shank_r", "foot_r")),
                TorqueSpec("left", "knee_l", (0.0, -1.0, 0.0), ("shank_l",)),
                TorqueSpec("neck", "neck", (0.0, 1.0, 0.0), ("head",))]
    assert opensim_coordinates(monitors) == {"knee": ("knee_angle_r", 1.0), "left": ("knee_angle_l", -1.0)}


def test_torque_plot_is_against_time_with_phases_and_summary_records(sleeve_run):
    """torque.png: the torques against the body time [s] (every record: the settling's too), the phases named,
    the motion's records (those of the summary's peaks) shaded and the peaks marked at their summary times, the
    elbow angle on a second axis."""
    _, _, history, figure = sleeve_run
    ax, twin = figure.axes[:2]
    assert ax.get_xlabel() == "body time [s]" and ax.get_ylabel() == "resisting torque [N m]"
    assert twin.get_ylabel() == "elbow angle [deg]"
    elbow = next(line for line in ax.get_lines() if line.get_label() == "elbow")
    np.testing.assert_allclose(elbow.get_xdata(), history.times)
    assert {"settle", "motion"} <= {text.get_text().strip() for text in ax.texts}
    spans = [patch for patch in ax.patches if "summary" in patch.get_label()]
    assert len(spans) == 1
    peak = next(line for line in ax.get_lines() if line.get_label().startswith("peak"))
    summary = history.summary()
    assert list(peak.get_xdata()) == pytest.approx([summary["torque_elbow"]["peak_time_s"],
                                                    summary["torque_elbow_both_segments"]["peak_time_s"]])
    assert min(peak.get_xdata()) >= SETTLE


def test_resume_of_a_completed_run_says_so_and_exits_0(sleeve_run):
    """`fabricfem run --resume` of a completed run: one line saying it is complete, exit 0, nothing rewritten."""
    out, path, _, _ = sleeve_run
    stamp = (out / "torque.csv").stat().st_mtime_ns
    done = subprocess.run([sys.executable, "-m", "fabricfem.cli", "run", str(path), "--resume"], capture_output=True,
                          text=True, env=child_environment())
    assert done.returncode == 0, done.stderr
    assert "is complete" in done.stdout and "nothing to resume" in done.stdout
    assert (out / "torque.csv").stat().st_mtime_ns == stamp


def test_a_frame_equal_to_an_earlier_one_is_not_rendered_twice():
    """The peak pressure at a requested coordinate gives the same frame twice: it is rendered once and copied
    (recorder._first_equal: same title and arrays); a frame that differs in one value is rendered."""
    from fabricfem.wear.recorder import _first_equal
    points, triangles = np.eye(3), np.array([[0, 1, 2]])
    values, garment = np.array([1.0, 2.0, 3.0]), (np.eye(3), np.array([[0, 1, 2]]))
    frame = ("pressure_57.00deg.png", "57 deg", (points, triangles, values), garment)
    peak = ("pressure_peak.png", "57 deg", (points.copy(), triangles.copy(), values.copy()), garment)
    other = ("pressure_38.00deg.png", "57 deg", (points, triangles, values + [0.0, 0.0, 1e-12]), garment)
    assert _first_equal([frame, other, peak]) == [0, 1, 0]
