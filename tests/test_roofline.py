"""The roofline benchmark's FLOP counter (fabricfem.benchmarks.roofline) against hand counts."""
from __future__ import annotations

import shutil

import pytest

from fabricfem.benchmarks.roofline import cell_bytes, counted_flops

SIZES = "#define NU 9\n#define NT 9\n#define NQF 9\n#define NQR 4\n#define SF 40\n#define SR 30\n#define NLAW 1\n"
KERNEL = r"""
static inline double dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
void naghdi_force(double* restrict A, const double* restrict w, const double* restrict c,
                  const double* restrict coordinate_dofs, const int* restrict entity_local_index,
                  const uint8_t* restrict quadrature_permutation)
{
  double s, co;
  for (int q = 0; q < 4; ++q)
    A[q] += dot3(w, c) / sqrt(w[q]);
  sincos(w[0], &s, &co);
  A[5] -= -s * co;
}
"""


@pytest.mark.skipif(shutil.which("g++") is None, reason="g++ is not installed")
def test_flops_are_counted_as_written():
    """Per pass of the loop: dot3 5 (3 products, 2 sums), the division, sqrt and += 3: 32 for 4 passes; sincos 2,
    the product and -= 2 (a negation is no FLOP): 36."""
    assert counted_flops(SIZES + KERNEL) == 36


LANE_KERNEL = r"""
void naghdi_force(double* restrict A, const double* restrict w, const double* restrict c,
                  const double* restrict coordinate_dofs, const int* restrict entity_local_index,
                  const uint8_t* restrict quadrature_permutation)
{
  vd a;
  for (int l = 0; l < LANES; ++l)
    a[l] = w[l];
  const vd b = 2.0 * (a * a + a) - a / c[0];
  A[0] = b[0];
}
"""


@pytest.mark.skipif(shutil.which("g++") is None, reason="g++ is not installed")
def test_lanes_are_counted_per_cell():
    """A kernel on LANES = 4 cells (the lane type): per lane a * a, + a, 2 *, a / c, - : 5 FLOPs a cell."""
    assert counted_flops(SIZES + "#define LANES 4\n" + LANE_KERNEL) == 5


def test_bytes_per_cell_follow_the_layout():
    """dofs 3 NU + 2 NT = 45: reference quantities (9 x 40 + 4 x 30) x 8, residual 45 x 8, dofmap 45 x 4 bytes."""
    assert cell_bytes(SIZES) == (360 + 120) * 8 + 45 * 8 + 45 * 4
