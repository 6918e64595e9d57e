"""The vector work of a central-difference step (fabricfem.dynamics.explicit.CentralDifference.step) in compiled
passes over the owned entries, each entry computed with the operations and in the order of the PETSc calls it
replaces, so that the step's values are the same to the bit:

    predict:    d_old_bc = d[bc];  d = (d + dt v) + dt^2/2 a;  v~ = v + dt/2 a        (Vec.axpy x 3, Vec.copy)
    balance:    r = (-f_int) + lambda F_ref;  c = C_L v~;  r = r - c                  (Vec.scale, axpy, pointwiseMult)
    accelerate: r[bc] = 0;  a = r / (M_L + dt/2 C_L)  (0 where the divisor is 0)      (zero_bc_rows, pointwiseDivide)
    correct:    v = v~ + dt/2 a;  v[bc] = (d[bc] - d_old_bc) / dt                     (Vec.copy, axpy, numpy)

PETSc's Vec.axpy is BLAS daxpy (y + alpha x, rounded twice, nothing added when alpha is 0) and its pointwise
operations one product or quotient per entry; the passes are compiled without contraction of multiply-adds
(fabricfem.forms.jit.ROUNDING_FLAGS), so every product and sum rounds as there. `matches_petsc()`
checks it on random vectors (the integrator falls back to the PETSc calls if it does not hold). Units: those of
the integrator's vectors (m, rad; m/s, rad/s; m/s^2, rad/s^2; N, N m; kg, kg m^2; s).
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.forms.jit import ROUNDING_FLAGS, built_once

CDEF = """
void cd_predict(double* d, const double* v, const double* a, double* vp, double* d_old_bc, const int32_t* bc,
                int nbc, int n, double dt, double half_dt2, double half_dt);
void cd_balance(double* r, const double* f_ref, double lam, const double* damping, const double* vp, double* cv,
                int n);
void cd_accelerate(double* a, double* r, const double* denominator, const int32_t* bc, int nbc, int n);
void cd_correct(double* v, const double* vp, const double* a, const double* d, const double* d_old_bc,
                const int32_t* bc, int nbc, int n, double dt, double half_dt);
"""

SOURCE = r"""
#include <stdint.h>

void cd_predict(double* restrict d, const double* restrict v, const double* restrict a, double* restrict vp,
                double* restrict d_old_bc, const int32_t* restrict bc, int nbc, int n, double dt, double half_dt2,
                double half_dt)
{
  for (int j = 0; j < nbc; ++j)
    d_old_bc[j] = d[bc[j]];
  for (int i = 0; i < n; ++i)
  {
    double di = dt != 0.0 ? d[i] + dt * v[i] : d[i];
    d[i] = half_dt2 != 0.0 ? di + half_dt2 * a[i] : di;
    vp[i] = half_dt != 0.0 ? v[i] + half_dt * a[i] : v[i];
  }
}

/* damping NULL: no damping term (cv untouched) */
void cd_balance(double* restrict r, const double* restrict f_ref, double lam, const double* restrict damping,
                const double* restrict vp, double* restrict cv, int n)
{
  for (int i = 0; i < n; ++i)
  {
    double ri = -r[i];
    if (lam != 0.0)
      ri = ri + lam * f_ref[i];
    if (damping)
    {
      cv[i] = damping[i] * vp[i];
      ri = ri + -1.0 * cv[i];
    }
    r[i] = ri;
  }
}

void cd_accelerate(double* restrict a, double* restrict r, const double* restrict denominator,
                   const int32_t* restrict bc, int nbc, int n)
{
  for (int j = 0; j < nbc; ++j)
    r[bc[j]] = 0.0;
  for (int i = 0; i < n; ++i)
    a[i] = denominator[i] != 0.0 ? r[i] / denominator[i] : 0.0;
}

void cd_correct(double* restrict v, const double* restrict vp, const double* restrict a, const double* restrict d,
                const double* restrict d_old_bc, const int32_t* restrict bc, int nbc, int n, double dt,
                double half_dt)
{
  for (int i = 0; i < n; ++i)
    v[i] = half_dt != 0.0 ? vp[i] + half_dt * a[i] : vp[i];
  for (int j = 0; j < nbc; ++j)
    v[bc[j]] = (d[bc[j]] - d_old_bc[j]) / dt;
}
"""


def _library():
    """(lib, ffi) of the passes, built once per process (rank 0 builds, on COMM_WORLD's ranks at once)."""
    return built_once("fabricfem_cd_passes", CDEF, SOURCE, MPI.COMM_SELF, ROUNDING_FLAGS)


class StepPasses:
    """The compiled passes of a central-difference step on an integrator's PETSc vectors (module docstring).
    bc_rows: the owned Dirichlet rows (int32, sorted), as CentralDifference.bc_rows."""

    def __init__(self, bc_rows: np.ndarray):
        self.lib, self.ffi = _library()
        self.bc = np.ascontiguousarray(bc_rows, dtype=np.int32)
        self.d_old_bc = np.zeros(len(self.bc))
        self._bc = self.ffi.from_buffer("int32_t[]", self.bc)
        self._d_old_bc = self.ffi.from_buffer("double[]", self.d_old_bc)

    def _p(self, vec, readonly: bool = False):
        """cffi pointer to a PETSc Vec's owned entries."""
        return self.ffi.from_buffer("double[]", vec.getArray(readonly=readonly))

    def predict(self, d, v, a, vp, dt: float) -> None:
        """d_old_bc = d[bc]; d += dt v, then += dt^2/2 a; vp = v + dt/2 a (d, v, a, vp: PETSc Vecs; dt [s])."""
        self.lib.cd_predict(self._p(d), self._p(v, True), self._p(a, True), self._p(vp), self._d_old_bc, self._bc,
                            len(self.bc), d.getLocalSize(), dt, 0.5 * dt ** 2, 0.5 * dt)

    def balance(self, r, f_ref, lam: float, damping, vp, cv) -> None:
        """r = -r + lam f_ref, then (damping a Vec) cv = damping * vp and r = r - cv; damping None: no damping."""
        none = self.ffi.NULL
        self.lib.cd_balance(self._p(r), self._p(f_ref, True), lam,
                            none if damping is None else self._p(damping, True),
                            none if damping is None else self._p(vp, True), none if damping is None else self._p(cv),
                            r.getLocalSize())

    def accelerate(self, a, r, denominator) -> None:
        """r[bc] = 0; a = r / denominator (0 where it is 0)."""
        self.lib.cd_accelerate(self._p(a), self._p(r), self._p(denominator, True), self._bc, len(self.bc),
                               a.getLocalSize())

    def correct(self, v, vp, a, d, dt: float) -> None:
        """v = vp + dt/2 a; v[bc] = (d[bc] - d_old_bc) / dt, d_old_bc from the last `predict`."""
        self.lib.cd_correct(self._p(v), self._p(vp, True), self._p(a, True), self._p(d, True), self._d_old_bc,
                            self._bc, len(self.bc), v.getLocalSize(), dt, 0.5 * dt)


_CHECKED: dict[int, bool] = {}


def matches_petsc(n: int = 1001, seed: int = 0) -> bool:
    """Whether the passes give the values of the PETSc calls they replace to the bit on random sequential vectors of
    n entries (every 7th a Dirichlet row); checked once per process."""
    if seed not in _CHECKED:
        _CHECKED[seed] = _compare(n, seed)
    return _CHECKED[seed]


def _compare(n: int, seed: int) -> bool:
    """matches_petsc's comparison."""
    rng = np.random.default_rng(seed)
    vecs = []

    def vec(values):
        out = PETSc.Vec().createSeq(len(values), comm=MPI.COMM_SELF)
        out.getArray()[:] = values
        vecs.append(out)
        return out

    bc = np.arange(0, n, 7, dtype=np.int32)
    passes = StepPasses(bc)
    dt, lam = float(rng.uniform(1e-6, 1e-3)), float(rng.uniform(-2.0, 2.0))
    d, v, a, f, damping, den, r = (rng.standard_normal(n) for _ in range(7))
    den[bc] = 1.0
    ours = [vec(x) for x in (d, v, a, f, damping, den, r)] + [vec(np.zeros(n)), vec(np.zeros(n))]
    theirs = [vec(x) for x in (d, v, a, f, damping, den, r)] + [vec(np.zeros(n)), vec(np.zeros(n))]
    D, V, A, F, C, M, R, VP, CV = ours
    passes.predict(D, V, A, VP, dt)
    passes.balance(R, F, lam, C, VP, CV)
    passes.accelerate(A, R, M)
    passes.correct(V, VP, A, D, dt)
    D, V, A, F, C, M, R, VP, CV = theirs
    old = D.getArray()[bc].copy()
    D.axpy(dt, V)
    D.axpy(0.5 * dt ** 2, A)
    V.copy(VP)
    VP.axpy(0.5 * dt, A)
    R.scale(-1.0)
    R.axpy(lam, F)
    CV.pointwiseMult(C, VP)
    R.axpy(-1.0, CV)
    R.getArray()[bc] = 0.0
    A.pointwiseDivide(R, M)
    VP.copy(V)
    V.axpy(0.5 * dt, A)
    V.getArray()[bc] = (D.getArray()[bc] - old) / dt
    same = all(np.array_equal(x.getArray(), y.getArray()) for x, y in zip(ours, theirs))
    for x in vecs:
        x.destroy()
    return same
