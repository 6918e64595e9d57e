"""The sensor pressure (fabricfem.wear.sensor) against closed forms: a uniform pressure and a line load."""
from __future__ import annotations

import math

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.wear.sensor import sensor_pressure

DIAMETER = 0.03   # m


def grid(h: float, half: float = 0.05) -> np.ndarray:
    """The nodes (N, 3) [m] of a square grid of spacing h [m] over [-half, half]^2 in the plane z = 0."""
    axis = np.arange(-half, half + h / 2, h)
    x, y = np.meshgrid(axis, axis, indexing="ij")
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])


def test_uniform_pressure_reads_itself():
    """A uniform pressure p0 over the cloth: every disc's mean is p0 (to round-off, 1e-12 relative)."""
    points = grid(0.002)
    value = sensor_pressure(points, np.full(len(points), 1234.5), np.full(len(points), 0.002 ** 2), DIAMETER)
    assert value == pytest.approx(1234.5, rel=1e-12)


@pytest.mark.parametrize("h", [0.0006, 0.0003])
def test_line_load_converges_to_the_disc_mean(h):
    """A line load q = 10 N/m along y = 0 (nodal pressure q / h on the row of nodes, area h^2 each): the nodal
    peak is q / h and grows without limit as h -> 0, while the disc mean tends to q D / (pi D^2 / 4) = 4 q / (pi D)
    (the line's length D inside the disc over its area). On a grid of D / h = 50 and 100 spacings the lattice
    points of the disc and of its diameter differ from the continuous area and length by O(h / D): 3 %."""
    q = 10.0
    points = grid(h)
    on_line = np.abs(points[:, 1]) < h / 2
    pressure = np.where(on_line, q / h, 0.0)
    value = sensor_pressure(points, pressure, np.full(len(points), h * h), DIAMETER)
    assert pressure.max() == pytest.approx(q / h)
    assert value == pytest.approx(4.0 * q / (math.pi * DIAMETER), rel=0.03)


def test_no_contact_reads_zero():
    points = grid(0.01)
    assert sensor_pressure(points, np.zeros(len(points)), np.ones(len(points)), DIAMETER) == 0.0


@pytest.mark.mpi
def test_ranks_holding_parts_of_the_cloth_read_as_one():
    """The line load's nodes dealt round-robin over the ranks: the same value as one rank with all of them (the
    neighbours of a disc on another rank are gathered), to round-off (1e-12 relative)."""
    comm = MPI.COMM_WORLD
    h, q = 0.001, 10.0
    points = grid(h)
    pressure = np.where(np.abs(points[:, 1]) < h / 2, q / h, 0.0)
    area = np.full(len(points), h * h)
    whole = sensor_pressure(points, pressure, area, DIAMETER)
    mine = np.arange(comm.rank, len(points), comm.size)
    parts = sensor_pressure(points[mine], pressure[mine], area[mine], DIAMETER, comm)
    assert parts == pytest.approx(whole, rel=1e-12)
