"""Inertia and damping operators of the shell: consistent and lumped mass, Rayleigh and air damping.

Units: SI. Areal density rho t [kg/m^2] (Fabric.areal_density), rotational inertia rho t^3/12 [kg]
per unit area, air-drag coefficient eta [kg/(m^2 s)], Rayleigh coefficients a [1/s] and b [s].

Rotational inertia. The Naghdi director is d = cos th1 cos th2 a3 + cos th1 sin th2 a1 - sin th1 a2
(fabricfem.forms.shell.director). The thesis neglects the angular-velocity-squared term of the
acceleration [Man2006, eq. 2.65]; here the director velocity is also linearised about the director base,
d' ~ th2' a1 - th1' a2, so |d'|^2 ~ |theta'|^2 and the kinetic energy density is

    T = 1/2 rho t |u'|^2 + 1/2 rho t^3/12 |theta'|^2,

which gives a constant mass matrix ([Man2006, eq. 2.67] without the deformation dependence). The exact
metric of the angles is diag(1, cos^2 th1), so the rotational inertia is exact at theta = 0 and off by
O(th1^2) relative for finite angles; translational inertia is exact. The director base must therefore
stay fixed during a dynamic run (ShellModel.rebase = False; the integrators switch it off).

Rotary-inertia mass scaling (`rotary_inertia_scale` s >= 1, default 1 = physical): the rotational entries
rho t^3/12 are multiplied by s. In explicit shell codes this is the standard cure for a critical time
step governed by the thickness-shear / rotational modes (omega_s ~ sqrt(12 k G13 / rho) / t scales as
1 / sqrt(s), fabricfem.dynamics.stability); the translational mass, hence the loads' inertia and every
static answer, is unchanged (the rotational kinetic energy is t^2 s / 12 |theta'|^2 / |u'|^2 of the
translational one, negligible for s t^2 << L^2). Used by CentralDifference(rotary_inertia_scale=...).
"""
from __future__ import annotations

import basix
import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from ffcx.element_interface import create_element
from petsc4py import PETSc

from fabricfem.forms import shell as shell_forms
from fabricfem.materials import positive_number


def _check_density(model) -> float:
    rho_t = float(model.fabric.areal_density)
    if not rho_t > 0.0:
        raise ValueError(f"dynamics needs a positive fabric density (Fabric.density [kg/m^3]); "
                         f"areal density is {rho_t!r} kg/m^2")
    return rho_t


def rotational_inertia_factor(model) -> float:
    """t^2/12 [m^2]: rotational over translational inertia per unit area [Man2006, eq. 2.82]."""
    return float(model.fabric.thickness) ** 2 / 12.0


def rotary_scale(value) -> float:
    """The rotary-inertia scale factor s >= 1 (finite) or ValueError naming `rotary_inertia_scale`."""
    s = positive_number("rotary_inertia_scale", value)
    if s < 1.0:
        raise ValueError(f"rotary_inertia_scale must be >= 1 (1: physical rotary inertia), got {value!r}")
    return s


def mass_form(model, rotary_inertia_scale: float = 1.0):
    """Consistent mass bilinear form [kg]: rho t u.v + s rho t^3/12 theta.eta ([Man2006, eq. 2.67], linearised
    director; s the rotary-inertia scale, module docstring)."""
    scale = rotary_scale(rotary_inertia_scale)
    rho_t = fem.Constant(model.mesh, PETSc.ScalarType(_check_density(model)))
    trial = ufl.split(model.w_trial) if model.model == "naghdi" else (model.w_trial,)
    form = rho_t * ufl.dot(trial[0], model.v) * model.dx
    if model.model == "naghdi":
        j = fem.Constant(model.mesh, PETSc.ScalarType(scale * rotational_inertia_factor(model)))
        form += rho_t * j * ufl.dot(trial[1], model.eta) * model.dx
    return form


def air_drag_form(model, eta: float):
    """Bilinear form of the air drag f_d = -eta v [Peng2022], eta [kg/(m^2 s)] per unit reference area."""
    trial = ufl.split(model.w_trial)[0] if model.model == "naghdi" else model.w_trial
    return fem.Constant(model.mesh, PETSc.ScalarType(eta)) * ufl.dot(trial, model.v) * model.dx


def _strains(model, w):
    """Voigt membrane strain, bending strain and shear strain (Naghdi) of the state `w` (UFL)."""
    F0 = ufl.grad(model.phi0)
    if model.model == "naghdi":
        u, theta = ufl.split(w)
    else:
        u, theta = w, None
    F = F0 + ufl.grad(u)
    e1, e2 = shell_forms.material_frame(F0, model.t1, model.t2)
    eps_m = shell_forms.voigt(shell_forms.membrane_strain(F, F0), e1, e2)
    if theta is None:
        return eps_m, None, None
    d = shell_forms.director(theta, model.a3, model.a1, model.a2)
    kappa = shell_forms.voigt(shell_forms.bending_strain(F, F0, d, model.n0), e1, e2)
    g = shell_forms.shear_strain(F, F0, d, model.n0)
    return eps_m, kappa, ufl.as_vector([ufl.dot(g, e1), ufl.dot(g, e2)])


def material_stiffness_form(model, w_frozen: fem.Function, psri_degrees: tuple[int, int] = (4, 2)):
    """Material part K_M of the tangent stiffness at the state `w_frozen` [Man2006, eq. 2.85].

    K_M = int deps.A Deps + dkappa.D Dkappa + k_s G t dgamma.Dgamma with the strain variations taken at
    w_frozen and the PSRI split of the energy; the geometric part (stress times second variation of
    the strains) is left out, as in the thesis. A nonlinear bending law is replaced by its linear
    rigidity D here (damping only).
    """
    eps_m, kappa, gamma = _strains(model, w_frozen)
    test, trial = model.w_test, model.w_trial

    def bilinear(strain, C):
        return ufl.dot(ufl.derivative(strain, w_frozen, test), C * ufl.derivative(strain, w_frozen, trial))

    membrane = bilinear(eps_m, model.A)
    if kappa is None:
        return membrane * ufl.Measure("dx", domain=model.mesh, metadata={"quadrature_degree": 4})
    shear = model.shear_stiffness * ufl.dot(ufl.derivative(gamma, w_frozen, test),
                                            ufl.derivative(gamma, w_frozen, trial))
    bending = bilinear(kappa, model.D)
    dx_full, dx_reduced = shell_forms.psri_measures(model.mesh, *psri_degrees)
    h = getattr(model, "cell_size", None)              # the PSRI weight's h of the energy (a ShellModel's)
    h = ufl.CellDiameter(model.mesh) if h is None else h
    alpha = shell_forms.psri_weight(model.psri_thickness, h)
    return bending * dx_full + alpha * (membrane + shear) * dx_full + (1.0 - alpha) * (membrane + shear) * dx_reduced


def _subspaces(model) -> list[tuple[object, str]]:
    """(scalar subspace, 'u' or 'theta') for every field component of W."""
    if model.model == "naghdi":
        return [(model.W.sub(0).sub(i), "u") for i in range(3)] + [(model.W.sub(1).sub(j), "theta") for j in range(2)]
    return [(model.W.sub(i), "u") for i in range(3)]


def _hrz_nodal_factors(model, scalar_element) -> tuple[np.ndarray, int]:
    """Per owned cell and local node A: area_e int_e N_A^2 / sum_B int_e N_B^2 [m^2] ([Man2006, eq. 2.82], lambda);
    computed once per model and element (they depend on the fixed reference geometry only; the JIT lookup of the
    Jacobian's expression cost about 2 ms per integrator)."""
    cache = model.__dict__.setdefault("_hrz_factors", {})
    key = str(scalar_element)
    if key not in cache:
        cache[key] = _hrz_factors_of(model, scalar_element)
    return cache[key]


def _hrz_factors_of(model, scalar_element) -> tuple[np.ndarray, int]:
    """_hrz_nodal_factors, computed."""
    mesh = model.mesh
    cellname = mesh.ufl_cell().cellname()
    basix_cell = {"triangle": basix.CellType.triangle, "quadrilateral": basix.CellType.quadrilateral}[cellname]
    element = create_element(scalar_element)
    degree = 2 * scalar_element.degree() + 2
    points, weights = basix.make_quadrature(basix_cell, degree)
    N = element.tabulate(0, points)[0]  # (n_points, n_nodes)
    n_cells = mesh.topology.index_map(mesh.topology.dim).size_local
    cells = np.arange(n_cells, dtype=np.int32)
    detJ = np.abs(fem.Expression(ufl.JacobianDeterminant(mesh), points).eval(cells)).reshape(n_cells, -1)
    wJ = detJ * weights[None, :]  # (cells, points)
    diag = wJ @ (N ** 2)  # int_e N_A^2, (cells, nodes)
    area = wJ.sum(axis=1)  # int_e 1
    return area[:, None] * diag / diag.sum(axis=1, keepdims=True), n_cells


def lumped_mass(model, translational: bool = True, rotational: bool = True,
                rotary_inertia_scale: float = 1.0) -> PETSc.Vec:
    """Diagonal (lumped) mass of [Man2006, eq. 2.82] [kg, kg m^2] as a ghosted PETSc Vec on W.

    M_AA = lambda_e rho t int_e N_A^2 for the displacements and s t^2/12 of that for the rotations
    (s = rotary_inertia_scale >= 1, module docstring; 1 is eq. 2.82),
    lambda_e = int_e rho t / sum_B int_e rho t N_B^2 (the element's mass is preserved; all entries are
    positive for P2, Q2 and P2 + bubble, unlike row-sum lumping). Dirichlet rows are not modified.
    `translational` / `rotational` select which fields get their entries (the others are 0).
    """
    rho_t = _check_density(model)
    scale_rotary = rotary_scale(rotary_inertia_scale)
    m = model.create_vector()
    with m.localForm() as local:
        local.set(0.0)
        array = local.array
        cache: dict[str, np.ndarray] = {}
        for sub, field in _subspaces(model):
            if (field == "u" and not translational) or (field == "theta" and not rotational):
                continue
            V, to_parent = sub.collapse()
            if field not in cache:
                cache[field], _ = _hrz_nodal_factors(model, V.ufl_element())
            factors = cache[field]
            cell_dofs = V.dofmap.list.array.reshape(-1, V.dofmap.dof_layout.num_dofs)[:factors.shape[0]]
            parent = np.asarray(to_parent)[cell_dofs]
            scale = rho_t * (scale_rotary * rotational_inertia_factor(model) if field == "theta" else 1.0)
            np.add.at(array, parent.ravel(), scale * factors.ravel())
    m.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    m.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    return m


def assemble_matrix(form, bcs=None, diagonal: float = 1.0) -> PETSc.Mat:
    """Assemble a bilinear form (compiled here) into a new PETSc matrix."""
    compiled = fem.form(form)
    A = fem_petsc.assemble_matrix(compiled, bcs=bcs or [], diagonal=diagonal)
    A.assemble()
    return A


def consistent_mass(model, bcs=None, diagonal: float = 1.0) -> PETSc.Mat:
    """Consistent mass matrix [kg] (mass_form), optionally with Dirichlet rows/columns eliminated."""
    return assemble_matrix(mass_form(model), bcs, diagonal)


class InertiaDamping:
    """Mass M and damping C = a M + b K_M(d^n) + C_air of a model ([Man2006, eqs. 2.82, 2.84]-2.85; [Peng2022]).

    Args:
        model: a ShellModel (compiled here).
        lumped: use the diagonal mass of eq. 2.82 (and a diagonal air drag) instead of the consistent ones.
        rayleigh: (a [1/s], b [s]) of C = a M + b K_M; K_M is the material stiffness at the last converged
            state, frozen during a step [Man2006, eq. 2.85].
        air_drag: eta [kg/(m^2 s)] of the drag force per unit area f_d = -eta v (translations only).
        rotary_inertia_scale: s >= 1 multiplying the rotational inertia (module docstring; 1: physical).

    Products act on all rows; the callers zero the Dirichlet rows. `jacobian_form(c_mass, c_damp)` gives the
    consistent (non-diagonal) parts c_mass M + c_damp C as a UFL form, `diagonal` the lumped ones.
    """

    def __init__(self, model, lumped: bool = False, rayleigh: tuple[float, float] = (0.0, 0.0), air_drag: float = 0.0,
                 rotary_inertia_scale: float = 1.0):
        if len(rayleigh) != 2:
            raise ValueError(f"rayleigh must be a pair (a [1/s], b [s]), got {rayleigh!r}")
        a, b = (float(c) for c in rayleigh)
        for name, value in (("rayleigh[0] (mass-proportional a)", a), ("rayleigh[1] (stiffness-proportional b)", b),
                            ("air_drag (eta)", float(air_drag))):
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        model.compile()
        self.model = model
        self.lumped = bool(lumped)
        self.a, self.b, self.eta = a, b, float(air_drag)
        self.rotary_inertia_scale = rotary_scale(rotary_inertia_scale)
        self.w_frozen = fem.Function(model.W, name="damping_state")
        self.mass_ufl = mass_form(model, self.rotary_inertia_scale)
        self.stiffness_ufl = material_stiffness_form(model, self.w_frozen) if b > 0 else None
        if self.lumped:
            self.mass_diag = lumped_mass(model, rotary_inertia_scale=self.rotary_inertia_scale)
            diag = self.mass_diag.copy()
            diag.scale(a)
            if self.eta > 0:
                drag = lumped_mass(model, rotational=False)
                diag.axpy(self.eta / float(model.fabric.areal_density), drag)
            self.damping_diag = diag
            self.M = None
            consistent_damping = None
        else:
            self.mass_diag = self.damping_diag = None
            self.M = consistent_mass(model)  # no Dirichlet elimination: products need the full rows
            consistent_damping = a * self.mass_ufl if a > 0 else None
            if self.eta > 0:
                drag = air_drag_form(model, self.eta)
                consistent_damping = drag if consistent_damping is None else consistent_damping + drag
        if self.stiffness_ufl is not None:
            bK = fem.Constant(model.mesh, PETSc.ScalarType(b)) * self.stiffness_ufl
            consistent_damping = bK if consistent_damping is None else consistent_damping + bK
        self.damping_ufl = consistent_damping
        self._damping_form = fem.form(consistent_damping) if consistent_damping is not None else None
        self.C = fem_petsc.create_matrix(self._damping_form) if self._damping_form is not None else None
        self._assemble_damping()
        self._work: PETSc.Vec | None = None        # C x and a diagonal at once (damping_action)
        # whether C is non-zero: fixed by the construction (a norm is a reduction over the ranks: once, not per step)
        self.has_damping = self.C is not None or (self.damping_diag is not None and self.damping_diag.norm() > 0)

    def _assemble_damping(self):
        if self.C is None:
            return
        self.C.zeroEntries()
        fem_petsc.assemble_matrix(self.C, self._damping_form)
        self.C.assemble()

    def freeze(self, d: PETSc.Vec):
        """Re-evaluate b K_M at the converged state d ([Man2006, eq. 2.85]: C fixed during a step)."""
        if self.stiffness_ufl is None:
            return
        d.copy(self.w_frozen.vector)
        self.w_frozen.vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        self._assemble_damping()

    def mass_action(self, x: PETSc.Vec, out: PETSc.Vec):
        """out = M x."""
        if self.lumped:
            out.pointwiseMult(self.mass_diag, x)
        else:
            self.M.mult(x, out)

    def damping_action(self, x: PETSc.Vec, out: PETSc.Vec):
        """out = C x."""
        if self.C is None:
            if self.damping_diag is None:
                out.set(0.0)
            else:
                out.pointwiseMult(self.damping_diag, x)
            return
        self.C.mult(x, out)
        if self.damping_diag is not None:
            if self._work is None:
                self._work = x.duplicate()
            self._work.pointwiseMult(self.damping_diag, x)
            out.axpy(1.0, self._work)

    def jacobian_form(self, c_mass, c_damp):
        """UFL form c_mass M + c_damp C of the non-diagonal parts (None if there are none); c_* are Constants."""
        form = None if self.lumped else c_mass * self.mass_ufl
        if self.damping_ufl is not None:
            form = c_damp * self.damping_ufl if form is None else form + c_damp * self.damping_ufl
        return form

    def jacobian_diagonal(self, c_mass: float, c_damp: float) -> PETSc.Vec | None:
        """c_mass M_L + c_damp C_L of the lumped parts (None for consistent mass)."""
        if not self.lumped:
            return None
        out = self.mass_diag.copy()
        out.scale(c_mass)
        out.axpy(c_damp, self.damping_diag)
        return out

    def kinetic_energy(self, v: PETSc.Vec) -> float:
        """1/2 v.M v [J]."""
        tmp = v.duplicate()
        self.mass_action(v, tmp)
        energy = 0.5 * tmp.dot(v)
        tmp.destroy()
        return float(energy)
