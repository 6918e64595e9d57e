"""Frictionless rigid obstacles for particles by penalty ([Eischen2000, sec. 3.2.2], eq. 48 F_ext). SI units.

A `TableTop` is a horizontal rectangle [xmin, xmax] x [ymin, ymax] (bounds may be infinite: the half-plane
x <= edge is the table of the overhanging beam) whose top surface is the plane z = height, with edges
rounded to the radius `edge_radius`: the solid is every point within edge_radius of the rectangle lowered to
z = height - edge_radius. The gap of a particle is g = |p - q| - edge_radius with q the closest point of that
rectangle; where g < 0 the particle receives the normal force k_pen (-g) n, n = (p - q) / |p - q|, with
energy 0.5 k_pen g^2. On the top face n = e_z and this is a plane; the rounded edge makes the force
continuous when a particle slides over the edge (a sharp edge switches the support off discontinuously,
which stalls Newton's method). The seed cancels the normal resultant instead; a stiff penalty gives the same
equilibrium up to a penetration of reaction / k_pen.
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
class TableTop:
    """Frictionless table: top plane z = height [m] over xmin <= x <= xmax, ymin <= y <= ymax [m] (bounds may
    be infinite), edges rounded to edge_radius [m] > 0, penalty stiffness [N/m]."""

    height: float
    stiffness: float
    edge_radius: float
    xmin: float = -np.inf
    xmax: float = np.inf
    ymin: float = -np.inf
    ymax: float = np.inf

    def __post_init__(self):
        if not math.isfinite(self.height):
            raise ValueError(f"height must be finite, got {self.height!r}")
        if not (math.isfinite(self.stiffness) and self.stiffness > 0):
            raise ValueError(f"stiffness must be positive and finite, got {self.stiffness!r}")
        if not (math.isfinite(self.edge_radius) and self.edge_radius > 0):
            raise ValueError(f"edge_radius must be positive and finite, got {self.edge_radius!r}")
        if not (self.xmin < self.xmax and self.ymin < self.ymax):
            raise ValueError("TableTop bounds must satisfy xmin < xmax and ymin < ymax")

    def _gap(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed gap g [m] and outward unit normal n of every particle."""
        q = np.column_stack([np.clip(x[:, 0], self.xmin, self.xmax), np.clip(x[:, 1], self.ymin, self.ymax),
                             np.full(len(x), self.height - self.edge_radius)])
        d = x - q
        dist = np.linalg.norm(d, axis=1)
        n = np.where(dist[:, None] > 0, d / np.where(dist > 0, dist, 1.0)[:, None], np.array([0.0, 0.0, 1.0]))
        return dist - self.edge_radius, n

    def penetration(self, x: np.ndarray) -> np.ndarray:
        """Penetration depth -g of every particle [m] (0 where not in contact)."""
        g, _ = self._gap(x)
        return np.maximum(-g, 0.0)

    def forces(self, x: np.ndarray) -> np.ndarray:
        """Contact forces k_pen * penetration * n [N], shape (n, 3)."""
        g, n = self._gap(x)
        return (self.stiffness * np.maximum(-g, 0.0))[:, None] * n

    def energy(self, x: np.ndarray) -> float:
        return float(0.5 * self.stiffness * np.sum(self.penetration(x) ** 2))

    def stiffness_blocks(self, x: np.ndarray) -> np.ndarray:
        """3x3 tangent blocks k_pen n n^T per particle (Gauss-Newton part of the Hessian; the edge-curvature
        term is dropped, which keeps it positive semi-definite). Particles touching the surface (g <= 0) count
        as in contact, so that a cloth lying exactly on the table is supported from the first iteration."""
        g, n = self._gap(x)
        k = np.where(g <= 0, self.stiffness, 0.0)
        return k[:, None, None] * n[:, :, None] * n[:, None, :]


def table_top(center_x: float, center_y: float, half_x: float, half_y: float, height: float,
              stiffness: float, edge_radius: float) -> TableTop:
    """A rectangular table top centred at (center_x, center_y) with half sides half_x, half_y [m]."""
    if not (half_x > 0 and half_y > 0):
        raise ValueError(f"half_x and half_y must be > 0, got {half_x!r}, {half_y!r}")
    return TableTop(height, stiffness, edge_radius, center_x - half_x, center_x + half_x, center_y - half_y,
                    center_y + half_y)


def table_edge(edge_x: float, height: float, stiffness: float, edge_radius: float) -> TableTop:
    """The half-plane x <= edge_x at z = height (the table of the overhanging beam, edge at x = edge_x)."""
    return TableTop(height, stiffness, edge_radius, xmax=edge_x)
