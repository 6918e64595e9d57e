"""The cost of contact queries against a triangulated skin: the Debian human (26756 triangles) rigged to the lower
body in Winter's gait, 2000 points within about 1 cm of the skin (the cloth's nodes), medians of repeats.

Measures: reading and rigging once; per posed time the posing (linear blend skinning) and the AABB tree with the
pseudonormals (`MeshSkin.posed`, libigl); per call the contact's compiled query (fabricfem.body.mesh_query) of a
posed time already built; libigl's `signed_distance` (its own tree each call) on the same points; and an
explicit-like sequence (times dt apart, `calls` queries per time: the compiled tree refitted per time) with its
largest gap error against libigl's tree of each pose. Run: `python -m fabricfem.benchmarks.mesh_skin`.
"""
from __future__ import annotations

import argparse
import time

import igl
import numpy as np

from fabricfem.body import lower_body, winter_walking
from fabricfem.body.human import HUMAN_DIMENSIONS, HUMAN_KEYS, HUMAN_PATH, human_rest
from fabricfem.body.mesh_distance import PosedSurface
from fabricfem.body.mesh_skin import MeshSkin, read_skin


def median_ms(f, repeats: int) -> float:
    """Median wall time [ms] of f() over `repeats` calls."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        f()
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def sequence_ms(skin: MeshSkin, idx, offset, t0: float, dt: float, steps: int, calls: int) -> tuple[float, float]:
    """(median per-step time [ms] of `calls` queries at each of `steps` times dt apart, largest gap error [m]
    against libigl's tree of each pose)."""
    times, error = [], 0.0
    for k in range(steps):
        t = t0 + k * dt
        x = skin.surface(t)[0][idx] + offset
        start = time.perf_counter()
        for _ in range(calls):
            q = skin.query(x, t)
        times.append(time.perf_counter() - start)
        error = max(error, float(np.abs(q.gap - skin.posed(t).closest(x)[0]).max()))
    return 1e3 * float(np.median(times)), error


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--dt", type=float, default=1e-4, help="time between the sequence's steps [s]")
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--calls", type=int, default=3, help="queries per step")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    mesh = read_skin(HUMAN_PATH, **HUMAN_KEYS)
    read = time.perf_counter() - start
    body = lower_body(HUMAN_DIMENSIONS, winter_walking(HUMAN_DIMENSIONS))
    start = time.perf_counter()
    skin = MeshSkin(mesh, body, rest_positions=human_rest())
    rig = time.perf_counter() - start
    print(f"human: {len(mesh.faces)} triangles, read {read:.2f} s, rigged (bone heat) {rig:.2f} s")
    rng = np.random.default_rng(0)
    t0 = 0.3
    idx = rng.integers(0, len(mesh.vertices), args.points)
    offset = 0.01 * rng.standard_normal((args.points, 3))
    vertices = skin.surface(t0)[0]
    x = vertices[idx] + offset
    print(f"segment frames {median_ms(lambda: skin.transforms(t0), args.repeats):.2f} ms; a new posed time "
          f"{median_ms(lambda: skin.posed(t0 + 1e-9 * rng.random()), args.repeats):.1f} ms (LBS + AABB tree + "
          f"pseudonormals), of which tree + pseudonormals "
          f"{median_ms(lambda: PosedSurface(vertices, skin.topology), args.repeats):.1f} ms")
    print(f"query of {args.points} points on a built pose {median_ms(lambda: skin.query(x, t0), args.repeats):.1f} ms")
    faces = mesh.faces
    signed = median_ms(lambda: igl.signed_distance(x, vertices, faces, igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL),
                       args.repeats)
    print(f"igl.signed_distance (pseudonormal, its own tree each call) {signed:.1f} ms")
    step, error = sequence_ms(skin, idx, offset, t0, args.dt, args.steps, args.calls)
    print(f"sequence dt {args.dt:g} s, {args.calls} queries per step: {step:.1f} ms per step, gap error "
          f"{error:.2e} m")


if __name__ == "__main__":
    main()
