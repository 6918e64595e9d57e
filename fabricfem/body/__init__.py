"""The wearer: rigid ellipsoidal body segments posed from joint and marker positions (thesis ch. 5)."""
from fabricfem.body.ellipsoid import Ellipsoid

__all__ = ["Ellipsoid"]
