"""The explicit engine's contact against a mesh skin against the blended ellipsoids: per-step cost on the sleeve.

The default sleeve (tube on the default arm, mu = 0.1, explicit engine) flexed to `angle` degrees on mesh
`n_around` x `n_along`, once on the blended-ellipsoid skin (the default, compiled contact) and once on a
`MeshSkin` of the same arm (`ellipsoid_skin`: marching cubes of the blended arm at `spacing`, rigged to the
segments; queried with the active set `margin` and the rigid segments' static trees, fabricfem.body.mesh_skin).
The cost of a step's contact is the body-contact hooks' time over the motion's steps (search, projection,
friction, posing and torque sums: `contact_s + pose_torque_s` of `fabricfem.wear.engine.step_breakdown`), the
median of `repeats` runs each; the ratio mesh / ellipsoids and the elbow torque of both at the final angle.

`--scene pants`: the trousers on the lower body of the Debian human's dimensions (scenes/trousers_human.toml in the
tests' quick mode: h = 0.08 m, the run cut 0.1 s into the walk), once on the blended ellipsoids (`[body] type =
"lower_body"` with `HUMAN_DIMENSIONS`), once on their triangulation (`ellipsoid_skin` at `--pants-spacing`, 0.012 m:
20072 triangles) and once on the Debian human's own skin (26756 triangles; another shape, so other contacts);
the same per-step cost of the hooks over the timed (motion) steps.

Run: `python -m fabricfem.benchmarks.mesh_skin_contact [--mesh 10x13] [--angle 10] [--repeats 3] [--scene pants]`.
"""
from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
import tomllib
from pathlib import Path

from mpi4py import MPI

from fabricfem.body.human import HUMAN_DIMENSIONS
from fabricfem.body.mesh_skin import MeshSkin, ellipsoid_skin
from fabricfem.scenes import build as scene_build
from fabricfem.scenes import wear
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.sleeve import flexion_timeline, similarity_factor, tube_flexion_run


def sleeve_skin(config: SleeveConfig, spacing: float, margin: float | None) -> MeshSkin:
    """A MeshSkin of the configuration's flexing arm: its blended ellipsoids triangulated at `spacing` [m]."""
    body, _, _ = flexion_timeline(config.motion, config.route, similarity_factor(config.fabric, config.route),
                                  config.arm)
    return ellipsoid_skin(body, spacing=spacing, margin=margin)


def contact_ms(config: SleeveConfig, skin: MeshSkin | None, comm=MPI.COMM_WORLD) -> dict:
    """One flexion: ms per motion step of the body contact hooks and of the whole step without the records'
    output, the steps, the final torque [N m] and the skin's searched points per step (mesh skin)."""
    run = tube_flexion_run("bench", config.fabric, config.tube, config.arm, config.motion, config.contact,
                           config.route, comm, skin=skin)
    start = time.perf_counter()
    history = run.run()
    wall = time.perf_counter() - start
    t = history.timings
    steps = max(int(t["steps"]), 1)
    searched = run.contact.skin.exact_points / max(run.integrator.step_count, 1) if skin is not None else 0.0
    out = {"contact_ms": 1e3 * (t["contact_s"] + t["pose_torque_s"]) / steps,
           "step_ms": 1e3 * (t["loop_s"] - t["output_s"]) / steps,
           "steps": steps, "torque": history.steps[-1].torques["elbow"], "wall_s": wall, "searched": searched,
           "max_penetration": max(s.max_penetration for s in history.steps)}
    run.destroy()
    return out


PANTS = Path(__file__).resolve().parents[2] / "scenes" / "trousers_human.toml"
QUICK = {"garment": {"h": 0.08, "sewing_time": 0.1}, "donning": {"time": 0.1}, "motion": {"settle_time": 0.05},
         "route": {"end_time": 0.35}}      # the quick mode of tests/test_human_scene.py


def pants_scene(ellipsoids: bool) -> scene_build.Scene:
    """The quick trousers scene (QUICK) on the Debian human's skin, or on the blended lower body of its dimensions
    (validated as if read from scenes/trousers_human.toml)."""
    data = tomllib.loads(PANTS.read_text())
    for section, values in QUICK.items():
        data[section].update(values)
    if ellipsoids:
        data["body"] = {"type": "lower_body", **dataclasses.asdict(HUMAN_DIMENSIONS)}
    return scene_build.validate(data, PANTS.name, PANTS)


def pants_ms(scene: scene_build.Scene, skin: MeshSkin | None, comm=MPI.COMM_WORLD) -> dict:
    """One quick trousers run: ms per timed step of the body contact hooks, the steps, the searched points."""
    run = scene_build.garment_scene_run(scene, comm, skin=skin)
    start = time.perf_counter()
    history = run.run()
    wall = time.perf_counter() - start
    t = history.timings
    steps = max(int(t["steps"]), 1)
    used = run.contact.skin
    out = {"contact_ms": 1e3 * (t["contact_s"] + t["pose_torque_s"]) / steps, "steps": steps, "wall_s": wall,
           "searched": used.exact_points / max(run.integrator.step_count, 1) if used is not None else 0.0,
           "max_penetration": max(s.max_penetration for s in history.steps)}
    run.destroy()
    return out


def pants(repeats: int, spacing: float) -> None:
    """The --scene pants benchmark (module docstring): medians of `repeats` runs of each skin."""
    blended, human = pants_scene(True), pants_scene(False)
    parsed = blended.parsed
    body = wear.plan(parsed, wear.wear_fabric(parsed, scene_build.build_fabric), blended.path).body
    mesh = ellipsoid_skin(body, spacing=spacing, margin=0.0)
    print(f"pants: triangulated blend {len(mesh.mesh.faces)} triangles ({mesh.blended_triangles} blended), "
          f"spacing {spacing} m", flush=True)
    variants = {"ellipsoids": (blended, None), "mesh": (blended, mesh), "human": (human, None)}
    rows = {name: [] for name in variants}
    for k in range(repeats):
        for name, (scene, skin) in variants.items():
            r = pants_ms(scene, skin)
            rows[name].append(r)
            print(f"  run {k + 1} {name}: contact {r['contact_ms']:.3f} ms/step, {r['steps']} steps, searched "
                  f"{r['searched']:.0f} points/step, penetration {r['max_penetration']:.2e} m, "
                  f"{r['wall_s']:.1f} s", flush=True)
    med = {name: statistics.median(r["contact_ms"] for r in runs) for name, runs in rows.items()}
    print(f"medians of {repeats}: ellipsoids {med['ellipsoids']:.3f} ms/step, triangulated blend {med['mesh']:.3f} "
          f"(ratio {med['mesh'] / med['ellipsoids']:.2f}), human {med['human']:.3f} (ratio "
          f"{med['human'] / med['ellipsoids']:.2f})", flush=True)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", default="10x13", help="n_around x n_along of the tube")
    parser.add_argument("--angle", type=float, default=10.0, help="final elbow angle [deg]")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--spacing", type=float, default=0.01, help="the skin's marching-cubes spacing [m]")
    parser.add_argument("--margin", type=float, default=0.0, help="the active set's margin [m] (<0: none)")
    parser.add_argument("--scene", choices=("sleeve", "pants"), default="sleeve")
    parser.add_argument("--pants-spacing", type=float, default=0.012, help="the pants' skin spacing [m]")
    args = parser.parse_args(argv)
    if args.scene == "pants":
        pants(args.repeats, args.pants_spacing)
        return
    n_around, n_along = (int(v) for v in args.mesh.split("x"))
    config = SleeveConfig.of(n_around=n_around, n_along=n_along, final_angle=args.angle)
    skin = sleeve_skin(config, args.spacing, None if args.margin < 0 else args.margin)
    print(f"skin: {len(skin.mesh.faces)} triangles ({skin.blended_triangles} blended), spacing {args.spacing} m, "
          f"margin {args.margin} m", flush=True)
    rows = {"ellipsoids": [], "mesh": []}
    for k in range(args.repeats):
        for name in rows:
            r = contact_ms(config, skin if name == "mesh" else None)
            rows[name].append(r)
            print(f"  run {k + 1} {name}: contact {r['contact_ms']:.3f} ms/step, step {r['step_ms']:.3f} ms, "
                  f"{r['steps']} steps, torque {r['torque']:.5e} N m, searched {r['searched']:.0f} points/step, "
                  f"penetration {r['max_penetration']:.2e} m, {r['wall_s']:.1f} s", flush=True)
    med = {name: {key: statistics.median(r[key] for r in runs) for key in ("contact_ms", "step_ms")}
           for name, runs in rows.items()}
    print(f"medians of {args.repeats}: ellipsoids contact {med['ellipsoids']['contact_ms']:.3f} ms/step (step "
          f"{med['ellipsoids']['step_ms']:.3f}), mesh contact {med['mesh']['contact_ms']:.3f} ms/step (step "
          f"{med['mesh']['step_ms']:.3f}); ratio contact {med['mesh']['contact_ms'] / med['ellipsoids']['contact_ms']:.2f}"
          f", whole step {med['mesh']['step_ms'] / med['ellipsoids']['step_ms']:.2f}", flush=True)


if __name__ == "__main__":
    main()
