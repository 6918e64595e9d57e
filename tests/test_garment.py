"""The garment engine (fabricfem.wear.garment, fabricfem.contact.seams) and wear scenes (fabricfem.scenes.wear):
sewing closes the seams and conserves momentum; the shipped wear scenes are valid; wear scenes refuse bad input
before meshing."""
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from toml_text import refused_in_one_line

from fabricfem.body.pose import Body, Segment
from fabricfem.contact.seams import SeamSpec
from fabricfem.materials import Fabric
from fabricfem.meshes.pattern import Panel, Pattern, Stitch
from fabricfem.meshes.pattern_mesh import mesh_pattern
from fabricfem.scenes import build as scene_build
from fabricfem.wear.garment import ExplicitSettings, Timeline, build_garment_run

ROOT = Path(__file__).resolve().parents[1]
COTTON = Fabric(E1=1.2e6, E2=1.2e6, G12=1e5, nu12=0.0, thickness=1e-3, density=436.0)


class Still:
    names = ("p", "d", "m")
    time_range = (0.0, 0.0)

    def positions(self, t):
        return {"p": np.array([10.0, 0.0, 0.0]), "d": np.array([11.0, 0.0, 0.0]), "m": np.array([10.5, 1.0, 0.0])}


def far_body() -> Body:
    """One small ellipsoid 10 m away: the garment never touches it."""
    return Body([Segment("far", "p", "d", "m", (0.5, 0.1, 0.1))], Still())


def test_sewing_closes_the_seam_and_conserves_momentum():
    """Two flat 0.1 m squares 5 cm apart in z = 0, one stitch between facing edges, sewn in 0.05 s with nothing
    else acting (no gravity, no contact): after the sewing the stitched nodes coincide (to round-off), the
    garment's centre of mass has not moved (no external force: conservation of momentum, to round-off of the
    mass-weighted sums, 1e-12 m) and it is at rest up to the damped sewing motion."""
    square = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]])
    pattern = Pattern({"left": Panel("left", square, translation=(0.0, 0.0, 0.0)),
                       "right": Panel("right", square, translation=(0.15, 0.0, 0.0))},
                      [Stitch(("left", 1), ("right", 3))])
    garment = mesh_pattern(pattern, 0.05, comm=MPI.COMM_SELF)
    seams = [SeamSpec(s.name, s.points_a, s.panel_tag_a, s.points_b, s.panel_tag_b, float(np.mean(s.lengths)))
             for s in garment.stitches]
    run = build_garment_run("sewing", garment.fabric, COTTON, far_body(), seams=seams,
                            timeline=Timeline(record_time=0.01, sewing_time=0.05, settle_time=0.05, motion_time=0.0),
                            settings=ExplicitSettings(gravity=None), measure_strain=False)
    nodes = run.contact.nodes
    centre0 = (nodes.area[:, None] * nodes.reference).sum(axis=0) / nodes.area.sum()
    history = run.run()
    d = run.integrator.d.getArray(readonly=True)
    x = nodes.reference + d[nodes.dofs]
    centre = (nodes.area[:, None] * x).sum(axis=0) / nodes.area.sum()
    assert history.steps[0].seam_gap > 0.04                      # open while sewing ...
    assert history.steps[-1].seam_gap < 1e-12                   # ... closed after it
    np.testing.assert_allclose(centre, centre0, atol=1e-12)
    run.destroy()


# ------------------------------------------------------------------------------ refusals before meshing
def _trousers() -> dict:
    return tomllib.loads((ROOT / "scenes" / "trousers_standing.toml").read_text())


BOW_TIE = """stitches = []
[panels.front]
vertices = [[0.0, 0.0], [0.3, 0.3], [0.3, 0.0], [0.0, 0.3]]
"""
MISSING_PANEL = """stitches = [["front", 1, "back", 3]]
[panels.front]
vertices = [[0.0, 0.0], [0.3, 0.0], [0.3, 0.6], [0.0, 0.6]]
"""
EDGE_OUT_OF_RANGE = """stitches = [["front", 7, "back", 3]]
[panels.front]
vertices = [[0.0, 0.0], [0.3, 0.0], [0.3, 0.6], [0.0, 0.6]]
[panels.back]
vertices = [[0.0, 0.0], [0.3, 0.0], [0.3, 0.6], [0.0, 0.6]]
"""
MARKERS = ["waist", "crotch", "chest", "trunk_marker", "pelvis_marker"] + [
    f"{p}_{s}" for s in "lr" for p in ("hip", "knee", "ankle", "toe", "thigh_marker", "shank_marker", "foot_marker")]


def _marker_csv(times, drop: str | None = None, nan_at: tuple[str, int] | None = None) -> str:
    names = [m for m in MARKERS if m != drop]
    lines = ["time," + ",".join(f"{m}_x,{m}_y,{m}_z" for m in names)]
    for k, t in enumerate(times):
        values = []
        for j, m in enumerate(names):
            v = [0.1 * j, 0.01 * j + 0.001 * k, 1.0]
            if nan_at == (m, k):
                v[0] = math.nan
            values += [f"{c}" for c in v]
        lines.append(f"{t}," + ",".join(values))
    return "\n".join(lines) + "\n"


WEAR_BAD = [  # (files next to the scene, mutation of the trousers scene, text the one-line error must contain)
    ({"p.toml": MISSING_PANEL}, lambda d: d["garment"].update(pattern="p.toml"), "'back'"),
    ({"p.toml": EDGE_OUT_OF_RANGE}, lambda d: d["garment"].update(pattern="p.toml"), "7"),
    ({"p.toml": BOW_TIE}, lambda d: d["garment"].update(pattern="p.toml"), "intersect"),
    ({}, lambda d: d["garment"].update(pattern="no_such_pattern"), "garment.pattern"),
    ({"m.csv": _marker_csv([0.0, 0.1, 0.2], drop="knee_r")},
     lambda d: d.update(motion={"type": "file", "path": "m.csv"}), "knee_r"),
    ({"m.csv": _marker_csv([0.0, 0.2, 0.1])}, lambda d: d.update(motion={"type": "file", "path": "m.csv"}),
     "frame"),
    ({"m.csv": _marker_csv([0.0, 0.1, 0.2], nan_at=("hip_l", 1))},
     lambda d: d.update(motion={"type": "file", "path": "m.csv"}), "hip_l"),
    ({}, lambda d: d["torque"][0].update(joint="hip_l"), "hip_l"),
    ({}, lambda d: d["torque"][0].update(segments=["tail"]), "tail"),
    ({}, lambda d: d["torque"][0].update(segments=[]), "torque[0].segments"),
    ({}, lambda d: d["body"].update(type="octopus"), "body.type"),
    ({}, lambda d: d["body"].update(thigh_length=-0.4), "thigh_length"),
    ({}, lambda d: d["garment"].update(sewing_tme=0.1), "sewing_tme"),
    ({}, lambda d: d["donning"].update(remove=["tail"]), "donning.remove"),
    ({}, lambda d: d["fabric"].update(catalogue="no-such-fabric"), "fabric.catalogue"),
    ({}, lambda d: d.update(motion={"type": "walking", "cycle_time": 0.0}), "cycle_time"),
    ({}, lambda d: d.update(motion={"type": "obstacle_walk", "obstacle_height": 1.5}), "obstacle_height"),
    ({}, lambda d: d["fabric"].update(thickness=0.0), "thickness"),
    ({}, lambda d: d["donning"].update(pull_edges=["Lfront.9"], pull_path=[[0, 0, 0], [0, 0, 0.1]], pull_time=0.1),
     "donning.pull_edges"),
    ({}, lambda d: d["donning"].update(pull_edges=["Lfront.4"]), "donning.pull_path"),
]


@pytest.mark.parametrize("files, mutate, key", WEAR_BAD, ids=[f"{i}-{k}" for i, (_, _, k) in enumerate(WEAR_BAD)])
def test_bad_wear_scene_refused_before_meshing(files, mutate, key, tmp_path, capsys, no_meshing):
    data = _trousers()
    data["output"] = {"dir": str(tmp_path / "out")}
    mutate(data)
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    refused_in_one_line(tmp_path / "bad.toml", data, key, capsys)


def test_shipped_wear_scenes_are_valid():
    for name in ("sleeve.toml", "trousers_standing.toml", "compression_sleeve.toml"):
        scene = scene_build.load(ROOT / "scenes" / name)
        assert scene.kind == "wear", name


@pytest.mark.mpi
def test_sewn_sleeve_histories_same_on_one_and_two_ranks():
    """A sleeve sewn from two flat panels (0.15 and 0.227 m wide, 0.5 m long, rolled onto the 6 cm cylinder
    around the arm, two seams along the arm) on the flexing arm (settle 0.1 s, 4 degrees, mu = 0.1): the elbow
    torque, peak pressure and seam-gap histories on COMM_WORLD (2 ranks under mpirun) equal the serial ones
    (COMM_SELF) within 1e-6 relative to their largest values (the acceptance bound). The ranks differ only in the
    summation order of the assembly and of the reductions (round-off).
    Measured: a sewing run whose panels are drawn across the body in 0.06 s (the trousers at h = 8 cm) is
    chaotic: 2 ranks and 1 rank differ by 3e-12 after the first record and by O(1) after the collisions
    (docs/findings/2026-11-25-garment-engine.md); the settled and flexing garment is not."""
    from fabricfem.body.arm import DEFAULT_ARM, default_arm, elbow_flexion
    from fabricfem.meshes.pattern_mesh import wrap_on_cylinder
    from fabricfem.wear.garment import TorqueSpec
    radius, widths = 0.06, (0.15, 2 * math.pi * 0.06 - 0.15)

    def history(comm):
        panels = {n: Panel(n, np.array([[0.0, 0.0], [w, 0.0], [w, 0.5], [0.0, 0.5]]), grain=(0.0, 1.0))
                  for n, w in zip("ab", widths)}
        pattern = Pattern(panels, [Stitch(("a", 1), ("b", 3)), Stitch(("b", 1), ("a", 3))])
        placements = {n: wrap_on_cylinder((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), radius, zero_direction=(0.0, 1.0, 0.0),
                                          angle0=a) for n, a in (("a", 0.0), ("b", widths[0] / radius))}
        garment = mesh_pattern(pattern, 0.06, placements=placements, comm=comm)
        seams = [SeamSpec(s.name, s.points_a, s.panel_tag_a, s.points_b, s.panel_tag_b, float(np.mean(s.lengths)))
                 for s in garment.stitches]
        omega = math.radians(45.0)
        body = default_arm(elbow_flexion(DEFAULT_ARM, angular_velocity=omega, final_angle=math.radians(4.0)))
        hold = [t for t in garment.fabric.tags if t.endswith(".0")]       # the shoulder ends (panel edge 0: y = 0)
        run = build_garment_run("sewn sleeve", garment.fabric, COTTON, body, seams=seams, holds=hold,
                                torques=[TorqueSpec("elbow", "elbow", (0.0, 0.0, 1.0), ("forearm",))],
                                timeline=Timeline(record_time=math.radians(1.0) / omega, settle_time=0.1),
                                settings=ExplicitSettings(gravity=(0.0, -9.81, 0.0)), friction=0.1,
                                measure_strain=False)
        h = run.run()
        run.destroy()
        return np.array([[s.torques["elbow"], s.peak_pressure, s.seam_gap, s.contact_force] for s in h.steps])

    parallel, serial = history(MPI.COMM_WORLD), history(MPI.COMM_SELF)
    scale = np.max(np.abs(serial), axis=0)
    assert serial[-1, 0] > 0.0 and scale[1] > 0.0                     # the forearm touches the sleeve
    assert np.all(np.abs(parallel - serial) <= 1e-6 * scale + 1e-15), ((parallel - serial) / scale, serial)


def test_belt_pulls_a_circular_waistband_with_its_tension():
    """A belt of tension T = 3 N along the two end edges of the sewn tube (a circle of radius R0 drawn through
    both panels' node chains): every node of the loop gets the force of a polygonal string under tension,
    T (sin(g+ / 2) + sin(g- / 2)) towards the axis and T (cos(g+ / 2) - cos(g- / 2)) along the circle, g- and g+
    the angles to its neighbours (closed form; at the seams the two coincident end nodes share it), to 1e-9."""
    from types import SimpleNamespace

    from fabricfem.contact.handles import Belt
    from fabricfem.shell import ShellModel
    from fabricfem.verify.garment import FABRIC, sewn_tube
    garment, r0 = sewn_tube(comm=MPI.COMM_SELF)
    model = ShellModel(garment.fabric, FABRIC)
    edges = [(f"{p}.0", garment.panel_tags[p], garment.edge_points(p, 0)) for p in "ab"]
    belt = Belt(model, edges, tension=3.0, start=0.0, ramp=0.0)
    d, rhs = model.create_vector(), model.create_vector()
    belt.forces(SimpleNamespace(d=d), 0.0, rhs)
    f = rhs.getArray()[belt.nodes.rows]
    x = belt.nodes.reference
    angle = np.round(np.arctan2(x[:, 2], x[:, 1]) % (2 * np.pi), 12)
    theta = np.unique(angle)
    after = np.diff(np.concatenate([theta, [theta[0] + 2 * np.pi]]))        # g+ of each distinct angle
    before = np.roll(after, 1)                                               # g-
    radial = np.column_stack([np.zeros(len(x)), np.cos(angle), np.sin(angle)])
    tangent = np.column_stack([np.zeros(len(x)), -np.sin(angle), np.cos(angle)])
    k = np.searchsorted(theta, angle)
    inward = np.bincount(k, -np.sum(f * radial, axis=1))        # the two seam nodes of one angle summed
    along = np.bincount(k, np.sum(f * tangent, axis=1))
    np.testing.assert_allclose(inward, 3.0 * (np.sin(after / 2) + np.sin(before / 2)), rtol=1e-9)
    np.testing.assert_allclose(along, 3.0 * (np.cos(after / 2) - np.cos(before / 2)), atol=1e-9)
    assert np.max(np.abs(f[:, 0])) < 1e-12                                   # nothing along the axis


def test_grip_moves_an_edge_along_its_path_and_lets_go():
    """A flat 0.1 m square with its top edge gripped and pulled 5 cm along z over 0.05 s (no gravity, no contact):
    at the end of the pull the gripped nodes have moved by the path's offset along the path (the forward-increment
    constraint, to round-off: 1e-12 m) and are free across it; after it the grip exerts no force."""
    from fabricfem.contact.handles import EdgeGrip
    square = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]])
    garment = mesh_pattern(Pattern({"p": Panel("p", square)}, []), 0.05, comm=MPI.COMM_SELF)
    top = garment.edge_points("p", 2)
    grip = []
    run = build_garment_run("grip", garment.fabric, COTTON, far_body(),
                            timeline=Timeline(record_time=0.01, pull_time=0.05, settle_time=0.02, motion_time=0.0),
                            settings=ExplicitSettings(gravity=None), measure_strain=False,
                            handles=[lambda model: grip.append(EdgeGrip(model, [("p.2", garment.panel_tags["p"], top)],
                                                                        [[0, 0, 0], [0, 0, 0.05]], 0.0, 0.05))
                                     or grip[0]])
    positions = []
    run.run(on_step=lambda s: positions.append(grip[0].nodes.positions(run.integrator.d.getArray(readonly=True))))
    moved = positions[4] - grip[0].nodes.gather(grip[0].nodes.reference)      # after 0.05 s (5 records)
    np.testing.assert_allclose(moved[:, 2], 0.05, atol=1e-12)
    assert np.all(grip[0].force == 0.0)
    run.destroy()


def test_a_motion_file_drives_the_scene_body(tmp_path):
    """[motion] type = "file": a TRC written from the standing lower body raised by 2 cm at 0.1 s (mm, Z-up) is
    read, mapped onto the body's joints by name and poses it: the pelvis centre is where the analytic pose puts it
    (1e-6 m, the TRC's printed precision in mm)."""
    from fabricfem.body import JointTrajectory
    from fabricfem.body.lower_body import standing
    from fabricfem.body.mocap import write_trc
    from fabricfem.scenes import wear
    from fabricfem.scenes.contract import parse
    base = standing(duration=0.2)
    times = np.linspace(0.0, 0.2, 21)
    lift = np.where(times >= 0.1, 0.02, 0.0)
    points = {n: np.array([base.positions(t)[n] + [0.0, 0.0, h] for t, h in zip(times, lift)]) for n in base.names}
    write_trc(tmp_path / "lift.trc", JointTrajectory(times, points), units="mm")
    data = _trousers()
    data["motion"] = {"type": "file", "path": "lift.trc", "record_time": 0.02}
    plan = wear.plan(parse(data, "wear"), COTTON, tmp_path / "scene.toml")     # the parsed scene (scenes.contract)
    analytic = Body(list(plan.body.segments.values()), JointTrajectory(times, points))
    for t in (0.05, 0.15):
        got, want = plan.body.pose(t)["pelvis"], analytic.pose(t)["pelvis"]
        np.testing.assert_allclose(got.center, want.center, atol=1e-6)
