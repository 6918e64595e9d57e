"""Cantilever strips: roll-up [Man2006, sec. 2.3.2.2] and the elastica benchmarks of [Eischen2000, sec. 4.1-4.2.]"""
from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
from mpi4py import MPI

from fabricfem.launch import child_environment
from fabricfem.materials import Fabric
from fabricfem.meshes import directions, plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.verify import Timer, case, references, result

# [Eischen2000, sec. 4.1-4.2]: L = 1, EA = 2 sqrt(3) e-3, EI = 2 sqrt(3) e-9 (so t = sqrt(12 EI / EA) = 3.46e-3).
SEED_L, SEED_EA, SEED_EI, SEED_WIDTH = 1.0, 2.0 * np.sqrt(3.0) * 1e-3, 2.0 * np.sqrt(3.0) * 1e-9, 0.1


def strip_model(L: float, width: float, E: float, t: float, nx: int, ny: int = 1, comm=MPI.COMM_WORLD,
                cell: str = "quadrilateral", warp_angle: float = 0.0) -> ShellModel:
    """Strip [0, L] x [0, width] clamped at x = 0 (nu = 0), its warp at `warp_angle` [rad] to the strip
    (about +z; the director base starts on warp and weft)."""
    fmesh = plate(L, width, nx, ny, cell=cell, comm=comm)
    if warp_angle:
        fmesh = dataclasses.replace(fmesh, warp=directions.constant((np.cos(warp_angle), np.sin(warp_angle), 0.0)))
    return ShellModel(fmesh, Fabric.isotropic(E, 0.0, t)).clamp("left")


def seed_cantilever(nx: int = 20, comm=MPI.COMM_WORLD) -> tuple[ShellModel, float]:
    t = np.sqrt(12.0 * SEED_EI / SEED_EA)
    E = SEED_EA / (SEED_WIDTH * t)
    return strip_model(SEED_L, SEED_WIDTH, E, t, nx, comm=comm), t


def _tip_angle_tracker(model: ShellModel, tip, sign: float):
    """Accumulated rotation of the tip director in the x-z plane [rad] along the load path."""
    angles = [0.0]

    def track(_step=None):
        d = model.director_at(tip)
        angle = np.arctan2(sign * d[0], d[2])
        angles.append(float(np.unwrap([angles[-1], angle])[1]))
    return angles, track


def rollup(m_values=(0.25, 0.5, 0.75, 1.0), L: float = 1.0, width: float = 0.1, t: float = 1e-3, E: float = 1e7,
           nx: int = 40, comm=MPI.COMM_WORLD, cell: str = "quadrilateral", warp_angle: float = 0.0,
           max_step: float | None = None) -> tuple[ShellModel, dict[float, np.ndarray], float, list]:
    """Roll the strip up by an end moment M = m 2 pi EI / L (about -y, whatever the warp); returns the model,
    the tip position at each m, EI and the load-step history (first step 0.05, capped by max_step)."""
    model = strip_model(L, width, E, t, nx, comm=comm, cell=cell, warp_angle=warp_angle)
    EI = E * width * t ** 3 / 12.0
    M = 2.0 * np.pi * EI / L
    model.add_edge_moment("right", (0.0, -M / width, 0.0))  # about -y: the strip curls towards +z
    tip = np.array([L, 0.0, 0.0])
    positions = {}
    history = solve_load_path(model, list(m_values), initial_step=0.05, max_step=max_step,
                              on_target=lambda m: positions.__setitem__(round(m, 12), tip + model.node_value(tip)))
    return model, positions, EI, history


@case("rollup-cantilever", mpi=True)
def rollup_cantilever() -> list:
    """Tip position against the exact circle of radius EI / M, |error| / L < 1% at m = 0.25 ... 1
    (t/L = 1/1000); at m = 1 the tip returns to the clamped end."""
    L = 1.0
    with Timer() as timer:
        model, positions, _, _ = rollup(L=L)
    out = []
    for m, tip in positions.items():
        exact = references.rollup_tip(L, m * 2.0 * np.pi / L)
        err = np.hypot(tip[0] - exact[0], tip[2] - exact[1]) + abs(tip[1])
        out.append(result("rollup-cantilever", f"tip position error / L at m = {m:g}", err / L, 0.0, 0.01,
                          model.ndofs, timer.elapsed, scale=1.0))
    closure = np.linalg.norm(positions[1.0] - np.array([0.0, positions[1.0][1], 0.0]))
    out.append(result("rollup-cantilever", "m = 1: distance tip to clamp / L (closed circle)", closure / L, 0.0,
                      0.01, model.ndofs, timer.elapsed, scale=1.0))
    return out


@case("tip-loaded-cantilever")
def tip_loaded_cantilever(lambdas=(1.0, 2.0, 5.0, 10.0), nx: int = 20) -> list:
    """[Eischen2000, sec. 4.1]: dead tip load P = lambda EI / L^2; tip deflection and rotation against the
    elastica ODE (scipy shooting, references.elastica_tip_load) within 1%."""
    out = []
    with Timer() as timer:
        model, _ = seed_cantilever(nx)
        P = 1.0 * SEED_EI / SEED_L ** 2
        model.add_edge_traction("right", (0.0, 0.0, -P / SEED_WIDTH))
        tip = np.array([SEED_L, 0.0, 0.0])
        angles, track = _tip_angle_tracker(model, tip, +1.0)
        values = {}

        def record(lam):
            values[lam] = (-model.node_value(tip)[2] / SEED_L, angles[-1])
        solve_load_path(model, list(lambdas), initial_step=0.5, progress=track, on_target=record)
    for lam, (w, rot) in values.items():
        ref = references.elastica_tip_load(lam)
        out.append(result("tip-loaded-cantilever", f"w/L at lambda = {lam:g}", w, ref["w"], 0.01, model.ndofs,
                          timer.elapsed))
        out.append(result("tip-loaded-cantilever", f"tip rotation [rad] at lambda = {lam:g}", rot, ref["rotation"],
                          0.01, model.ndofs, timer.elapsed))
    return out


@case("moment-loaded-cantilever")
def moment_loaded_cantilever(lambdas=(0.5, 1.0, 1.5, 2.0), nx: int = 20) -> list:
    """[Eischen2000, sec. 4.2]: end moment M = lambda pi EI / L; the elastica is a circular arc of curvature
    M / EI: tip deflection (error relative to L) and rotation lambda pi within 1%."""
    out = []
    with Timer() as timer:
        model, _ = seed_cantilever(nx)
        M = np.pi * SEED_EI / SEED_L
        model.add_edge_moment("right", (0.0, -M / SEED_WIDTH, 0.0))
        tip = np.array([SEED_L, 0.0, 0.0])
        angles, track = _tip_angle_tracker(model, tip, -1.0)
        values = {}

        def record(lam):
            values[lam] = (model.node_value(tip)[2] / SEED_L, angles[-1])
        solve_load_path(model, list(lambdas), initial_step=0.05, progress=track, on_target=record)
    for lam, (w, rot) in values.items():
        exact = references.rollup_tip(SEED_L, lam * np.pi / SEED_L)
        out.append(result("moment-loaded-cantilever", f"w/L at lambda = {lam:g} (error relative to L)", w,
                          exact[1] / SEED_L, 0.01, model.ndofs, timer.elapsed, scale=1.0))
        out.append(result("moment-loaded-cantilever", f"tip rotation [rad] at lambda = {lam:g}", rot, lam * np.pi,
                          0.01, model.ndofs, timer.elapsed))
    return out


def rollup_tip_half(comm=MPI.COMM_WORLD) -> tuple[np.ndarray, int]:
    """Tip position of the roll-up at m = 0.5 and the number of dofs (to compare 1 and 2 MPI ranks)."""
    model, positions, _, _ = rollup(m_values=(0.5,), comm=comm)
    return positions[0.5], model.ndofs


@case("mpi-consistency", mpi=True)
def mpi_consistency() -> list:
    """Roll-up at m = 0.5 on 1 and on 2 MPI ranks: tip positions agree within 1e-8 relative.
    Serially this launches `mpirun -n 2` on fabricfem.verify.cantilevers; under mpirun it compares
    COMM_WORLD with COMM_SELF in-process."""
    with Timer() as timer:
        serial, ndofs = rollup_tip_half(MPI.COMM_SELF)
        if MPI.COMM_WORLD.size > 1:
            parallel, _ = rollup_tip_half(MPI.COMM_WORLD)
        else:
            proc = subprocess.run(["mpirun", "-n", "2", sys.executable, "-m", "fabricfem.verify.cantilevers"],
                                  capture_output=True, text=True, env=child_environment(), timeout=900)
            if proc.returncode != 0:
                raise RuntimeError(f"mpirun -n 2 failed (exit {proc.returncode}):\n{proc.stdout[-2000:]}\n"
                                   f"{proc.stderr[-2000:]}")
            parallel = np.array(json.loads(proc.stdout.strip().splitlines()[-1]))
    diff = np.linalg.norm(parallel - serial) / np.linalg.norm(serial)
    return [result("mpi-consistency", "|tip(2 ranks) - tip(1 rank)| / |tip|, roll-up m = 0.5", diff, 0.0, 1e-8,
                   ndofs, timer.elapsed, scale=1.0)]


if __name__ == "__main__":  # the parallel half of mpi-consistency
    tip, _ = rollup_tip_half(MPI.COMM_WORLD)
    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps(tip.tolist()))
