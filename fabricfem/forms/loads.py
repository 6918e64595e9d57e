"""External virtual work of dead loads on the reference surface (SI units).

Each function returns the linear form delta W_ext(v) for a test function v of the
displacement (or rotation) field; the solver multiplies the sum by the load factor.
"""
from __future__ import annotations

import ufl


def body_force(v, areal_density, gravity, dx):
    """Weight of the sheet: int rho_A g . v dA, rho_A [kg/m^2], gravity [m/s^2] (a vector)."""
    return areal_density * ufl.dot(gravity, v) * dx


def edge_traction(v, traction, ds):
    """Force per unit reference edge length [N/m] on the tagged edge: int T . v dS."""
    return ufl.dot(traction, v) * ds


def surface_pressure(v, pressure, normal, dx):
    """Dead pressure [Pa] along the reference normal: int q n0 . v dA."""
    return pressure * ufl.dot(normal, v) * dx


def edge_moment(eta, moment, ds):
    """Moment per unit edge length [N m/m] doing work on the rotation angles: int m . eta dS."""
    return ufl.dot(moment, eta) * ds
