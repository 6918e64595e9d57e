"""fabricfem: verified finite-element mechanics of clothing on FEniCSx (SI units throughout)."""
import logging as _logging

# FFCx/CFFI log every JIT compilation at INFO on the root logger; keep user output clean.
_logging.getLogger().setLevel(_logging.WARNING)

__version__ = "0.1.0"
