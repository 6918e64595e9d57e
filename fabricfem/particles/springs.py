"""Particle grid, spring sets and their forces/stiffness ([Eischen2000, sec. 3.1], eqs. 36-47). SI units.

A rectangular sheet is a grid of nx x ny particles (index k = iy nx + ix) joined by
- structural springs between direct neighbours along x and y (stretching, eqs. 36-38),
- shear springs along both diagonals of each cell (in-plane shear, eqs. 39-43),
- flexion (bending) triples of consecutive particles along x and y, whose energy depends on the
  angle Delta phi between the two consecutive segments (eqs. 44-47),
as in Provot's model ([Man2006, sec. 2.1.1.1], Fig. 4) with the stiffnesses of [Eischen2000].

Cross sections: eq. 37 writes A = b h with b the spacing. A spring along x stands for the strip of
sheet of width dy around its row, so we take A = w h with w the tributary width (dy inside, dy / 2
on the two border rows); then the springs of one cross section add up to the sheet's E h W and
E W h^3 / 12 exactly. On a square grid away from the border this is eq. 37 as written.
Masses are the areal density times the tributary area of each particle (lumped).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from fabricfem.materials import positive_number


@dataclass(frozen=True)
class SpringSet:
    """Linear springs between particles i[s] and j[s]: force stiffness (l - rest_length) along the spring.

    stiffness [N/m]; in compression (l < rest_length) it is scaled by compression_factor (D' of eq. 38).
    """

    name: str
    i: np.ndarray
    j: np.ndarray
    rest_length: np.ndarray
    stiffness: np.ndarray
    compression_factor: float = 1.0

    def __len__(self) -> int:
        return len(self.i)


@dataclass(frozen=True)
class BendingSet:
    """Flexion triples (a, b, c), b in the middle; energy 0.5 stiffness Delta phi^2 with Delta phi the angle
    between the segments b - a and c - b. stiffness is the rotational stiffness M / Delta phi [N m / rad]."""

    name: str
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    stiffness: np.ndarray

    def __len__(self) -> int:
        return len(self.a)


@dataclass
class ParticleSystem:
    """Particles (reference positions [m], lumped masses [kg]) with their spring and flexion sets."""

    positions: np.ndarray
    mass: np.ndarray
    springs: tuple[SpringSet, ...]
    bending: tuple[BendingSet, ...] = ()
    shape: tuple[int, int] | None = None  # (nx, ny) for grids
    spacing: float = 1.0  # characteristic particle spacing b [m]
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        self.positions = np.asarray(self.positions, dtype=float)
        self.mass = np.asarray(self.mass, dtype=float)
        if self.positions.ndim != 2 or self.positions.shape[1] != 3:
            raise ValueError(f"positions must have shape (n, 3), got {self.positions.shape}")
        if self.mass.shape != (len(self.positions),) or not np.all(np.isfinite(self.mass)) or np.any(self.mass < 0):
            raise ValueError("mass must be a finite non-negative array with one entry per particle")

    @property
    def n(self) -> int:
        return len(self.positions)

    def index(self, ix, iy) -> np.ndarray:
        """Particle index of grid node (ix, iy) (negative ix/iy count from the end)."""
        if self.shape is None:
            raise ValueError("index(): this particle system is not a grid")
        nx, ny = self.shape
        return (np.asarray(iy) % ny) * nx + np.asarray(ix) % nx

    def spring_set(self, name: str) -> SpringSet:
        for s in self.springs:
            if s.name == name:
                return s
        raise ValueError(f"no spring set named {name!r} (have {[s.name for s in self.springs]})")


def _tributary(n: int, d: float) -> np.ndarray:
    """Tributary length of each of n equally spaced nodes at spacing d (half at the two ends)."""
    w = np.full(n, d)
    w[0] = w[-1] = 0.5 * d
    return w


def rectangular_grid(nx: int, ny: int, dx: float, dy: float, E: float, nu: float, thickness: float,
                     areal_density: float, origin=(0.0, 0.0, 0.0), compression_factor: float = 1.0,
                     shear_factor: float = 1.0) -> ParticleSystem:
    """Flat nx x ny particle grid in the plane z = origin[2] with [Eischen2000]'s spring constants.

    E [Pa], nu, thickness h [m], areal_density [kg/m^2], spacings dx, dy [m].
    compression_factor = D' of eq. 38 (stretch springs in compression), shear_factor = B' of eq. 43.
    """
    if not (isinstance(nx, (int, np.integer)) and nx >= 2):
        raise ValueError(f"nx must be an integer >= 2, got {nx!r}")
    if not (isinstance(ny, (int, np.integer)) and ny >= 2):
        raise ValueError(f"ny must be an integer >= 2, got {ny!r}")
    dx, dy = positive_number("dx", dx), positive_number("dy", dy)
    E, h = positive_number("E", E), positive_number("thickness", thickness)
    if not (math.isfinite(nu) and -1.0 < nu < 0.5 + 1e-15):
        raise ValueError(f"nu must lie in (-1, 0.5], got {nu!r}")
    if not (math.isfinite(areal_density) and areal_density >= 0):
        raise ValueError(f"areal_density must be >= 0, got {areal_density!r}")
    positive_number("compression_factor", compression_factor)
    positive_number("shear_factor", shear_factor)

    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny))  # shape (ny, nx)
    ids = iy * nx + ix
    pos = np.column_stack([origin[0] + dx * ix.ravel(), origin[1] + dy * iy.ravel(),
                           np.full(nx * ny, float(origin[2]))])
    wx, wy = _tributary(nx, dx), _tributary(ny, dy)  # tributary lengths along x and y
    mass = areal_density * np.outer(wy, wx).ravel()

    # Structural springs, eq. 38: F = D' E A (Delta b / b), A = w h (eq. 37) -> stiffness E w h / b
    ax_i, ax_j = ids[:, :-1].ravel(), ids[:, 1:].ravel()
    ax_w = np.repeat(wy, nx - 1)
    ay_i, ay_j = ids[:-1, :].ravel(), ids[1:, :].ravel()
    ay_w = np.tile(wx, ny - 1)
    structural = SpringSet(
        "structural", np.concatenate([ax_i, ay_i]), np.concatenate([ax_j, ay_j]),
        np.concatenate([np.full(len(ax_i), dx), np.full(len(ay_i), dy)]),
        np.concatenate([E * h * ax_w / dx, E * h * ay_w / dy]), compression_factor)

    # Shear springs on both diagonals of each cell, eq. 43: F = B' E A Delta d / (2 b (1 + nu)) with
    # A = b h (eq. 37) -> stiffness B' E h / (2 (1 + nu)) = B' G h, independent of b.
    d_i = np.concatenate([ids[:-1, :-1].ravel(), ids[:-1, 1:].ravel()])
    d_j = np.concatenate([ids[1:, 1:].ravel(), ids[1:, :-1].ravel()])
    diag = math.hypot(dx, dy)
    shear = SpringSet("shear", d_i, d_j, np.full(len(d_i), diag),
                      np.full(len(d_i), shear_factor * E * h / (2.0 * (1.0 + nu))))

    # Flexion triples, eq. 47: F_bend = E I Delta phi / (b^2 (1 - nu^2)) applied with lever b (eq. 44),
    # i.e. the moment M = E I Delta phi / (b (1 - nu^2)); I = A h^2 / 12 (eq. 46), A = w h.
    bending = []
    if nx >= 3:
        I = np.repeat(wy * h ** 3 / 12.0, nx - 2)
        bending.append(BendingSet("flexion-x", ids[:, :-2].ravel(), ids[:, 1:-1].ravel(), ids[:, 2:].ravel(),
                                  E * I / (dx * (1.0 - nu ** 2))))
    if ny >= 3:
        I = np.tile(wx * h ** 3 / 12.0, ny - 2)
        bending.append(BendingSet("flexion-y", ids[:-2, :].ravel(), ids[1:-1, :].ravel(), ids[2:, :].ravel(),
                                  E * I / (dy * (1.0 - nu ** 2))))
    return ParticleSystem(pos, mass, (structural, shear), tuple(bending), shape=(nx, ny),
                          spacing=min(dx, dy),
                          info=dict(E=E, nu=nu, thickness=h, areal_density=areal_density, dx=dx, dy=dy))


def beam_strip(n_elements: int, length: float, EA: float, EI: float, line_density: float,
               origin=(0.0, 0.0, 0.0)) -> ParticleSystem:
    """A beam as two lines of particles ([Eischen2000, sec. 4]: "two lines of particles"), n_elements cells along x.

    The strip has width W = dx = length / n_elements; thickness h = sqrt(12 EI / EA) and E = EA / (W h) make
    the two lines carry together the axial rigidity EA [N] and the bending rigidity EI [N m^2] (nu = 0);
    line_density [kg/m] is the mass per unit length.
    """
    if not (isinstance(n_elements, (int, np.integer)) and n_elements >= 2):
        raise ValueError(f"n_elements must be an integer >= 2, got {n_elements!r}")
    length, EA, EI = positive_number("length", length), positive_number("EA", EA), positive_number("EI", EI)
    if not (math.isfinite(line_density) and line_density >= 0):
        raise ValueError(f"line_density must be >= 0, got {line_density!r}")
    dx = length / n_elements
    h = math.sqrt(12.0 * EI / EA)
    E = EA / (dx * h)
    return rectangular_grid(n_elements + 1, 2, dx, dx, E, 0.0, h, line_density / dx, origin=origin)


def chain(n_springs: int, rest_length: float, stiffness: float, particle_mass: float,
          direction=(0.0, 0.0, -1.0), origin=(0.0, 0.0, 0.0)) -> ParticleSystem:
    """A straight chain of n_springs + 1 particles (particle 0 at origin), equal springs and masses."""
    if not (isinstance(n_springs, (int, np.integer)) and n_springs >= 1):
        raise ValueError(f"n_springs must be an integer >= 1, got {n_springs!r}")
    L0, k, m = positive_number("rest_length", rest_length), positive_number("stiffness", stiffness), positive_number(
        "particle_mass", particle_mass)
    e = np.asarray(direction, dtype=float)
    if e.shape != (3,) or not np.linalg.norm(e) > 0:
        raise ValueError("direction must be a non-zero 3-vector")
    e = e / np.linalg.norm(e)
    pos = np.asarray(origin, dtype=float) + L0 * np.arange(n_springs + 1)[:, None] * e
    idx = np.arange(n_springs)
    springs = SpringSet("structural", idx, idx + 1, np.full(n_springs, L0), np.full(n_springs, k))
    return ParticleSystem(pos, np.full(n_springs + 1, m), (springs,), (), spacing=L0)


# ---------------------------------------------------------------------------------------------
# Forces, energies and stiffness (vectorized over springs / triples)


def scatter_add(out: np.ndarray, index: np.ndarray, values: np.ndarray) -> None:
    """out[index] += values for repeated indices (np.bincount per axis; much faster than np.add.at)."""
    n = len(out)
    for c in range(out.shape[1]):  # 3 axes
        out[:, c] += np.bincount(index, weights=values[:, c], minlength=n)


def _spring_state(x: np.ndarray, s: SpringSet):
    d = x[s.j] - x[s.i]
    length = np.linalg.norm(d, axis=1)
    if np.any(length <= 0):
        raise ValueError(f"spring set {s.name!r}: coincident particles (zero spring length)")
    k = np.where(length < s.rest_length, s.stiffness * s.compression_factor, s.stiffness)
    return d, length, k


def spring_energy(x: np.ndarray, s: SpringSet) -> float:
    """Elastic energy sum 0.5 k (l - l0)^2 [J]."""
    _, length, k = _spring_state(x, s)
    return float(0.5 * np.sum(k * (length - s.rest_length) ** 2))


def spring_forces(x: np.ndarray, s: SpringSet, out: np.ndarray | None = None) -> np.ndarray:
    """Forces on the particles, [Man2006, eq. 2.1]: F_i = k (|d| - l0) d / |d|, F_j = -F_i, d = x_j - x_i."""
    out = np.zeros_like(x) if out is None else out
    d, length, k = _spring_state(x, s)
    f = (k * (length - s.rest_length) / length)[:, None] * d
    scatter_add(out, s.i, f)
    scatter_add(out, s.j, -f)
    return out


def spring_stiffness_blocks(x: np.ndarray, s: SpringSet, definite: bool = True) -> np.ndarray:
    """3x3 blocks K_s = k [n n^T + (1 - l0/l) (I - n n^T)] (the Hessian of 0.5 k (l - l0)^2).

    definite=True clips (1 - l0/l) at 0 (springs in compression contribute no negative geometric stiffness),
    which keeps the matrix positive semi-definite for Newton-type relaxation.
    """
    d, length, k = _spring_state(x, s)
    n = d / length[:, None]
    nn = n[:, :, None] * n[:, None, :]
    g = 1.0 - s.rest_length / length
    if definite:
        g = np.maximum(g, 0.0)
    return k[:, None, None] * (nn + g[:, None, None] * (np.eye(3) - nn))


def _angle_gradient(e1: np.ndarray, e2: np.ndarray):
    """Angle phi between e1 and e2 and theta-weighted gradients: returns phi, phi dphi/de1, phi dphi/de2.

    dphi/de1 = -(u2 - cos(phi) u1) / (|e1| sin(phi)) (u = unit vectors); multiplied by phi the ratio
    phi / sin(phi) stays finite as phi -> 0.
    """
    l1, l2 = np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)
    if np.any(l1 <= 0) or np.any(l2 <= 0):
        raise ValueError("flexion triple with coincident particles (zero segment length)")
    u1, u2 = e1 / l1[:, None], e2 / l2[:, None]
    cos = np.einsum("ij,ij->i", u1, u2)
    sin = np.linalg.norm(np.cross(u1, u2), axis=1)
    phi = np.arctan2(sin, cos)
    ratio = np.where(sin > 1e-12, phi / np.where(sin > 1e-12, sin, 1.0), 1.0)  # phi / sin(phi)
    g1 = -(ratio / l1)[:, None] * (u2 - cos[:, None] * u1)
    g2 = -(ratio / l2)[:, None] * (u1 - cos[:, None] * u2)
    return phi, g1, g2


def bending_energy(x: np.ndarray, s: BendingSet) -> float:
    """Flexion energy sum 0.5 k_phi Delta phi^2 [J] (eqs. 44-47: M = k_phi Delta phi)."""
    e1, e2 = x[s.b] - x[s.a], x[s.c] - x[s.b]
    phi = np.arctan2(np.linalg.norm(np.cross(e1, e2), axis=1), np.einsum("ij,ij->i", e1, e2))
    return float(0.5 * np.sum(s.stiffness * phi ** 2))


def _bending_gradients(xa: np.ndarray, xb: np.ndarray, xc: np.ndarray, k: np.ndarray):
    """Energy gradients (dE/dxa, dE/dxb, dE/dxc) of 0.5 k phi^2 for each triple."""
    _, g1, g2 = _angle_gradient(xb - xa, xc - xb)
    g1, g2 = k[:, None] * g1, k[:, None] * g2
    return -g1, g1 - g2, g2


def bending_forces(x: np.ndarray, s: BendingSet, out: np.ndarray | None = None) -> np.ndarray:
    """Flexion forces -dE/dx. On the end particles they are normal to the segments with magnitude
    k_phi Delta phi / b = E I Delta phi / (b^2 (1 - nu^2)) (eq. 47); the middle particle balances them."""
    out = np.zeros_like(x) if out is None else out
    ga, gb, gc = _bending_gradients(x[s.a], x[s.b], x[s.c], s.stiffness)
    scatter_add(out, s.a, -ga)
    scatter_add(out, s.b, -gb)
    scatter_add(out, s.c, -gc)
    return out


def bending_stiffness_blocks(x: np.ndarray, s: BendingSet, step: float) -> np.ndarray:
    """9x9 Hessians of the flexion energy per triple by central differences of the analytic gradient
    (vectorized over triples; `step` [m] is the perturbation, ~1e-6 of the spacing)."""
    X = np.stack([x[s.a], x[s.b], x[s.c]], axis=1)  # (m, 3, 3)
    H = np.empty((len(s), 9, 9))
    for q in range(9):  # 9 local coordinates of a triple (not a loop over particles)
        p, c = divmod(q, 3)
        Xp, Xm = X.copy(), X.copy()
        Xp[:, p, c] += step
        Xm[:, p, c] -= step
        gp = np.concatenate(_bending_gradients(Xp[:, 0], Xp[:, 1], Xp[:, 2], s.stiffness), axis=1)
        gm = np.concatenate(_bending_gradients(Xm[:, 0], Xm[:, 1], Xm[:, 2], s.stiffness), axis=1)
        H[:, :, q] = (gp - gm) / (2.0 * step)
    return 0.5 * (H + H.transpose(0, 2, 1))


def internal_forces(system: ParticleSystem, x: np.ndarray) -> np.ndarray:
    """Sum of stretch, shear and flexion forces on every particle [N], shape (n, 3)."""
    out = np.zeros_like(x, dtype=float)
    for s in system.springs:
        spring_forces(x, s, out)
    for s in system.bending:
        bending_forces(x, s, out)
    return out


def elastic_energy(system: ParticleSystem, x: np.ndarray) -> float:
    """Total spring + flexion energy [J]."""
    return sum(spring_energy(x, s) for s in system.springs) + sum(bending_energy(x, s) for s in system.bending)


def stiffness_matrix(system: ParticleSystem, x: np.ndarray, definite: bool = True) -> sp.csr_matrix:
    """Tangent stiffness K = d^2 E / dx^2 as a (3n x 3n) sparse matrix (dof 3 k + c for particle k, axis c)."""
    rows, cols, vals = [], [], []

    def add(blocks: np.ndarray, nodes: np.ndarray):  # blocks (m, 3p, 3p), nodes (m, p)
        dofs = (3 * nodes[:, :, None] + np.arange(3)).reshape(len(nodes), -1)
        rows.append(np.repeat(dofs, dofs.shape[1], axis=1).ravel())
        cols.append(np.tile(dofs, (1, dofs.shape[1])).ravel())
        vals.append(blocks.ravel())

    for s in system.springs:
        K = spring_stiffness_blocks(x, s, definite)
        add(np.block([[K, -K], [-K, K]]), np.column_stack([s.i, s.j]))
    for s in system.bending:
        add(bending_stiffness_blocks(x, s, 1e-6 * system.spacing), np.column_stack([s.a, s.b, s.c]))
    n3 = 3 * system.n
    if not rows:
        return sp.csr_matrix((n3, n3))
    return sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n3, n3)).tocsr()
