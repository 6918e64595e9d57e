"""Plain-weave yarn geometry (pure numpy/scipy): sinusoidal centrelines, elliptic tubes.

Thesis ([Man2006], X. Man 2006) sec. 4.3.5: "the centerline of a yarn is
represented as a half wave of a sinusoidal curve [...] the half period and
the amplitude [...] identified using the yarn density and the crimp ratio"
(Kawabata's parameters y_0i and h_mi, sec. 4.1.2.1); "the cross section of a
yarn is assumed to be an ellipse with a radius ratio of 1.5".

Coordinates (metres): warp yarns run along x, weft yarns along y, z is the
fabric normal.  In the infinite fabric, warp yarn k lies in the plane
y = k * p_f with centreline z = (-1)^k A_w cos(pi x / p_w), and weft yarn m
lies in x = m * p_w with z = -(-1)^m A_f cos(pi y / p_f), so that at every
crossing the two yarns are on opposite sides of z = 0 (plain weave).  Here
p_w = warp.half_period (the projected warp length between two crossings,
Kawabata's y_01, equal to the weft spacing) and p_f = weft.half_period.

The cross-section of a yarn is the ellipse with semi-axes a = width / 2
(along the binormal, in the fabric plane) and b = height / 2 (along the
principal normal), in the plane perpendicular to the centreline tangent.

Unit cells [Man2006, Fig. 19a]: option B, ``"quarter"``, is
[-p_w/2, p_w/2] x [-p_f/2, p_f/2] and holds the half waves of warp 0 and
weft 0 crossing at the origin, cut at their inflection points; the structure
repeats anti-symmetrically (translation by a half period with z -> -z).
Option A, ``"full"``, is [-p_w/2, 3p_w/2] x [-p_f/2, 3p_f/2] with warp 0, 1
and weft 0, 1 over one full period each; it repeats by translation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import integrate, optimize

from . import _validate

OPTIONS = ("quarter", "full")
CRIMP_MODELS = ("sinusoid", "kawabata")


_positive = _validate.positive


_non_negative = _validate.non_negative


def sinusoid_arc_length(half_period: float, amplitude: float, start: float, end: float) -> float:
    """Arc length (m) of z = A cos(pi s / p) for s in [start, end], by adaptive quadrature."""
    k = math.pi / half_period
    value, _ = integrate.quad(lambda s: math.sqrt(1.0 + (amplitude * k * math.sin(k * s)) ** 2),
                              start, end, epsabs=0.0, epsrel=1e-13, limit=200)
    return value


def amplitude_from_crimp(half_period: float, crimp: float, model: str = "sinusoid") -> float:
    """Crimp height h_m (m) of a yarn with half period ``half_period`` and crimp ratio ``crimp``.

    The crimp ratio is (yarn length - projected length) / projected length.

    * ``"sinusoid"``: the centreline z = h_m cos(pi s / p) has arc length
      (1 + crimp) p over one half period (solved numerically), so the
      meshed yarn has exactly the requested crimp.
    * ``"kawabata"``: Kawabata's straight segments rising 2 h_m over y_0
      ([Man2006, eq. 4.1], l_0 = sqrt(4 h_m^2 + y_0^2)):
      h_m = (y_0 / 2) sqrt((1 + crimp)^2 - 1).
    """
    p = _positive("half_period", half_period)
    c = _non_negative("crimp", crimp)
    if model not in CRIMP_MODELS:
        raise ValueError(f"model: unknown crimp model {model!r}; expected one of {list(CRIMP_MODELS)}")
    if c == 0.0:
        return 0.0
    if model == "kawabata":
        # thesis eq. (4.1): yarn length sqrt(4 h_m^2 + y_0^2) over projected length y_0
        return 0.5 * p * math.sqrt((1.0 + c) ** 2 - 1.0)
    # arc length >= 2 A over a half period, so A <= (1 + c) p / 2 brackets the root
    return optimize.brentq(lambda a: sinusoid_arc_length(p, a, 0.0, p) / p - 1.0 - c,
                           0.0, 0.5 * (1.0 + c) * p + p, xtol=1e-15 * p, rtol=1e-14)


@dataclass(frozen=True)
class YarnFamily:
    """Geometry of one yarn family (warp or weft), SI units (m).

    Attributes:
        half_period: p, projected centreline length between two successive
            crossings (Kawabata's y_0i), equal to the spacing of the
            crossing yarn family; > 0.
        amplitude: A, crimp height h_mi: the centreline is z = +-A cos(pi s / p); >= 0.
        width: 2a, in-plane axis of the elliptic cross-section; > 0.
        height: 2b, out-of-plane axis of the cross-section; > 0.
    """

    half_period: float = 1.0e-3
    amplitude: float = 0.2e-3
    width: float = 0.5e-3
    height: float = 0.5e-3 / 1.5

    def __post_init__(self) -> None:
        object.__setattr__(self, "half_period", _positive("half_period", self.half_period))
        object.__setattr__(self, "amplitude", _non_negative("amplitude", self.amplitude))
        object.__setattr__(self, "width", _positive("width", self.width))
        object.__setattr__(self, "height", _positive("height", self.height))

    @classmethod
    def from_crimp(cls, half_period: float, crimp: float, width: float, aspect_ratio: float = 1.5,
                   model: str = "sinusoid") -> "YarnFamily":
        """Yarn from Kawabata's measurable parameters.

        Args:
            half_period: 1 / (number of crossing yarns per metre), m.
            crimp: crimp ratio (yarn length / fabric length - 1), >= 0.
            width: in-plane axis 2a of the cross-section, m.
            aspect_ratio: width / height (thesis: 1.5), > 0.
            model: how crimp maps to amplitude, see :func:`amplitude_from_crimp`.
        """
        ratio = _positive("aspect_ratio", aspect_ratio)
        w = _positive("width", width)
        return cls(half_period, amplitude_from_crimp(half_period, crimp, model), w, w / ratio)

    @property
    def semi_width(self) -> float:
        """a = width / 2 (m)."""
        return 0.5 * self.width

    @property
    def semi_height(self) -> float:
        """b = height / 2 (m)."""
        return 0.5 * self.height

    @property
    def aspect_ratio(self) -> float:
        """width / height."""
        return self.width / self.height

    @property
    def section_area(self) -> float:
        """Ellipse area pi a b (m^2)."""
        return math.pi * self.semi_width * self.semi_height

    @property
    def crimp(self) -> float:
        """Crimp ratio of the sinusoidal centreline: arc length / half period - 1."""
        return sinusoid_arc_length(self.half_period, self.amplitude, 0.0, self.half_period) / self.half_period - 1.0

    @property
    def max_curvature(self) -> float:
        """Largest centreline curvature A pi^2 / p^2 (1/m), at the crests."""
        return self.amplitude * (math.pi / self.half_period) ** 2


def _default_yarn() -> YarnFamily:
    return YarnFamily()


@dataclass(frozen=True)
class YarnPath:
    """One yarn of a unit cell: an elliptic tube around a sinusoidal centreline.

    Centreline, with s the coordinate along ``axis`` (0: x, warp; 1: y, weft)::

        c(s) = s e_axis + offset e_other + sign * A cos(pi s / p) e_z

    Local frame: unit tangent T(s), in-plane binormal B (+y for warp, -x for
    weft; constant), principal normal N = T x B, so that (T, B, N)
    is right-handed and N has a positive z component.  A point is
    c(s) + u B + v N with the section coordinates (u, v); the yarn is
    (u / a)^2 + (v / b)^2 <= 1.  ``start``, ``end`` bound s for the meshed piece.
    """

    name: str
    family: YarnFamily
    axis: int
    offset: float
    sign: float
    start: float
    end: float

    @property
    def binormal(self) -> np.ndarray:
        """Constant in-plane binormal B (3,)."""
        return np.array([0.0, 1.0, 0.0]) if self.axis == 0 else np.array([-1.0, 0.0, 0.0])

    def height(self, s: np.ndarray) -> np.ndarray:
        """Centreline z(s) (m)."""
        k = math.pi / self.family.half_period
        return self.sign * self.family.amplitude * np.cos(k * s)

    def slope(self, s: np.ndarray) -> np.ndarray:
        """dz/ds."""
        k = math.pi / self.family.half_period
        return -self.sign * self.family.amplitude * k * np.sin(k * s)

    def centre(self, s: np.ndarray) -> np.ndarray:
        """Centreline points (n, 3)."""
        s = np.asarray(s, dtype=np.float64)
        c = np.empty(s.shape + (3,))
        c[..., self.axis] = s
        c[..., 1 - self.axis] = self.offset
        c[..., 2] = self.height(s)
        return c

    def tangent(self, s: np.ndarray) -> np.ndarray:
        """Unit tangents (n, 3) in the direction of increasing s."""
        dz = self.slope(np.asarray(s, dtype=np.float64))
        norm = np.sqrt(1.0 + dz * dz)
        t = np.zeros(dz.shape + (3,))
        t[..., self.axis] = 1.0 / norm
        t[..., 2] = dz / norm
        return t

    def normal(self, s: np.ndarray) -> np.ndarray:
        """Unit principal normals N (n, 3) in the vertical plane, N_z > 0."""
        dz = self.slope(np.asarray(s, dtype=np.float64))
        norm = np.sqrt(1.0 + dz * dz)
        n = np.zeros(dz.shape + (3,))
        n[..., self.axis] = -dz / norm
        n[..., 2] = 1.0 / norm
        return n

    def arc_length(self) -> float:
        """Centreline length of the meshed piece (m), by quadrature."""
        f = self.family
        return sinusoid_arc_length(f.half_period, f.amplitude, self.start, self.end)

    def volume(self) -> float:
        """Exact volume of the meshed piece: pi a b x arc length (m^3).

        Exact for a tube whose planar sections are perpendicular to a planar
        centreline through their centroids, while the tube does not overlap
        itself (b * max curvature < 1, checked by :func:`check_weave`).
        """
        return self.family.section_area * self.arc_length()

    def section_coordinates(self, x: np.ndarray, n_scan: int = 33) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Section coordinates (s, u, v) of points ``x`` (n, 3) w.r.t. the infinite tube.

        Solves (x - c(s)) . T(s) = 0 for s in the window |s - x_axis| <= b
        (every point of the tube lies there: |x_axis - s| = |v| |N_axis| <= b),
        scanning ``n_scan`` samples for sign changes and refining each root by
        bisection; among several roots the one with the smallest
        (u/a)^2 + (v/b)^2 is kept.  Points without a root get s = nan and
        v = inf (they are outside the tube).
        """
        x = np.asarray(x, dtype=np.float64).reshape(-1, 3)
        b = self.family.semi_height
        xs, xz = x[:, self.axis], x[:, 2]
        binormal = self.binormal
        u = x @ binormal - self.offset * binormal[1 - self.axis]
        window = b * (1.0 + 1e-9) + 1e-12 * self.family.half_period
        grid = xs[:, None] + np.linspace(-window, window, n_scan)[None, :]

        def residual(t: np.ndarray, px: np.ndarray, pz: np.ndarray) -> np.ndarray:
            # (x - c(t)) . (1, dz/dt): foot-point condition, zero where x - c is normal to the curve
            return (px - t) + (pz - self.height(t)) * self.slope(t)

        f = residual(grid, xs[:, None], xz[:, None])
        change = (f[:, :-1] * f[:, 1:]) <= 0.0
        point, interval = np.nonzero(change)
        lo = grid[point, interval]
        hi = grid[point, interval + 1]
        f_lo = f[point, interval]
        px, pz = xs[point], xz[point]
        for _ in range(60):  # bisection: the bracket shrinks 2^-60, below round-off
            mid = 0.5 * (lo + hi)
            f_mid = residual(mid, px, pz)
            left = f_lo * f_mid <= 0.0
            hi = np.where(left, mid, hi)
            lo = np.where(left, lo, mid)
            f_lo = np.where(left, f_lo, f_mid)
        root = 0.5 * (lo + hi)
        dz = self.slope(root)
        v_root = ((pz - self.height(root)) - (px - root) * dz) / np.sqrt(1.0 + dz * dz)
        a = self.family.semi_width
        level_root = (u[point] / a) ** 2 + (v_root / b) ** 2
        order = np.lexsort((level_root, point))  # per point, smallest level first
        point, root, v_root = point[order], root[order], v_root[order]
        first = np.ones(point.size, dtype=bool)
        first[1:] = point[1:] != point[:-1]
        s = np.full(x.shape[0], np.nan)
        v = np.full(x.shape[0], np.inf)
        s[point[first]] = root[first]
        v[point[first]] = v_root[first]
        return s, u, v

    def level(self, x: np.ndarray) -> np.ndarray:
        """(u/a)^2 + (v/b)^2 of points ``x`` (n, 3): < 1 inside the (infinite) tube, inf far away."""
        _, u, v = self.section_coordinates(x)
        return (u / self.family.semi_width) ** 2 + (v / self.family.semi_height) ** 2

    def surface_points(self, n_along: int, n_around: int) -> np.ndarray:
        """Points (n_along * n_around, 3) on the exact tube surface over [start, end]."""
        s = np.linspace(self.start, self.end, n_along)
        theta = np.linspace(0.0, 2.0 * np.pi, n_around, endpoint=False)
        u = self.family.semi_width * np.cos(theta)
        v = self.family.semi_height * np.sin(theta)
        pts = (self.centre(s)[:, None, :] + u[None, :, None] * self.binormal[None, None, :]
               + v[None, :, None] * self.normal(s)[:, None, :])
        return pts.reshape(-1, 3)


@dataclass(frozen=True)
class PlainWeave:
    """Plain-weave geometry with independent warp (along x) and weft (along y) yarns.

    The warp yarns are spaced ``weft.half_period`` apart (along y) and the
    weft yarns ``warp.half_period`` apart (along x).  Construct directly from
    amplitudes, or from crimp ratios with :meth:`YarnFamily.from_crimp`, or
    with :meth:`balanced` from the thesis parameters (sec. 4.3.5).
    """

    warp: YarnFamily = field(default_factory=_default_yarn)
    weft: YarnFamily = field(default_factory=_default_yarn)

    def __post_init__(self) -> None:
        for name in ("warp", "weft"):
            if not isinstance(getattr(self, name), YarnFamily):
                raise ValueError(f"{name}: must be a YarnFamily, got {getattr(self, name)!r}")

    @classmethod
    def balanced(cls, half_period: float = 1.0e-3, crimp: float = 0.08, volume_fraction: float = 0.4,
                 aspect_ratio: float = 1.5, crimp_model: str = "sinusoid") -> "PlainWeave":
        """Balanced weave (warp = weft) as in [Man2006, sec. 4.3.5.]

        From the thesis ([Man2006], line ~2147-2149): sinusoidal half-wave centrelines, warp = weft,
        elliptic section with radius ratio 1.5, volume fraction phi = 0.4. The thesis gives no
        numbers for the yarn spacing (half period), the crimp ratio or the gap between the yarns
        (it only says they follow from the yarn density and crimp ratio, Kawabata), so
        half_period = 1 mm and crimp = 0.08 are this code's assumptions; the homogenized S does
        not depend on half_period (no material length), only on crimp, aspect ratio and phi.

        The yarn width is solved so that the quarter-cell yarn volume over
        the bounding box is ``volume_fraction`` ([Man2006, eq. 4.65], phi = 0.4),
        the box height being the fabric thickness 2 (A + b).

        Args:
            half_period: projected yarn length between crossings (m).
            crimp: crimp ratio, >= 0.
            volume_fraction: phi = |Y_s| / |Y| (eq. 4.65), in (0, 1); ValueError
                naming it if the resulting yarns would overlap (:func:`check_weave`).
            aspect_ratio: width / height of the cross-section (thesis: 1.5).
            crimp_model: see :func:`amplitude_from_crimp`.
        """
        p = _positive("half_period", half_period)
        ratio = _positive("aspect_ratio", aspect_ratio)
        phi = float(volume_fraction)
        if not (math.isfinite(phi) and 0.0 < phi < 1.0):
            raise ValueError(f"volume_fraction: must be in (0, 1), got {volume_fraction!r}")
        amplitude = amplitude_from_crimp(p, crimp, crimp_model)
        length = sinusoid_arc_length(p, amplitude, -0.5 * p, 0.5 * p)

        def fraction(width: float) -> float:
            a, b = 0.5 * width, 0.5 * width / ratio
            # eq. (4.65): two half waves of section pi a b in the box p x p x 2 (A + b)
            return 2.0 * math.pi * a * b * length / (p * p * 2.0 * (amplitude + b))

        widest = p  # neighbouring parallel yarns touch at width = spacing
        if fraction(widest) <= phi:
            raise ValueError(f"volume_fraction: {phi} is not reachable with yarns narrower than the "
                             f"spacing {p} m (at most {fraction(widest):.3f} for crimp {crimp}, "
                             f"aspect_ratio {ratio})")
        width = optimize.brentq(lambda w: fraction(w) - phi, 1e-9 * p, widest, xtol=1e-15 * p)
        yarn = YarnFamily(p, amplitude, width, width / ratio)
        weave = cls(yarn, yarn)
        try:
            check_weave(weave)
        except ValueError as error:
            raise ValueError(f"volume_fraction: {phi} with crimp {crimp} and aspect_ratio {ratio} needs "
                             f"yarns {width:.4g} m wide that do not fit: {error}") from None
        return weave

    def half_thickness(self) -> float:
        """Half the fabric thickness max(A_w + b_w, A_f + b_f) (m)."""
        return max(self.warp.amplitude + self.warp.semi_height, self.weft.amplitude + self.weft.semi_height)

    def cell_bounds(self, option: str) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper corners (3,) of the unit-cell bounding box (m)."""
        _option(option)
        pw, pf, h = self.warp.half_period, self.weft.half_period, self.half_thickness()
        n = 1.0 if option == "quarter" else 2.0
        lower = np.array([-0.5 * pw, -0.5 * pf, -h])
        return lower, lower + np.array([n * pw, n * pf, 2.0 * h])

    def yarns(self, option: str) -> tuple[YarnPath, ...]:
        """The yarn pieces of unit cell ``option`` ([Man2006, Fig. 19a]: quarter = B, full = A)."""
        _option(option)
        pw, pf = self.warp.half_period, self.weft.half_period
        if option == "quarter":
            return (YarnPath("warp0", self.warp, 0, 0.0, 1.0, -0.5 * pw, 0.5 * pw),
                    YarnPath("weft0", self.weft, 1, 0.0, -1.0, -0.5 * pf, 0.5 * pf))
        return (YarnPath("warp0", self.warp, 0, 0.0, 1.0, -0.5 * pw, 1.5 * pw),
                YarnPath("warp1", self.warp, 0, pf, -1.0, -0.5 * pw, 1.5 * pw),
                YarnPath("weft0", self.weft, 1, 0.0, -1.0, -0.5 * pf, 1.5 * pf),
                YarnPath("weft1", self.weft, 1, pw, 1.0, -0.5 * pf, 1.5 * pf))

    def yarn_volume(self, option: str) -> float:
        """Exact total yarn volume of the unit cell (m^3), see :meth:`YarnPath.volume`."""
        return sum(y.volume() for y in self.yarns(option))

    def volume_fraction(self, option: str = "quarter") -> float:
        """phi = |Y_s| / |Y| of the exact geometry [Man2006, eq. 4.65]."""
        lower, upper = self.cell_bounds(option)
        return self.yarn_volume(option) / float(np.prod(upper - lower))


def _option(option: str) -> str:
    if option not in OPTIONS:
        raise ValueError(f"option: unknown unit cell {option!r}; expected one of {list(OPTIONS)}")
    return option


def _neighbourhood(weave: PlainWeave) -> list[YarnPath]:
    """Yarns of the infinite fabric near the full cell: warp k = -1..2, weft m = -1..2."""
    pw, pf = weave.warp.half_period, weave.weft.half_period
    lo_w, hi_w = -1.5 * pw, 2.5 * pw
    lo_f, hi_f = -1.5 * pf, 2.5 * pf
    warps = [YarnPath(f"warp{k}", weave.warp, 0, k * pf, (-1.0) ** k, lo_w, hi_w) for k in range(-1, 3)]
    wefts = [YarnPath(f"weft{m}", weave.weft, 1, m * pw, -(-1.0) ** m, lo_f, hi_f) for m in range(-1, 3)]
    return warps + wefts


def check_weave(weave: PlainWeave, n_along: int = 240, n_around: int = 48) -> float:
    """Raise ValueError if the yarns of the (infinite) weave overlap; return the clearance.

    Checks, in this order:

    1. parallel yarns: width < spacing of that family (``warp.width`` <
       ``weft.half_period``, ``weft.width`` < ``warp.half_period``);
    2. each tube is free of self-overlap: b * max curvature = b A pi^2 / p^2 < 1
       (names ``amplitude``: crimp too large for the half period and height);
    3. crossing yarns: points sampled on the exact surface of warp 0, 1 and
       weft 0, 1 over one period (``n_along`` x ``n_around`` each) must lie
       outside every other yarn of the fabric (implicit function
       (u/a)^2 + (v/b)^2 > 1).  If some lies inside, the error names the
       amplitudes: too small if the crossing gap A_w + A_f - b_w - b_f is not
       positive, otherwise the crimp is too large for the spacing and yarn
       thickness (the steep flanks cut into the crossing yarn).

    The sampling spacing (period / n_along along, 2 pi b / n_around around)
    bounds the size of an overlap that could go unnoticed.

    Returns:
        The smallest level (u/a)^2 + (v/b)^2 of any sample in another yarn
        (> 1; inf if no sample comes near another yarn).
    """
    w, f = weave.warp, weave.weft
    if w.width >= f.half_period:
        raise ValueError(f"warp.width: {w.width} m must be less than the warp spacing "
                         f"weft.half_period = {f.half_period} m (neighbouring warp yarns overlap)")
    if f.width >= w.half_period:
        raise ValueError(f"weft.width: {f.width} m must be less than the weft spacing "
                         f"warp.half_period = {w.half_period} m (neighbouring weft yarns overlap)")
    for name, y in (("warp", w), ("weft", f)):
        if y.semi_height * y.max_curvature >= 1.0:
            raise ValueError(
                f"{name}.amplitude: crimp too large: the smallest radius of curvature p^2/(pi^2 A) = "
                f"{1.0 / y.max_curvature:.4g} m is not larger than the half height b = {y.semi_height:.4g} m "
                f"(half_period {y.half_period} m), so the yarn overlaps itself")
    near = _neighbourhood(weave)
    pw, pf = w.half_period, f.half_period
    samples = {}
    for y in near:
        if y.name in ("warp0", "warp1", "weft0", "weft1"):
            piece = YarnPath(y.name, y.family, y.axis, y.offset, y.sign,
                             -0.5 * (pw if y.axis == 0 else pf), 1.5 * (pw if y.axis == 0 else pf))
            samples[y.name] = piece.surface_points(n_along, n_around)
    clearance = math.inf
    for name, pts in samples.items():
        for other in near:
            if other.name == name:
                continue
            # cheap prefilter: |u| < a (u is exact, the binormal is constant) and |z| < A + b
            a = other.family.semi_width
            u = pts[:, 1 - other.axis] - other.offset
            close = (np.abs(u) < a) & (np.abs(pts[:, 2]) < other.family.amplitude + other.family.semi_height)
            if not np.any(close):
                continue
            level = other.level(pts[close])
            clearance = min(clearance, float(np.min(level)))
            if np.any(level <= 1.0):
                gap = w.amplitude + f.amplitude - w.semi_height - f.semi_height
                if gap <= 0.0:
                    raise ValueError(
                        f"amplitude: yarns {name} and {other.name} interpenetrate at the crossing: "
                        f"warp.amplitude + weft.amplitude = {w.amplitude + f.amplitude:.4g} m is not larger "
                        f"than the half heights b_w + b_f = {w.semi_height + f.semi_height:.4g} m")
                raise ValueError(
                    f"amplitude: yarns {name} and {other.name} interpenetrate: crimp amplitude too large "
                    f"for the spacing and yarn thickness (warp: A = {w.amplitude:.4g} m, p = {pw:.4g} m, "
                    f"width {w.width:.4g} m, height {w.height:.4g} m; weft: A = {f.amplitude:.4g} m, "
                    f"p = {pf:.4g} m, width {f.width:.4g} m, height {f.height:.4g} m)")
    return clearance
