"""Frictionless rigid obstacles for particles by penalty (seed 001 sec. 3.2.2, eq. 48 F_ext). SI units.

A `TablePlane` is the horizontal plane z = height restricted to a rectangle of (x, y) (a table top;
an unbounded half-plane x <= edge is the table of the overhanging beam). A particle whose (x, y) lies in
the rectangle (bounds included) and whose z is below the plane, but not deeper than `depth` (so particles
hanging below the table beside it are not caught), receives the normal force k_pen (height - z) e_z;
the energy is 0.5 k_pen (height - z)^2. The seed cancels the normal resultant instead; a penalty with a
stiff k_pen gives the same equilibrium up to a penetration reaction / k_pen.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fabricfem.particles.springs import ParticleSystem


def penalty_stiffness(system: ParticleSystem, factor: float = 100.0) -> float:
    """k_pen = factor x the largest spring stiffness of the system [N/m].

    With factor = 100 a particle pressed on the plane penetrates 1/100 of the elongation the same force would
    give its stiffest spring, so contact does not noticeably soften the cloth, while the static tangent
    matrix stays well conditioned (contact adds at most `factor` times the largest diagonal entry).
    For explicit dynamics the stable time step shrinks by about sqrt(factor / 4) (omega = sqrt(k_pen / m)).
    """
    if not (math.isfinite(factor) and factor > 0):
        raise ValueError(f"factor must be positive, got {factor!r}")
    return factor * max(float(np.max(s.stiffness)) for s in system.springs)


@dataclass(frozen=True)
class TablePlane:
    """Horizontal frictionless plane z = height [m] over xmin <= x <= xmax, ymin <= y <= ymax (bounds may be
    infinite), penalty stiffness [N/m], catching particles at most `depth` [m] below the plane."""

    height: float
    stiffness: float
    xmin: float = -np.inf
    xmax: float = np.inf
    ymin: float = -np.inf
    ymax: float = np.inf
    depth: float = np.inf

    def __post_init__(self):
        if not math.isfinite(self.height):
            raise ValueError(f"height must be finite, got {self.height!r}")
        if not (math.isfinite(self.stiffness) and self.stiffness > 0):
            raise ValueError(f"stiffness must be positive and finite, got {self.stiffness!r}")
        if not (self.xmin < self.xmax and self.ymin < self.ymax):
            raise ValueError("TablePlane bounds must satisfy xmin < xmax and ymin < ymax")
        if not self.depth > 0:
            raise ValueError(f"depth must be > 0, got {self.depth!r}")

    def penetration(self, x: np.ndarray) -> np.ndarray:
        """Penetration depth height - z of every particle [m] (0 where not in contact)."""
        inside = ((x[:, 0] >= self.xmin) & (x[:, 0] <= self.xmax) & (x[:, 1] >= self.ymin)
                  & (x[:, 1] <= self.ymax))
        pen = self.height - x[:, 2]
        return np.where(inside & (pen > 0) & (pen <= self.depth), pen, 0.0)

    def forces(self, x: np.ndarray) -> np.ndarray:
        """Contact forces [N], shape (n, 3): k_pen * penetration along +z."""
        f = np.zeros_like(x)
        f[:, 2] = self.stiffness * self.penetration(x)
        return f

    def energy(self, x: np.ndarray) -> float:
        return float(0.5 * self.stiffness * np.sum(self.penetration(x) ** 2))

    def stiffness_diagonal(self, x: np.ndarray) -> np.ndarray:
        """Contribution to the diagonal of the tangent matrix, shape (3n,)."""
        d = np.zeros_like(x)
        d[:, 2] = np.where(self.penetration(x) > 0, self.stiffness, 0.0)
        return d.ravel()


def table_top(center_x: float, center_y: float, half_x: float, half_y: float, height: float,
              stiffness: float, depth: float | None = None) -> TablePlane:
    """A rectangular table top centred at (center_x, center_y) [m]; depth defaults to half its smaller side."""
    if not (half_x > 0 and half_y > 0):
        raise ValueError(f"half_x and half_y must be > 0, got {half_x!r}, {half_y!r}")
    return TablePlane(height, stiffness, center_x - half_x, center_x + half_x, center_y - half_y,
                      center_y + half_y, min(half_x, half_y) if depth is None else depth)


def table_edge(edge_x: float, height: float, stiffness: float, depth: float = np.inf) -> TablePlane:
    """The half-plane x <= edge_x at z = height (the table of the overhanging beam, edge at x = edge_x)."""
    return TablePlane(height, stiffness, xmax=edge_x, depth=depth)
