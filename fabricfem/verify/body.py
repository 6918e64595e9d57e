"""Wearer geometry: the ellipsoid gap function against the exact point-to-ellipsoid distance."""
from __future__ import annotations

import numpy as np

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.verify import Timer, case, result

GAP_SEED = 20060501
# semi-axes in units of the smallest radius: a sphere, prolate/oblate spheroids and triaxial bodies
# up to the ratio 5 of the task
GAP_RADII = ((1.0, 1.0, 1.0), (5.0, 1.0, 1.0), (5.0, 5.0, 1.0), (5.0, 2.5, 1.0), (3.0, 1.0, 2.0), (1.0, 4.0, 5.0))


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def near_surface_points(ellipsoid: Ellipsoid, n: int, band: float, rng: np.random.Generator
                        ) -> tuple[np.ndarray, np.ndarray]:
    """n points x = p + d n(p): p on the surface (random directions scaled onto it), d uniform in
    [-band, band] (half inside, half outside). Returns (x, d)."""
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    p_local = u / np.sqrt(np.sum((u / ellipsoid.radii) ** 2, axis=1))[:, None]
    p = ellipsoid.to_global(p_local)
    d = rng.uniform(-band, band, n)
    return p + d[:, None] * ellipsoid.normal(p), d


@case("ellipsoid-gap")
def ellipsoid_gap(n_points: int = 20000, r_min: float = 0.05) -> list:
    """`Ellipsoid.gap` vs the exact distance of `Ellipsoid.closest_point` for random (seeded) points
    within 0.1 r_min of the surface, inside and outside, radius ratios up to 5: max |g - d| / |d| < 1 %
    (the task's accuracy requirement). The exact solver is itself checked against the construction
    distance: x = p + d n(p) is at distance |d| from the surface whenever |d| is below the smallest
    radius of curvature r_min^2 / r_max (here 0.1 r_min < 0.2 r_min); tolerance |exact - d| < 1e-12
    r_min (the construction and the converged Newton solve each carry round-off of ~1e-16 x the
    coordinates, <= 0.5 m, i.e. ~1e-15 r_min; 1e-12 leaves room without hiding a wrong root, whose
    error would be of the order of d itself)."""
    rng = np.random.default_rng(GAP_SEED)
    out = []
    for radii in GAP_RADII:
        with Timer() as timer:
            e = Ellipsoid(rng.normal(scale=0.1, size=3), _random_rotation(rng), r_min * np.array(radii))
            x, d = near_surface_points(e, n_points, 0.1 * r_min, rng)
            keep = np.abs(d) > 1e-6 * r_min  # relative errors are meaningless at d ~ round-off
            x, d = x[keep], d[keep]
            _, exact, _ = e.closest_point(x)
            gap, _ = e.gap(x)
        label = "x".join(f"{r:g}" for r in radii)
        for side, mask in (("outside", d > 0), ("inside", d < 0)):
            rel = np.max(np.abs(gap[mask] - exact[mask]) / np.abs(exact[mask]))
            out.append(result("ellipsoid-gap", f"radii {label}: max |gap - exact| / |exact| ({side})",
                              rel, 0.0, 0.01, int(mask.sum()), timer.elapsed, scale=1.0))
        err_exact = np.max(np.abs(exact - d)) / r_min
        out.append(result("ellipsoid-gap", f"radii {label}: max |exact - d| / r_min (offset construction)",
                          err_exact, 0.0, 1e-12, len(d), timer.elapsed, scale=1.0))
    return out
