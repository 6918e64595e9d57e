"""The plots of the scene commands as a user reads them: a sweep's plot has a title, a user
quantity with its unit against the varied key with its unit, and sweep.csv holds the probe once; a static scene's
final.png has a colour bar of the displacement; a dynamic scene's monitor panels carry units. (The wear run's
torque plot: tests/test_wear_run_files.py.)"""
import csv
import json
import tomllib
from pathlib import Path

import pytest
from mpi4py import MPI
from test_sweep import TINY

from fabricfem import io
from fabricfem import scenes as scene_module
from fabricfem.scenes import sweep
from fabricfem.scenes.build import validate
from fabricfem.scenes.run import run_scene

ROOT = Path(__file__).resolve().parents[1]


def _drape(folder: Path, render: bool = False) -> scene_module.Scene:
    """scenes/drape.toml (the strip drooping under its weight, probe at the free corner) on 4 x 2 cells."""
    data = tomllib.loads((ROOT / "scenes" / "drape.toml").read_text())
    data["mesh"].update(nx=4, ny=2)
    data["output"].update(dir=str(folder), render=render)
    return validate(data)


def _capture(monkeypatch, module, name: str) -> list:
    """Wrap module.name so that each call's (arguments, keywords, result) is kept in the returned list."""
    calls, real = [], getattr(module, name)

    def keep(*args, **kwargs):
        calls.append((args, kwargs, real(*args, **kwargs)))
        return calls[-1][2]
    monkeypatch.setattr(module, name, keep)
    return calls


def test_sweep_plots_a_user_quantity_with_units_and_holds_the_probe_once(tmp_path, monkeypatch):
    """A sweep of the drape over fabric.E1: sweep.csv has probe_ux_m, probe_uy_m, probe_uz_m and no flattened
    probe_displacement_m_<i>; the default plot quantity is the probe's largest component, probe_uz_m (the strip
    droops), drawn against "fabric.E1 [Pa]" as "probe_uz_m [m]" under a title naming the scene."""
    plots = _capture(monkeypatch, sweep, "plot_sweep")
    rows = sweep.run_sweep(_drape(tmp_path / "base"), [("fabric.E1", [1e7, 2e7])], tmp_path, comm=MPI.COMM_SELF)
    assert all(row["status"] == "completed" for row in rows)
    header = next(csv.reader(open(tmp_path / "sweep.csv")))
    assert {"probe_ux_m", "probe_uy_m", "probe_uz_m"} <= set(header)
    assert not [name for name in header if name.startswith("probe_displacement")]
    args, _, figure = plots[0]
    assert args[3] == "probe_uz_m"
    ax = figure.axes[0]
    assert ax.get_xlabel() == "fabric.E1 [Pa]" and ax.get_ylabel() == "probe_uz_m [m]"
    assert "cantilever-drape" in ax.get_title() and "probe_uz_m" in ax.get_title()


@pytest.mark.parametrize("key, quantity, labels", [
    ("dynamics.dt_fraction", "final_corner_uz", ("dynamics.dt_fraction", "final_corner_uz [m]")),
    ("fabric.density", "kinetic_J", ("fabric.density [kg/m^3]", "kinetic_J [J]")),
    ("fabric.thickness", "max_strain_final", ("fabric.thickness [m]", "max_strain_final [-]"))])
def test_sweep_axis_labels_carry_the_units(key, quantity, labels):
    """The units of the axes: a varied key's from the scene reference (none where it has none), a quantity's from
    its name's suffix, a dynamic monitor's from its field, a strain's [-]."""
    base = validate(json.loads(json.dumps(TINY)))
    assert (sweep.key_label(base, key), sweep.quantity_label(base, quantity)) == labels


def test_static_final_png_has_a_colour_bar_of_the_displacement(tmp_path, monkeypatch):
    """final.png of the drape: the deformed strip coloured by |u| [m] with its colour bar (io.render_field) over the
    undeformed one, a title naming what is shown."""
    renders = _capture(monkeypatch, io, "render_field")
    outcome = run_scene(_drape(tmp_path, render=True), MPI.COMM_SELF)
    assert outcome.exit_code == 0 and (tmp_path / "final.png").is_file()
    (args, kwargs, _), = renders
    assert args[0] == tmp_path / "final.png"
    assert kwargs["scalar_bar_title"] == "displacement |u| [m]" and len(kwargs["bodies"]) == 1
    assert "undeformed" in args[3]


def test_dynamic_plot_panels_carry_units(tmp_path, monkeypatch):
    """The PNG of a dynamic scene: each monitor's panel labelled with its unit (corner_uz: a displacement [m]),
    then the energies [J] and the strain [-]; time [s] below."""
    plots = _capture(monkeypatch, io, "plot_time_series")
    data = json.loads(json.dumps(TINY))
    data["output"]["dir"] = str(tmp_path)
    run_scene(validate(data), MPI.COMM_SELF)
    figure = plots[0][2]
    assert [ax.get_ylabel() for ax in figure.axes] == ["corner_uz [m]", "energy [J]", "max strain [-]"]
    assert figure.axes[-1].get_xlabel() == "time [s]"
