"""The particle (mass-spring) model as a model level of the accuracy plan (fabricfem.scenes.accuracy). SI units.

A static plate scene becomes a grid of (nx + 1) x (ny + 1) particles on the plate's mesh nodes
(fabricfem.particles.rectangular_grid, the spring constants of [Eischen2000, eqs. 36-47]) with the scene's
orthotropic fabric: structural springs along x carry E1 t [N/m] per unit width, along y E2 t, the two diagonal shear
springs of a cell G12 t [N/m] each (eq. 43 with B' = 1), the flexion triples along x and y the shell's bending
rigidities D11 = E1 t^3 / (12 (1 - nu12 nu21)), D22 (or [fabric] bending_rigidity [B1, B2]) [N m] per unit width;
lumped masses density t x the tributary area [kg]. Loads as dead nodal forces [N] times the last solver target:
gravity [m/s^2] (m g), body_force [N/m^2] (x tributary area), edge_traction [N/m] (x tributary edge length), point
[N] (on the particle at the point). Supports: edges (bottom, right, top, left) or "all" or a point, u components
fixed or "free"; a rotation support only when all its components are "free". Solved by Newton's method on the
resultant forces (fabricfem.particles.relax_newton, load steps 0.1, 0.2, ..., 1); the quantity is the probe
particle's displacement (probe_u{x,y,z}_m).

What the particle model cannot represent (`particle_variant` says which, and the plan's notes carry it): dynamic
and wear scenes (not a particle level yet), tubes, unstructured plates, edge moments, pressure (a follower load),
fixed rotations (a clamp), nonlinear bending laws, a point support or load or a probe off the grid.
"""
from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
import time
from pathlib import Path

import numpy as np

from fabricfem import io
from fabricfem.particles import DivergenceError, ParticleSystem, Problem, rectangular_grid, relax_newton
from fabricfem.scenes.schema import ALL_NODES, SceneError
from fabricfem.scenes.sections import FabricSection, MeshSection, OutputSection, SolverSection, section

PARTICLE_LOADS = ("gravity", "body_force", "edge_traction", "point")
LOAD_STEPS = 10


def particle_variant(data: dict) -> tuple[dict | None, str]:
    """(the scene data, "") when the particle model can represent the scene, else (None, why not) (module
    docstring)."""
    why = _not_representable(data)
    return (None, f"particles: not considered ({why})") if why else (copy.deepcopy(data), "")


def _not_representable(data: dict) -> str:
    if "garment" in data:
        return "a wear scene: the wear engine runs the shell"
    if "dynamics" in data or "solver" not in data:
        return "not a static scene: the particle level is for static plates; dynamics not yet"
    if data.get("model", {}).get("kind", "naghdi") != "naghdi":
        return "the scene's model is not the shell"
    mesh = section(MeshSection, data["mesh"])
    if mesh.type != "plate":
        return "a tube: the particle grid is a flat rectangle"
    if not mesh.structured:
        return "an unstructured plate: the particles sit on a structured grid"
    fabric = section(FabricSection, data["fabric"])
    if fabric.bending_law is not None:
        return f"the nonlinear bending law {fabric.bending_law!r}: the flexion springs are linear"
    for i, load in enumerate(data.get("load", [])):
        if load["type"] not in PARTICLE_LOADS:
            return (f"load[{i}] is {'an edge moment' if load['type'] == 'edge_moment' else repr(load['type'])}: "
                    f"particles carry {', '.join(PARTICLE_LOADS)} only")
    for i, support in enumerate(data.get("support", [])):
        if any(v != "free" for v in support.get("theta") or ()):
            return f"support[{i}] fixes rotations: particles have none (a clamp needs the shell)"
    if section(OutputSection, data.get("output")).probe is None:
        return "no output.probe to compare"
    return ""


def particle_problem(data: dict) -> tuple[Problem, int]:
    """The particles.Problem of a representable static plate scene (module docstring) and the probe particle's
    index; SceneError naming the key when a point (support, load, probe) is not a particle."""
    m = section(MeshSection, data["mesh"])
    f = section(FabricSection, data["fabric"])
    nx, ny, dx, dy = m.nx + 1, m.ny + 1, m.lx / m.nx, m.ly / m.ny
    t = float(f.thickness)
    E1, E2, G12, nu12 = float(f.E1), float(f.E2), float(f.G12), float(f.nu12)
    nu21 = nu12 * E2 / E1
    B1, B2 = (tuple(float(b) for b in f.bending_rigidity) if f.bending_rigidity else
              (E1 * t ** 3 / (12 * (1 - nu12 * nu21)), E2 * t ** 3 / (12 * (1 - nu12 * nu21))))
    grid = rectangular_grid(nx, ny, dx, dy, E1, 0.0, t, float(f.density) * t)
    wx, wy = _tributary(nx, dx), _tributary(ny, dy)
    structural, shear = grid.spring_set("structural"), grid.spring_set("shear")
    n_x = ny * (nx - 1)                                   # x springs first (rectangular_grid)
    k = structural.stiffness.copy()
    k[n_x:] = E2 * t * np.tile(wx, ny - 1) / dy
    springs = (dataclasses.replace(structural, stiffness=k),
               dataclasses.replace(shear, stiffness=np.full(len(shear), G12 * t)))
    bending = []
    for s in grid.bending:   # flexion-x: B1 w / dx per triple, flexion-y: B2 w / dy
        w, B, d = ((np.repeat(wy, nx - 2), B1, dx) if s.name == "flexion-x" else (np.tile(wx, ny - 2), B2, dy))
        bending.append(dataclasses.replace(s, stiffness=B * w / d))
    system = ParticleSystem(grid.positions, grid.mass, springs, tuple(bending), shape=(nx, ny), spacing=min(dx, dy),
                            info=grid.info)
    x, y = system.positions[:, 0], system.positions[:, 1]
    tol = 1e-8 * max(m.lx, m.ly)
    edges = {"bottom": np.abs(y) < tol, "top": np.abs(y - m.ly) < tol, "left": np.abs(x) < tol,
             "right": np.abs(x - m.lx) < tol, ALL_NODES: np.ones(system.n, dtype=bool)}

    def particle(point, where: str) -> int:
        d = np.linalg.norm(system.positions - np.asarray(point, dtype=float), axis=1)
        i = int(np.argmin(d))
        if d[i] > tol:
            raise SceneError(f"{where}: {list(point)} is not a particle of the {m.nx}x{m.ny} grid")
        return i

    fixed = np.zeros((system.n, 3), dtype=bool)
    x0 = system.positions.copy()
    for i, support in enumerate(data.get("support", [])):
        if "point" in support:
            mask = np.zeros(system.n, dtype=bool)
            mask[particle(support["point"], f"support[{i}].point")] = True
        elif support["edge"] in edges:
            mask = edges[support["edge"]]
        else:
            raise SceneError(f"support[{i}].edge: unknown edge {support['edge']!r}; available: {sorted(edges)}")
        for c, v in enumerate(support.get("u") or ("free",) * 3):
            if v != "free":
                fixed[mask, c] = True
                x0[mask, c] = system.positions[mask, c] + float(v)
    forces = np.zeros((system.n, 3))
    gravity = np.zeros(3)
    area = np.outer(wy, wx).ravel()
    for i, load in enumerate(data.get("load", [])):
        kind, value = load["type"], load.get("value")
        if kind == "gravity":
            gravity += np.asarray(value if value is not None else (0.0, 0.0, -9.81), dtype=float)
        elif kind == "body_force":
            forces += area[:, None] * np.asarray(value, dtype=float)
        elif kind == "edge_traction":
            if load.get("edge") not in edges or load["edge"] == ALL_NODES:
                raise SceneError(f"load[{i}].edge: unknown edge {load.get('edge')!r}")
            mask = edges[load["edge"]]
            length = np.tile(wx, ny) if load["edge"] in ("bottom", "top") else np.repeat(wy, nx)
            forces[mask] += length[mask, None] * np.asarray(value, dtype=float)
        elif kind == "point":
            forces[particle(load["point"], f"load[{i}].point")] += np.asarray(value, dtype=float)
    scale = float(np.atleast_1d(section(SolverSection, data["solver"]).targets)[-1])
    probe = particle(section(OutputSection, data.get("output")).probe, "output.probe")
    problem = Problem(system, gravity=scale * gravity, point_forces=scale * forces, fixed=fixed)
    problem.start = x0   # prescribed displacements of the supports
    return problem, probe


def _tributary(n: int, d: float) -> np.ndarray:
    w = np.full(n, d)
    w[0] = w[-1] = 0.5 * d
    return w


def particle_dofs(data: dict) -> int:
    """3 x the number of particles, (nx + 1) (ny + 1)."""
    return 3 * (data["mesh"]["nx"] + 1) * (data["mesh"]["ny"] + 1)


def scene_hash(data: dict) -> str:
    """SHA-256 of the particle level's scene data: identifies the level a summary.json belongs to."""
    return hashlib.sha256(json.dumps({"particles": data}, sort_keys=True, default=str).encode()).hexdigest()


def solve_particles(data: dict, out: Path, comm=None) -> dict:
    """Solve the particle level of a static plate scene `data` into `out`/summary.json (read back when it holds a
    completed run of the same data): {"status", "ndofs", "wall_s", "newton_iterations", "probe_u{x,y,z}_m" [m],
    "probe_displacement_m", "solved_now"}. SceneError when Newton does not converge."""
    out = Path(out)
    sha = scene_hash(data)
    try:
        summary = json.loads((out / "summary.json").read_text())
        if summary.get("status") == "completed" and summary.get("scene_sha256") == sha:
            return {**summary, "solved_now": False}
    except (OSError, ValueError):
        pass
    t0 = time.perf_counter()
    problem, probe = particle_problem(data)
    try:
        result = relax_newton(problem, x0=problem.start, load_steps=LOAD_STEPS, max_iterations=100)
    except DivergenceError as exc:
        raise SceneError(f"particles ({data['mesh']['nx']}x{data['mesh']['ny']}): {exc}") from None
    u = result.x[probe] - problem.system.positions[probe]
    summary = {"kind": "static", "model": "particles", "status": "completed", "scene_sha256": sha,
               "ndofs": particle_dofs(data), "newton_iterations": result.iterations,
               "wall_s": time.perf_counter() - t0, "probe_displacement_m": [float(v) for v in u],
               **{f"probe_u{c}_m": float(v) for c, v in zip("xyz", u)}}
    if comm is None or comm.rank == 0:
        io.write_text_whole(out / "summary.json", json.dumps(summary, indent=1))
    return {**summary, "solved_now": True}

