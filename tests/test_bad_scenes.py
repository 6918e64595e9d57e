"""Bad scene files through the command line, for every scene kind: exit code 2, one line on stderr that names the
offending key, no traceback, and nothing meshed (the mesh builders are replaced by a trap). The arm in a sleeve and
the compression sleeve are wear scenes (the sleeve on its quasi-static Newton route: tests/data/sleeve_quasistatic.toml;
the limb grown into a tube on the explicit engine); their older layouts (tests/data/sleeve_kind.toml,
tests/data/compression_kind.toml) are refused the same way with every moved key in the one line."""
import tomllib
from pathlib import Path

import pytest
from toml_text import dumps

from fabricfem import cli

ROOT = Path(__file__).resolve().parents[1]
SCENES = {"static": "scenes/rollup.toml", "dynamic": "scenes/cantilever_vibration.toml",
          "explicit": "scenes/corner_pinned.toml", "quasistatic": "tests/data/sleeve_quasistatic.toml",
          "compression": "scenes/compression_sleeve.toml", "wear": "scenes/sleeve.toml"}


def _scene(kind: str) -> dict:
    data = tomllib.loads((ROOT / SCENES[kind]).read_text())
    if kind == "compression":            # the limb grown into the tube on the explicit engine
        data.setdefault("route", {})["solver"] = "explicit"
    return data


def _set(section: str, **values):
    return lambda d: d.setdefault(section, {}).update(values)


def _first(section: str, **values):
    return lambda d: d[section][0].update(values)


BAD = [  # (scene kind, mutation, text the one-line error must contain)
    ("static", _set("fabric", E1=-5e6), "E1"),
    ("static", _set("fabric", E2=float("inf")), "fabric.E2"),
    ("static", _set("fabric", E1=float("nan")), "fabric.E1"),
    ("static", _set("fabric", nu12=0.9, E1=1e6, E2=3e6), "nu12"),
    ("static", _set("fabric", thickness=0.0), "thickness"),
    ("static", _set("fabric", G12=-1.0), "G12"),
    ("static", _set("fabric", thicknes=1e-3), "thicknes"),
    ("static", _set("mesh", lx=0.0), "mesh.lx"),
    ("static", _set("mesh", nx=0), "mesh.nx"),
    ("static", _set("mesh", ny=-2), "mesh.ny"),
    ("static", _set("mesh", type="disk"), "mesh.type"),
    ("static", _set("mesh", cell="hexagon"), "mesh.cell"),
    ("static", _set("mesh", nx=100000, ny=3000), "mesh"),
    ("static", _first("support", edge="shoulder"), "support[0].edge"),
    ("static", _first("support", u=[0, 0]), "support[0].u"),
    ("static", _first("load", value=[0.0, float("nan"), 0.0]), "load[0].value"),
    ("static", _first("load", value=[0.0, float("inf"), 0.0]), "load[0].value"),
    ("static", _first("load", edge="tip"), "load[0].edge"),
    ("static", _set("output", probe=[float("nan"), 0.0, 0.0]), "output.probe"),
    ("static", _set("output", dir="/proc/fabricfem-cannot-write-here"), "output.dir"),
    ("static", lambda d: d.update(solverr={}), "solverr"),
    ("static", lambda d: d["solver"].pop("targets"), "targets"),
    ("static", _set("scene", kind="dynamic"), "scene.kind"),
    ("dynamic", _set("dynamics", dt=-1.0), "dynamics.dt"),
    ("dynamic", _set("dynamics", end_time=0.0), "dynamics.end_time"),
    ("dynamic", _set("dynamics", integrator="leapfrog"), "dynamics.integrator"),
    ("dynamic", _set("fabric", density=0.0), "fabric.density"),
    ("dynamic", _set("dynamics", rayleigh=[-1.0, 0.0]), "dynamics.rayleigh"),
    ("dynamic", lambda d: d["dynamics"]["monitors"][0].pop("name"), "name"),
    ("explicit", _set("dynamics", dt="auto", dt_fraction=1.5), "dynamics.dt_fraction"),
    ("explicit", _set("dynamics", dt=1.0, end_time=10.0), "dynamics.dt"),
    ("quasistatic", _set("fabric", E1=-1.2e6), "E1 must be"),
    ("quasistatic", _set("fabric", E2=2.0e6), "fabric.E2"),
    ("quasistatic", _set("contact", friction=-0.1), "contact.friction"),
    ("quasistatic", _set("contact", method="mortar"), "contact.method"),
    ("quasistatic", _set("route", solver="walking"), "route.solver"),
    ("quasistatic", _set("route", rotary_inertia_scale=0.5), "route.rotary_inertia_scale"),
    ("quasistatic", _set("route", mass_damping=-1.0), "route.mass_damping"),
    ("quasistatic", _set("route", damping_frame="body"), "route.damping_frame"),   # the explicit engine's only
    ("quasistatic", _set("motion", final_angle=200.0), "motion.final_angle"),
    ("quasistatic", _set("motion", angular_velocity=0.0), "motion.angular_velocity"),
    ("quasistatic", _set("motion", angle_steps=0), "motion.angle_steps"),
    ("quasistatic", _set("motion", solver="implicit"), "motion: unknown key 'solver'"),    # a [route] key
    ("quasistatic", _set("garment", n_around=0), "garment.n_around"),
    ("quasistatic", _set("body", upper_arm_girth=0.5), "upper_arm_girth"),
    ("wear", _set("garment", n_around=0), "garment.n_around"),
    ("wear", _set("garment", builder="knit"), "garment.builder"),
    ("wear", _set("motion", type="dance"), "motion.type"),
    ("wear", _set("body", blend_width=-1.0), "body.blend_width"),
    ("wear", _set("body", blend_width=0.0), "body.blend_width"),
    ("wear", _set("route", damping_frame="arm"), "route.damping_frame"),
    ("wear", _set("motion", final_angle=200.0), "final_angle"),
    ("wear", lambda d: (d["route"].update(solver="quasistatic", mass_damping=-1.0),     # the Newton route's
                        d["contact"].update(method="penalty")), "route.mass_damping"),      # contact method
    ("wear", _set("fabric", density=0.0), "density"),
    # the limb's checks on the explicit engine (the quasi-static route's symmetry checks, limb centre on the tube's
    # axis and n_around a multiple of 4, went with that route; donning.steps became donning.time)
    ("compression", _set("body", radii=[0.32, -0.04, 0.036]), "body.radii"),
    ("compression", _set("donning", time=0.0), "donning.time"),
    ("compression", _set("donning", start=1.5), "donning.start"),
    ("compression", _set("donning", method="knit"), "donning.method"),
    ("static", _set("accuracy", quantity="probe_ux_m", target=0.0), "accuracy.target"),
    ("static", _set("accuracy", quantity="probe_ux_m", target=1.0), "accuracy.target"),
    ("static", _set("accuracy", quantity="tip_angle", target=0.02), "accuracy.quantity"),
    ("explicit", _set("accuracy", quantity="corner_uy", target=0.02), "accuracy.quantity"),
    ("compression", _set("accuracy", quantity="x", target=0.02), "accuracy"),
    ("static", _set("accuracy", quantity="probe_ux_m", membrane="yes"), "accuracy.membrane"),
    ("static", _first("support", edge="al"), "did you mean 'all'"),
]


def _run_cli(path: Path, capsys) -> tuple[int, list[str]]:
    code = cli.main(["run", str(path)])
    err = capsys.readouterr().err
    return code, [line for line in err.splitlines() if line.strip()]


def test_enough_bad_scenes_of_every_kind():
    assert len(BAD) >= 40 and {kind for kind, _, _ in BAD} >= {"static", "dynamic", "explicit", "quasistatic",
                                                                "compression", "wear"}


@pytest.mark.parametrize("kind, mutate, key", BAD, ids=[f"{k}-{key}-{i}" for i, (k, _, key) in enumerate(BAD)])
def test_bad_scene_one_line_exit_2_nothing_meshed(kind, mutate, key, tmp_path, capsys, no_meshing):
    data = _scene(kind)
    data.setdefault("output", {})
    data["output"].setdefault("dir", str(tmp_path / "out"))
    mutate(data)
    path = tmp_path / "bad.toml"
    path.write_text(dumps(data))
    code, lines = _run_cli(path, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert _names(lines[0], key) and "Traceback" not in lines[0], lines[0]


def _names(line: str, key: str) -> bool:
    """The line names `key`: as written, or a dotted "section.key" in the scene contract's form "section: key ..."
    (fabricfem.scenes.contract: a section's dataclass refusing a value, its message starting with the key)."""
    section, dot, name = key.partition(".")
    return key in line or bool(dot and name and f"{section}: {name} " in line)


@pytest.mark.parametrize("name, layout, moved", [
    ("sleeve_kind.toml", "sleeve", ("scene.kind = 'sleeve' -> scene.kind = \"wear\"", "mesh.length -> garment.length",
                                    "mesh.type -> garment.builder", "body.type -> body.type = \"arm\"",
                                    "mesh.cell -> (dropped", "output.render_angles -> output.render_at")),
    ("compression_kind.toml", "compression", ("scene.kind = 'compression' -> scene.kind = \"wear\"",
                                              "mesh.n_around -> garment.n_around", "limb.center -> body.center",
                                              "limb.radii -> body.radii", "donning.steps -> donning.time",
                                              "motion.type = \"still\"")),
])
def test_older_layout_exits_2_listing_the_moved_keys(name, layout, moved, tmp_path, capsys, no_meshing):
    """The older sleeve and compression layouts (tests/data): exit 2, one line saying the layout is no longer read
    and listing its moved keys, nothing meshed."""
    data = tomllib.loads((ROOT / "tests" / "data" / name).read_text())
    data["output"]["dir"] = str(tmp_path / "out")
    path = tmp_path / name
    path.write_text(dumps(data))
    code, lines = _run_cli(path, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert f"the older {layout} layout is no longer read" in lines[0] and "Traceback" not in lines[0], lines[0]
    for key in moved:
        assert key in lines[0], key


@pytest.mark.parametrize("content, text", [(b"\xff\xfe\x00[mesh]\x00\x81", "UTF-8"),
                                           (bytes(range(256)), "UTF-8"),
                                           (b"[mesh\ntype = ", "not valid TOML")])
def test_binary_or_broken_scene_file(content, text, tmp_path, capsys, no_meshing):
    path = tmp_path / "bad.toml"
    path.write_bytes(content)
    code, lines = _run_cli(path, capsys)
    assert code == 2 and len(lines) == 1 and text in lines[0], lines


def test_debug_shows_the_traceback(tmp_path):
    data = _scene("static")
    data["fabric"]["E1"] = -5e6
    path = tmp_path / "bad.toml"
    path.write_text(dumps(data))
    with pytest.raises(Exception, match="E1"):
        cli.main(["--debug", "run", str(path)])
