"""The belt of verify skin-mesh-vs-ellipsoids at reduced size: the triangulated cylinder's skin contract, the
drag bias's closed form, and Euler-Eytelwein through the mesh skin at the other wrap angle (pi / 2, tails not
vertical), which the case itself (theta = pi) does not run."""
import math

import numpy as np

from fabricfem.verify.skin_mesh import (
    BELT_TOLERANCE,
    MU,
    RADIUS,
    belt_rows,
    capstan_pull,
    cylinder_body,
    cylinder_skin,
    drag_bias,
)


def test_cylinder_skin_is_the_cylinder():
    """Every weight 1 on the one segment; the gap of points off the axis is their radius minus R to the
    inscribed polygon's sagitta R (1 - cos(pi / n)); the normal is radial to the facets' half angle."""
    sections = 200
    skin = cylinder_skin(cylinder_body(), sections=sections)
    assert np.all(skin.weights == 1.0)
    rng = np.random.default_rng(0)
    phi = rng.uniform(0.0, 2.0 * math.pi, 200)
    r = RADIUS + rng.uniform(-0.01, 0.01, 200)
    y = rng.uniform(-0.02, 0.02, 200)
    x = np.column_stack([r * np.cos(phi), y, r * np.sin(phi)])
    q = skin.query(x, 0.0)
    sagitta = RADIUS * (1.0 - math.cos(math.pi / sections))
    assert np.all(np.abs(q.gap - (r - RADIUS)) <= sagitta * (1.0 + 1e-9) + 1e-12)
    radial = np.column_stack([np.cos(phi), np.zeros_like(phi), np.sin(phi)])
    assert np.all((q.normal * radial).sum(axis=1) >= math.cos(math.pi / sections) - 1e-12)
    assert np.allclose(q.weights, 1.0)


def test_drag_bias_closed_form():
    """No damping, no bias; the bias grows linearly with the pull speed."""
    assert drag_bias(math.pi, damping=0.0) == 0.0
    b1, b2 = drag_bias(math.pi, speed=0.01), drag_bias(math.pi, speed=0.02)
    assert b1 > 0.0 and math.isclose(b2, 2.0 * b1, rel_tol=1e-12)


def test_belt_quarter_wrap_on_the_mesh_skin():
    """theta = pi / 2 on a 200-sided cylinder, 30 x 1 cells, pulled 4 mm: T2 / T1 within the case's 2 % of
    exp(mu pi / 2), the whole strip sliding (the loaded end within 5 % of the pull speed)."""
    r = capstan_pull(0.5 * math.pi, "mesh", nx=30, pull=4e-3, window=1.5e-3, sections=200)
    assert abs(r["ratio"] / math.exp(0.5 * MU * math.pi) - 1.0) < BELT_TOLERANCE, r
    assert abs(r["speed"] - 1.0) < 0.05, r
    assert r["penetration"] < 1e-6, r


def test_belt_rows_reduced():
    """The case's rows on the mesh skin (theta = pi) at reduced size all pass (30 x 1 cells, 200 sides, 4 mm)."""
    rows = belt_rows(nx=30, pull=4e-3, window=1.5e-3, sections=200, skins=("mesh",))
    assert len(rows) == 3 and all(r.passed for r in rows), [(r.quantity, r.value) for r in rows]
