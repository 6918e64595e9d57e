"""Moments and symmetry planes at any angle to the warp: the roll-up strip turned against its warp, and a
clamped plate solved whole and as a half model cut by a symmetry plane at an angle."""
from __future__ import annotations

import numpy as np

from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.verify import Timer, case, references, result
from fabricfem.verify.cantilevers import rollup

WARP_ANGLES = {"x": 0.0, "y": 90.0, "30 deg": 30.0, "45 deg": 45.0}   # angle of the warp to the strip [deg]
# Triangles need a finer strip than quadrilaterals for the closed circle: h/t = 1/120/1e-3 = 8.3 (< 30);
# on h/t = 25 and 12.5 the tip is 0.44 L off at m = 1 whatever the warp (measured, x-aligned too).
MESHES = {"quadrilateral": 40, "triangle": 120}
# load steps per cell type: the step independence (a moment that is one does not depend on the path) is checked
# on the quadrilateral strip; the triangle strip (9x the dofs) checks the cell type at the coarser step
STEPS = {"quadrilateral": (0.05, 0.01), "triangle": (0.05,)}


@case("rollup-any-direction")
def rollup_any_direction(steps: dict = STEPS) -> list:
    """The roll-up strip (rollup-cantilever) with its warp along the strip, across it, at 30 and at
    45 degrees, under the end moment vector (0, -M, 0), M = m 2 pi EI / L, for fixed load steps (STEPS: 0.05
    and 0.01 on quadrilaterals, 0.05 on triangles): the tip lies on the exact circle of radius EI / M (references.rollup_tip) within 1e-3 L at
    m = 0.25 ... 1, and at m = 1 it is back at the clamp. Tolerance 1e-3 L: the x-aligned quadrilateral strip
    is 4.5e-5 L off (rollup-cantilever, P2 arc interpolation), so 1e-3 leaves room for the mesh but not for
    a moment that is not one (the (m1, m2)-on-angles load left the 45-degree tip 3.7e-2 L off at m = 0.75)."""
    out = []
    for cell, nx in MESHES.items():
        for label, angle in WARP_ANGLES.items():
            for step in steps[cell]:
                with Timer() as timer:
                    model, positions, _, _ = rollup(nx=nx, cell=cell, warp_angle=np.radians(angle), max_step=step)
                where = f"{cell}s, warp {label}, steps {step:g}"
                for m, tip in positions.items():
                    exact = references.rollup_tip(1.0, m * 2.0 * np.pi)
                    err = np.hypot(tip[0] - exact[0], tip[2] - exact[1]) + abs(tip[1])
                    out.append(result("rollup-any-direction", f"tip error / L at m = {m:g}, {where}", err, 0.0,
                                      1e-3, model.ndofs, timer.elapsed, scale=1.0))
                out.append(result("rollup-any-direction", f"m = 1: tip to clamp / L, {where}",
                                  np.linalg.norm(positions[1.0][[0, 2]]), 0.0, 1e-3, model.ndofs, timer.elapsed,
                                  scale=1.0))
    return out


# Clamped square-ish plate, isotropic (mirror-symmetric about its mid-plane whatever the warp)
SPAN, WIDTH, T, E, NU = 0.4, 0.2, 1e-3, 1e7, 0.3
PRESSURE = 0.15   # Pa: centre deflection 0.55 t, membrane stiffening already clear (twice the linear w)


def _plate(lx: float, nx: int, angle: float) -> ShellModel:
    """Plate [0, lx] x [0, WIDTH] (quadrilaterals, NX by 6) turned by `angle` [rad] about z; warp stays +x."""
    fmesh = plate(lx, WIDTH, nx, 6, cell="quadrilateral")
    c, s = np.cos(angle), np.sin(angle)
    x = fmesh.mesh.geometry.x
    x[:, :2] = x[:, :2] @ np.array([[c, s], [-s, c]])
    return ShellModel(fmesh, Fabric.isotropic(E, NU, T))


@case("symmetry-plane", mpi=True)
def symmetry_plane(angles_deg=(0.0, 30.0, 45.0, 90.0)) -> list:
    """Clamped plate (SPAN x WIDTH, all edges clamped, pressure) against its half (SPAN/2 x WIDTH, clamped on
    three edges, ShellModel.symmetry on the cut) with the plate turned so that the plane's normal is at 0, 30,
    45 and 90 degrees to the warp: deflection at the plate centre and at (SPAN/4, WIDTH/4) agree within 1e-6
    relative (to the centre deflection). Tolerance 1e-6: the half mesh is the whole mesh's left half, node
    for node; what remains is the u . n penalty (O(1/penalty) = 1e-8) and the director base the half model
    turns to the plane, which changes the discrete director between nodes at O(theta^2) (measured 2e-8
    here, 1e-6 at 3x the pressure, where w = 1.6 t)."""
    out = []
    for angle_deg in angles_deg:
        angle = np.radians(angle_deg)
        turn = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0, 0, 1.0]])
        points = [turn @ np.array(p) for p in ((SPAN / 2, WIDTH / 2, 0.0), (SPAN / 4, WIDTH / 4, 0.0))]
        values = []
        with Timer() as timer:
            for half in (False, True):
                model = _plate(SPAN / 2 if half else SPAN, 6 if half else 12, angle)
                for edge in ("left", "bottom", "top") + (() if half else ("right",)):
                    model.clamp(edge)
                if half:
                    model.symmetry("right", turn[:, 0])
                model.add_pressure(PRESSURE)
                solve_load_path(model, 1.0, initial_step=1.0)
                values.append([model.node_value(p)[2] for p in points])
        (w_centre, w_off), (h_centre, h_off) = values
        for label, h, w in (("centre", h_centre, w_centre), ("(SPAN/4, WIDTH/4)", h_off, w_off)):
            out.append(result("symmetry-plane", f"half / whole deflection at {label}, plane normal "
                              f"{angle_deg:g} deg to the warp", h, w, 1e-6, model.ndofs, timer.elapsed,
                              scale=w_centre))
    return out
