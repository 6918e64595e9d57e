"""Richardson extrapolation with the observed order on three levels of any refinement ratios, and the error
estimates of the accuracy target (fabricfem.scenes.accuracy, fabricfem.benchmarks.accuracy). Pure arithmetic.

Values q1, q2, q3 on cell sizes h1 > h2 > h3 (coarse to fine, any unit): the observed order p solves
(q1 - q2) / (q2 - q3) = (h1^p - h2^p) / (h2^p - h3^p) [Celik2008, eqs. 3-4] (for a constant ratio r this is
p = log(|q1 - q2| / |q2 - q3|) / log r), found by bisection; the extrapolated value is
q* = q3 + (q3 - q2) / (r^p - 1), r = h2 / h3 [Celik2008, eq. 5]. The sequence is "not asymptotic" when the
differences change sign, do not shrink, or p lies outside the plausible orders (P_MIN, P_MAX by default).

Estimated relative errors (`Estimate.errors`): asymptotic, |q_k - q*| / |q*| per level, and e3 r'^(-p m) for a
level m times finer by r' (`finer`); not asymptotic, the finest level's e3 = FS |q2 - q3| / ((r^P_FORMAL - 1) |q3|),
the grid convergence index with the safety factor FS = 3 of an unreliable order [Roache1994, GCI] (for r = 2 and
P_FORMAL = 2, e3 = |q2 - q3| / |q3|), and a coarser level's |q_k - q3| / |q3| + e3 (the triangle inequality).
"""
from __future__ import annotations

from dataclasses import dataclass

P_MIN, P_MAX = 0.5, 6.0   # plausible observed orders of a mesh sequence
P_FORMAL = 2.0            # the order assumed by the conservative estimate (second-order elements and integrators)
FS = 3.0                  # safety factor of the grid convergence index when the order is unreliable [Roache1994]
# plausible observed orders by scene kind: a static shell's Q2 elements may converge faster than order 2 (nodal
# superconvergence); a dynamic scene's step follows the mesh and its integrators are second order, so an observed
# order above 2 there is not the asymptotic rate
ORDERS = {"static": (P_MIN, P_MAX), "dynamic": (P_MIN, P_FORMAL)}


@dataclass
class Estimate:
    """Observed order p (None: not computed), extrapolated value (None: not asymptotic), `note` ("" or why the
    sequence is not asymptotic) and the estimated relative errors of the three levels, coarse to fine."""

    order: float | None
    extrapolated: float | None
    note: str
    errors: list[float]

    @property
    def asymptotic(self) -> bool:
        return not self.note

    def finer(self, refinement: float) -> float | None:
        """Predicted relative error of a level whose cells are `refinement` (> 1) times smaller than the finest's;
        None when the sequence is not asymptotic (no order to predict with)."""
        if not self.asymptotic:
            return None
        return self.errors[-1] * refinement ** -(self.order or 0.0)


def observed_order(values, sizes) -> float:
    """p of (q1 - q2) / (q2 - q3) = (h1^p - h2^p) / (h2^p - h3^p) by bisection on [1e-3, 50] (clamped to it)."""
    (q1, q2, q3), (h1, h2, h3) = values, sizes
    ratio = abs(q1 - q2) / abs(q2 - q3)
    lo, hi = 1e-3, 50.0
    f = lambda p: (h1 ** p - h2 ** p) / (h2 ** p - h3 ** p)   # noqa: E731 (increasing in p)
    if ratio <= f(lo) or ratio >= f(hi):
        return lo if ratio <= f(lo) else hi
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) < ratio else (lo, mid)
    return 0.5 * (lo + hi)


def richardson(values, sizes=(4.0, 2.0, 1.0), orders=(P_MIN, P_MAX)) -> Estimate:
    """The Estimate of three values on cell sizes `sizes` (coarse to fine, strictly decreasing), with the plausible
    observed orders `orders` (module docstring)."""
    if not sizes[0] > sizes[1] > sizes[2] > 0.0:
        raise ValueError(f"sizes: cell sizes must decrease strictly from coarse to fine, got {sizes!r}")
    q1, q2, q3 = values
    d1, d2 = q2 - q1, q3 - q2
    order, extrapolated, note = None, None, ""
    if d2 == 0.0:
        extrapolated, note = (q3, "") if d1 == 0.0 else (None, "the finest difference is zero")
    elif d1 * d2 < 0.0:
        note = "the differences change sign"
    elif abs(d2) >= abs(d1):
        note = "the differences do not shrink"
    else:
        order = observed_order(values, sizes)
        if not orders[0] <= order <= orders[1]:
            note = f"observed order {order:.2f} outside [{orders[0]:g}, {orders[1]:g}]"
        else:
            extrapolated = q3 + d2 / ((sizes[1] / sizes[2]) ** order - 1.0)
    if extrapolated == 0.0:
        extrapolated, note = None, "the extrapolated value is zero (no relative error)"
    if not note:
        return Estimate(order, extrapolated, "", [abs(q - extrapolated) / abs(extrapolated) for q in values])
    scale = abs(q3) or 1.0
    e3 = FS * abs(d2) / ((sizes[1] / sizes[2]) ** P_FORMAL - 1.0) / scale
    return Estimate(order, None, note, [abs(q1 - q3) / scale + e3, abs(q2 - q3) / scale + e3, e3])
