"""Particle (mass-spring) cloth model: the fast baseline of [Eischen2000, sec. 3] (SI units).

- springs: particle grid, structural / shear / flexion sets with [Eischen2000]'s constants (eqs. 36-47),
  forces, energies and sparse stiffness;
- obstacles: frictionless penalty planes (table top, table edge);
- integrate: velocity Verlet with Provot's strain limit, static relaxation (seed's iteration and Newton).
"""
from fabricfem.particles.integrate import (
                                           STANDARD_GRAVITY,
                                           DivergenceError,
                                           Problem,
                                           StaticResult,
                                           Trajectory,
                                           critical_time_step,
                                           provot_correction,
                                           relax_newton,
                                           relax_seed,
                                           simulate,
                                           strains,
                                           tangent_stiffness,
)
from fabricfem.particles.obstacles import TableTop, penalty_stiffness, table_edge, table_top
from fabricfem.particles.springs import (
                                           BendingSet,
                                           ParticleSystem,
                                           SpringSet,
                                           beam_strip,
                                           chain,
                                           elastic_energy,
                                           internal_forces,
                                           rectangular_grid,
                                           stiffness_matrix,
)

__all__ = ["STANDARD_GRAVITY", "DivergenceError", "Problem", "StaticResult", "Trajectory", "critical_time_step",
           "provot_correction", "relax_newton", "relax_seed", "simulate", "strains", "tangent_stiffness", "TableTop",
           "penalty_stiffness", "table_edge", "table_top", "BendingSet", "ParticleSystem", "SpringSet",
           "beam_strip", "chain", "elastic_energy", "internal_forces", "rectangular_grid", "stiffness_matrix"]
