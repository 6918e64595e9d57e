"""Argument checks shared by the mesh generators (ValueError naming the parameter)."""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

CELLS = ("triangle", "quadrilateral")


def positive(name: str, value: float, kind: str = "number") -> float:
    """``value`` as a float; it must be finite and > 0, else ValueError naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be a positive {kind}, got {value!r}") from None
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f"{name}: must be a positive {kind}, got {value!r}")
    return v


def non_negative(name: str, value: float, kind: str = "number") -> float:
    """``value`` as a float; it must be finite and >= 0, else ValueError naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be a non-negative {kind}, got {value!r}") from None
    if not (math.isfinite(v) and v >= 0.0):
        raise ValueError(f"{name}: must be a non-negative {kind}, got {value!r}")
    return v


def finite(name: str, value: float, kind: str = "angle in radians") -> float:
    """``value`` as a float; it must be a finite real number (not a bool), else ValueError naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be a finite {kind}, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(v):
        raise ValueError(f"{name}: must be a finite {kind}, got {value!r}")
    return v


def positive_length(name: str, value: float) -> float:
    """``value`` as a float; it must be finite and > 0 (metres)."""
    return positive(name, value, "length in metres")


def count(name: str, value: int, minimum: int = 1) -> int:
    """``value`` as an int; it must be an integer >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name}: must be an integer >= {minimum}, got {value!r}")
    return int(value)


def choice(name: str, value: str, allowed: Sequence[str]) -> str:
    """``value`` if it is one of ``allowed``."""
    if value not in allowed:
        raise ValueError(f"{name}: unknown value {value!r}; expected one of {list(allowed)}")
    return value


def point3(name: str, value: Sequence[float]) -> np.ndarray:
    """``value`` as a finite float array of shape (3,)."""
    try:
        p = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be 3 finite coordinates, got {value!r}") from None
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"{name}: must be 3 finite coordinates, got {value!r}")
    return p
