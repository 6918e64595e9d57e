"""Arc-length continuation through a limit point: snap-through of a shallow arch.

A shallow sinusoidal arch z = H sin(pi x / L) (half model, symmetric at the crown, pinned ends) under a
crown load has a limit point. The limit load found by arc-length continuation (load control, [Eischen2000]
eqs. 19-26) is compared with the one from displacement control of the crown (prescribed deflection,
load = crown reaction), an independent way of tracing the same curve through the limit point.
"""
import numpy as np
import pytest

from fabricfem.materials import Fabric
from fabricfem.meshes import FabricMesh, plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.arclength import arc_length
from fabricfem.solvers.loadstep import solve_load_path

L, WIDTH, RISE, T, E = 1.0, 0.02, 0.03, 2e-3, 1e7


def arch(nx: int = 24) -> ShellModel:
    """Half arch 0 <= x <= L/2: pinned at x = 0, symmetric at the crown x = L/2; nu = 0."""
    flat = plate(L / 2, WIDTH, nx, 1, cell="quadrilateral")
    x = flat.mesh.geometry.x
    x[:, 2] = RISE * np.sin(np.pi * x[:, 0] / L)
    slope = lambda p: RISE * np.pi / L * np.cos(np.pi * p[0] / L)  # noqa: E731

    def warp(p):
        s = slope(p)
        return np.vstack([np.ones_like(s), np.zeros_like(s), s]) / np.sqrt(1 + s ** 2)

    def normal(p):
        s = slope(p)
        return np.vstack([-s, np.zeros_like(s), np.ones_like(s)]) / np.sqrt(1 + s ** 2)

    fmesh = FabricMesh(flat.mesh, flat.facet_tags, flat.tags, warp, normal)
    model = ShellModel(fmesh, Fabric.isotropic(E, 0.0, T), rebase=False)
    model.constrain("left", u=(0.0, 0.0, 0.0))                         # pinned (rotations free)
    model.constrain("right", u=(0.0, None, None), theta=(None, 0.0))   # symmetry at the crown
    model.constrain(lambda p: np.isclose(p[1], 0.0), u=(None, 0.0, None))  # no lateral drift
    return model


def limit_from_samples(loads: np.ndarray, values: np.ndarray) -> float:
    """First local maximum of a sampled curve, refined by a parabola through it and its neighbours."""
    peaks = np.flatnonzero((values[1:-1] > values[:-2]) & (values[1:-1] >= values[2:])) + 1
    if len(peaks) == 0:
        raise AssertionError("the limit point was not bracketed")
    k = int(peaks[0])
    a, b, c = np.polyfit(loads[k - 1:k + 2], values[k - 1:k + 2], 2)
    return c - b * b / (4 * a)


@pytest.mark.slow
def test_arc_length_limit_load_matches_displacement_control():
    crown = np.array([L / 2, 0.0, RISE])
    # Displacement control: crown deflection d = lambda * (-2.5 RISE); load = crown reaction (both halves: x2)
    disp = arch()
    disp.constrain("right", u=(None, None, -2.5 * RISE))
    deflections, loads = [], []

    def sample(lam):
        deflections.append(-disp.node_value(crown)[2])
        loads.append(-2.0 * disp.reaction("right", "u", 2))
    targets = list(np.linspace(0.01, 1.0, 100))
    solve_load_path(disp, targets, initial_step=0.01, on_target=sample)
    deflections, loads = np.array(deflections), np.array(loads)
    limit_displacement_control = limit_from_samples(deflections, loads)

    # Arc-length: dead crown load P = lambda * P_ref on the crown edge (half the load on the half model)
    P_ref = 1.0
    arc = arch()
    arc.add_edge_traction("right", (0.0, 0.0, -0.5 * P_ref / WIDTH))
    path = []
    arc_length(arc, ds=5e-3, max_steps=400, target_iterations=5, u_ref=RISE,
               on_step=lambda s: path.append((s.load_factor, -arc.node_value(crown)[2])))
    lam = np.array([p[0] for p in path])
    w = np.array([p[1] for p in path])
    peak = int(np.argmax(np.diff(lam) < 0))
    assert peak > 0 and lam[peak:].min() < 0.95 * lam[peak], "the path did not pass the limit point"
    limit_arc_length = limit_from_samples(w, lam * P_ref)
    # Tolerance 1%: both curves are the same discrete model; the limit values differ only by the
    # parabola refinement of sampled maxima (samples every ~1% of the rise near the peak).
    print(f"limit load: arc-length {limit_arc_length:.6e} N, displacement control {limit_displacement_control:.6e} N, "
          f"{len(path)} arc-length steps")
    assert limit_arc_length == pytest.approx(limit_displacement_control, rel=1e-2)
