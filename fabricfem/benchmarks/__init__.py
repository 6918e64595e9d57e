"""Benchmarks that measure a property of the solvers (not a verification against a reference value).

- stability_map: largest stable explicit time step of the shell (central differences) and the particle
  model over in-plane stiffness and mesh size, against the predicted critical step; peak memory.

Run from the command line: `fabricfem bench stability-map [--out results/bench] [--quick]`.
"""
from fabricfem.benchmarks.stability_map import StabilityRow, particle_cloth, shell_cloth, shell_fabric, stability_map

__all__ = ["StabilityRow", "particle_cloth", "shell_cloth", "shell_fabric", "stability_map"]
