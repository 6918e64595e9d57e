"""Another mesh or thickness compiles no new form: every mesh- or thickness-dependent number of the shell's forms (the
symmetry plane's penalty stiffness, the areal density of the weight, A, D, t, the PSRI weight's h) is a dolfinx
Constant or a Function, not a literal in the generated code, so that FFCx finds the forms of a second plate in its
cache (a new literal recompiled every form of a run with a symmetry plane: 10-19 s per mesh or thickness).

Counted: FFCx's builds (ffcx.codegeneration.jit._compile_objects, called only on a cache miss). The first plate may
compile (a cold cache); the second, with other divisions, other side lengths and another thickness, must not. The
second plate's lengths and thickness are drawn anew on every run: a number that became a literal again would give
forms never compiled before, whatever the cache holds from earlier runs.

Serial:  python -m pytest -q tests/test_constants_recompile.py
"""
from __future__ import annotations

import ffcx.codegeneration.jit as ffcx_jit
import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel

COMM = MPI.COMM_WORLD


@pytest.fixture
def builds(monkeypatch) -> list[str]:
    """The names of the modules FFCx builds (cache misses) while the test runs."""
    names: list[str] = []
    compile_objects = ffcx_jit._compile_objects

    def counting(decl, objects, object_names, module_name, *args, **kwargs):
        names.append(module_name)
        return compile_objects(decl, objects, object_names, module_name, *args, **kwargs)

    monkeypatch.setattr(ffcx_jit, "_compile_objects", counting)
    return names


def exercise(lx: float, ly: float, nx: int, ny: int, thickness: float) -> float:
    """Build a clamped plate with a symmetry plane, its weight and a pressure; compile and evaluate everything a
    Newton solve and an explicit step use (residual, tangent, internal force, mass, energy). Returns |R(x)| at a
    small deflection [N]."""
    fabric = Fabric(E1=5e6, E2=2e6, nu12=0.3, G12=3e5, thickness=thickness, density=400.0)
    model = ShellModel(plate(lx, ly, nx, ny, cell="quadrilateral", comm=COMM), fabric)
    model.clamp("left")
    model.symmetry("bottom", (0.0, 1.0, 0.0))
    model.add_gravity()
    model.add_pressure(10.0)
    model.set_load_factor(1.0)
    x, b, A = model.create_vector(), model.create_vector(), model.create_matrix()
    x.getArray()[:] = 1e-6 * np.sin(np.arange(x.getLocalSize()))
    model.jacobian(x, A)
    model.internal_force(x, b)
    model.residual(x, b)
    model.w.x.array[:] = 0.0                       # the explicit step from rest
    integrator = CentralDifference(model, 1e-7, force=True)
    integrator.run(1, output_every=1)
    integrator.destroy()
    return b.norm()


def test_another_mesh_and_thickness_compile_no_form(builds):
    first = exercise(0.1, 0.05, 4, 2, 5e-4)
    cold = list(builds)
    lx, ly, thickness = COMM.bcast(np.random.default_rng().uniform((0.12, 0.06, 6e-4), (0.2, 0.09, 1e-3)), root=0)
    second = exercise(lx, ly, 6, 3, thickness)
    assert np.isfinite(first) and np.isfinite(second) and second != first
    assert builds == cold, f"the second plate compiled {builds[len(cold):]}"
