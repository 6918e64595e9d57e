"""fabricfem: verified finite-element mechanics of clothing on FEniCSx (SI units throughout).

SCOTCH_PTHREAD_NUMBER = 1 unless set: PT-Scotch, dolfinx's mesh partitioner here, partitions the same mesh
differently from run to run when it uses threads; with one thread a parallel run is repeatable bit for bit
(docs/findings/2026-11-28-startup.md, "The partition").
"""
import os

os.environ.setdefault("SCOTCH_PTHREAD_NUMBER", "1")

__version__ = "0.1.0"
