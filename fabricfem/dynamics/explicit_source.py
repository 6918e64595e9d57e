"""C source of the compiled explicit time loop (fabricfem.dynamics.compiled_loop): N central-difference steps of
[Man2006, eqs. 2.76, 2.82-2.84] with the run loop's bookkeeping and blow-up check, in one call.

One step, in the order and with the operations of `CentralDifference.step` and `TimeIntegrator._advance`
(fabricfem.dynamics.explicit, fabricfem.dynamics.integrator); d, v, a [m, m/s, m/s^2 or rad, rad/s, rad/s^2]:

    d^{n+1} = d^n + dt v^n + dt^2 / 2 a^n,   v~ = v^n + dt / 2 a^n                     [Man2006, eq. 2.76]
    d^{n+1} = lambda(t_{n+1}) g on the Dirichlet rows
    r       = lambda(t_{n+1}) F_ref - f_int(d^{n+1}) - C_L v~, 0 on the Dirichlet rows
    a^{n+1} = r / (M_L + dt/2 C_L)                                                     [Man2006, eq. 2.84]
    v^{n+1} = v~ + dt / 2 a^{n+1},  (d^{n+1} - d^n) / dt on the Dirichlet rows

f_int is assembled as dolfinx assembles a linear form over cells (fabricfem.shell.ShellModel.internal_force): per
cell the state's entries are gathered into the cell's packed coefficients, the element vector is zeroed, the
form's compiled kernel (FFCx's tabulate_tensor, or the hand-written fabricfem.forms.naghdi_kernel) is called and
its values are added to the rows of the cell, cells in the order of dolfinx's integration entities (the
hand-written kernel's own batched loop does the same, several cells a call). The work of
the loads and the damping's dissipation are booked by the trapezoidal rule, and the step is checked as
`TimeIntegrator._check` does: a non-finite d or v (status 1), or kinetic + strain energy above
energy_bound x (|E0| + max |W|) + floor (status 2), the strain energy by the energy form's kernels. The loop stops
after the step that fails, with its status; the caller repeats the check in Python (which raises its error).

Compiled without contraction of multiply-adds (`-ffp-contract=off`): every product and sum rounds as the vector
operations of the Python loop do.
"""
from __future__ import annotations

# ff_form: one compiled form over cells: kernel, cells, element vector length (0: a functional), packed coefficient
# width per cell with the state's block at state_start, the cells' state dofs (ncells x ndofs, or x the state
# block's length for a functional), the packed coefficients, constants and coordinate dofs (ncells x ncoord); or a
# batched kernel `cells` (fabricfem.forms.naghdi_kernel.assemble_cells) with its reference quantities, which reads
# the state itself (then kernel, coefficients and coordinates are unused)
TYPES = """
typedef void (*ff_kernel)(double*, const double*, const double*, const double*, const int*, const uint8_t*);
typedef void (*ff_cells)(double*, const double*, const double*, const double*, const int32_t*, int);
typedef struct {
  ff_kernel kernel;
  ff_cells cells;
  const double* reference;
  int ncells, ndofs, width, state_start, ncoord;
  const int32_t* dofs;
  double* coefficients;
  const double* constants;
  const double* coordinates;
} ff_form;
typedef struct {
  int n, nbc, nforce, nenergy, has_damping, check_energy;
  double dt, half_dt, half_dt2, energy_bound, energy_floor, energy0;
  double *d, *v, *a, *cv, *v_pred, *rhs, *d_old, *cv_old, *d_old_bc, *element;
  const double *mass, *damping, *denominator, *f_ref, *bc_scaled, *bc_fixed;
  const int32_t* bc_rows;
  const ff_form* force;
  const ff_form* energy;
  double t, lam, external_work, dissipated, max_work;
} ff_loop;
"""

CDEF = TYPES + """
int ff_run(ff_loop* L, int n_steps, const double* lams);
double ff_strain_energy(const ff_loop* L);
"""

SOURCE = r"""
#include <math.h>
#include <stdint.h>
#include <string.h>
""" + TYPES + r"""
/* copy the state d into the state block of every cell's packed coefficients (nstate values per cell) */
static void gather(const ff_form* f, const double* d, int nstate)
{
  for (int c = 0; c < f->ncells; ++c)
  {
    double* w = f->coefficients + (int64_t)c * f->width + f->state_start;
    const int32_t* dofs = f->dofs + (int64_t)c * nstate;
    for (int j = 0; j < nstate; ++j)
      w[j] = d[dofs[j]];
  }
}

/* rhs += the form's vector at d (cells in order; element vector zeroed before each kernel call) */
static void assemble_vector(const ff_form* f, const double* d, double* rhs, double* element)
{
  if (f->cells)
  {
    f->cells(rhs, d, f->reference, f->constants, f->dofs, f->ncells);
    return;
  }
  gather(f, d, f->ndofs);
  for (int c = 0; c < f->ncells; ++c)
  {
    memset(element, 0, sizeof(double) * f->ndofs);
    f->kernel(element, f->coefficients + (int64_t)c * f->width, f->constants,
              f->coordinates + (int64_t)c * f->ncoord, NULL, NULL);
    const int32_t* dofs = f->dofs + (int64_t)c * f->ndofs;
    for (int j = 0; j < f->ndofs; ++j)
      rhs[dofs[j]] += element[j];
  }
}

/* the functional's value at d: the cells' kernels add into one sum, as dolfinx's assemble_scalar */
static double assemble_scalar(const ff_form* f, const double* d)
{
  double value = 0.0;
  gather(f, d, f->ndofs);
  for (int c = 0; c < f->ncells; ++c)
    f->kernel(&value, f->coefficients + (int64_t)c * f->width, f->constants,
              f->coordinates + (int64_t)c * f->ncoord, NULL, NULL);
  return value;
}

double ff_strain_energy(const ff_loop* L)
{
  double energy = 0.0;
  for (int k = 0; k < L->nenergy; ++k)
    energy += assemble_scalar(&L->energy[k], L->d);
  return energy;
}

/* one central-difference step to t + dt with load factor lam (module docstring) */
static void step(ff_loop* L, double lam)
{
  const int n = L->n;
  double *d = L->d, *v = L->v, *a = L->a, *vp = L->v_pred, *rhs = L->rhs;
  for (int j = 0; j < L->nbc; ++j)
    L->d_old_bc[j] = d[L->bc_rows[j]];
  for (int i = 0; i < n; ++i)
    d[i] = d[i] + L->dt * v[i];
  for (int i = 0; i < n; ++i)
    d[i] = d[i] + L->half_dt2 * a[i];
  for (int i = 0; i < n; ++i)
    vp[i] = v[i] + L->half_dt * a[i];
  for (int j = 0; j < L->nbc; ++j)
    d[L->bc_rows[j]] = L->bc_scaled[j] != 0.0 ? lam * L->bc_scaled[j] : L->bc_fixed[j];
  memset(rhs, 0, sizeof(double) * n);
  for (int k = 0; k < L->nforce; ++k)
    assemble_vector(&L->force[k], d, rhs, L->element);
  for (int i = 0; i < n; ++i)
    rhs[i] = -rhs[i] + lam * L->f_ref[i];
  if (L->has_damping)
    for (int i = 0; i < n; ++i)
    {
      L->cv[i] = L->damping[i] * vp[i];
      rhs[i] = rhs[i] - L->cv[i];
    }
  for (int j = 0; j < L->nbc; ++j)
    rhs[L->bc_rows[j]] = 0.0;
  for (int i = 0; i < n; ++i)
    a[i] = rhs[i] / L->denominator[i];
  for (int i = 0; i < n; ++i)
    v[i] = vp[i] + L->half_dt * a[i];
  for (int j = 0; j < L->nbc; ++j)
    v[L->bc_rows[j]] = (d[L->bc_rows[j]] - L->d_old_bc[j]) / L->dt;
  L->t = L->t + L->dt;
}

/* work of the loads and the damping's dissipation over the step (trapezoidal rule), then the blow-up check:
   0 fine, 1 non-finite state, 2 energy above the bound */
static int account_and_check(ff_loop* L, double lam_old, double lam)
{
  const int n = L->n;
  double work = 0.0, dissipated = 0.0, kinetic = 0.0;
  for (int i = 0; i < n; ++i)
    work += L->f_ref[i] * (L->d[i] - L->d_old[i]);
  L->external_work += 0.5 * (lam_old + lam) * work;
  for (int i = 0; i < n; ++i)
    L->cv[i] = L->has_damping ? L->damping[i] * L->v[i] : 0.0;
  if (L->has_damping)
  {
    for (int i = 0; i < n; ++i)
      dissipated += (L->cv_old[i] + L->cv[i]) * (L->d[i] - L->d_old[i]);
    L->dissipated += 0.5 * dissipated;
  }
  L->max_work = fmax(L->max_work, fabs(L->external_work));
  for (int i = 0; i < n; ++i)
    if (!isfinite(L->d[i]) || !isfinite(L->v[i]))
      return 1;
  if (!L->check_energy)
    return 0;
  for (int i = 0; i < n; ++i)
    kinetic += L->mass[i] * L->v[i] * L->v[i];
  const double energy = 0.5 * kinetic + ff_strain_energy(L);
  const double scale = fabs(L->energy0) + L->max_work;
  return (!isfinite(energy) || energy > L->energy_bound * scale + L->energy_floor) ? 2 : 0;
}

/* up to n_steps steps with load factors lams[k] at their ends; returns the steps taken times 4 plus the status of
   the last one (0: all taken) */
int ff_run(ff_loop* L, int n_steps, const double* lams)
{
  for (int k = 0; k < n_steps; ++k)
  {
    memcpy(L->d_old, L->d, sizeof(double) * L->n);
    memcpy(L->cv_old, L->cv, sizeof(double) * L->n);
    const double lam_old = L->lam;
    step(L, lams[k]);
    L->lam = lams[k];
    const int status = account_and_check(L, lam_old, L->lam);
    if (status)
      return 4 * (k + 1) + status;
  }
  return 4 * n_steps;
}
"""
