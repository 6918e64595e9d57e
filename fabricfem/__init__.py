"""fabricfem: verified finite-element mechanics of clothing on FEniCSx (SI units throughout)."""
__version__ = "0.1.0"
