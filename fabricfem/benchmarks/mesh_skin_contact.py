"""The explicit engine's contact against a mesh skin against the blended ellipsoids: per-step cost on the sleeve.

The default sleeve (tube on the default arm, mu = 0.1, explicit engine) flexed to `angle` degrees on mesh
`n_around` x `n_along`, once on the blended-ellipsoid skin (the default, compiled contact) and once on a
`MeshSkin` of the same arm (`ellipsoid_skin`: marching cubes of the blended arm at `spacing`, rigged to the
segments; queried with the active set `margin` and the rigid segments' static trees, fabricfem.body.mesh_skin).
The cost of a step's contact is the body-contact hooks' time over the motion's steps (search, projection,
friction, posing and torque sums: `contact_s + pose_torque_s` of `fabricfem.wear.engine.step_breakdown`), the
median of `repeats` runs each; the ratio mesh / ellipsoids and the elbow torque of both at the final angle.

Run: `python -m fabricfem.benchmarks.mesh_skin_contact [--mesh 10x13] [--angle 10] [--repeats 3]`.
"""
from __future__ import annotations

import argparse
import statistics
import time

from mpi4py import MPI

from fabricfem.body.mesh_skin import MeshSkin, ellipsoid_skin
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.sleeve import flexion_timeline, similarity_factor, tube_flexion_run


def sleeve_skin(config: SleeveConfig, spacing: float, margin: float | None, tree_tolerance: float = 0.0
                ) -> MeshSkin:
    """A MeshSkin of the configuration's flexing arm: its blended ellipsoids triangulated at `spacing` [m]."""
    body, _, _ = flexion_timeline(config.motion, config.route, similarity_factor(config.fabric, config.route),
                                  config.arm)
    return ellipsoid_skin(body, spacing=spacing, margin=margin, tree_tolerance=tree_tolerance)


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


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", default="10x13", help="n_around x n_along of the tube")
    parser.add_argument("--angle", type=float, default=10.0, help="final elbow angle [deg]")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--spacing", type=float, default=0.01, help="the skin's marching-cubes spacing [m]")
    parser.add_argument("--margin", type=float, default=0.0, help="the active set's margin [m] (<0: none)")
    parser.add_argument("--tree-tolerance", type=float, default=0.0, help="blended tree reuse distance [m]")
    args = parser.parse_args(argv)
    n_around, n_along = (int(v) for v in args.mesh.split("x"))
    config = SleeveConfig.of(n_around=n_around, n_along=n_along, final_angle=args.angle)
    skin = sleeve_skin(config, args.spacing, None if args.margin < 0 else args.margin, args.tree_tolerance)
    print(f"skin: {len(skin.mesh.faces)} triangles ({len(skin.trees.blend_ids)} blended), spacing {args.spacing} m, "
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
