"""Speed profile eta2_ref(eta1): the fastest reference speed along the path that the vehicle's
limits allow, with bounded tangential acceleration and jerk. Time-invariant: a function of the
arclength eta1 only, precomputed once on an arclength grid.

On the path at speed ``V(s)`` (s: distance travelled, m) the reference motion's acceleration is
``a = sigma_ss V^2 + t_dir A`` with the tangential acceleration ``A = dV/dt = V dV/ds`` and the
thrust vector ``f = a + g e_z`` (world ENU, z up). The profile keeps

- ``g e_z + a / accel_share`` in the thrust set F of :class:`~pf_offboard.control.types.Limits`
  (tilt, min/max thrust): the reference uses at most ``accel_share`` of what the limits allow in
  that direction, the rest is left to the feedback;
- ``|A| <= max_tangential_accel_m_s2`` and ``|dA/dt| = |V dA/ds| <= max_tangential_jerk_m_s3``;
- ``V <= max_speed_m_s`` and the optional table of speeds over eta1;
- the roll/pitch rate of the reference thrust vector (eq. 25 with the on-path jerk) within
  ``max_body_rate_rad_s``;
- ``V = 0`` at the end of an open path (the end travelled towards).

Computation (``b = V^2``, ``db/ds = 2 A``, grid step ~2 cm): the largest feasible ``b`` at every
grid point (bisection on the line interval of F), a forward and a backward pass (the classic
time-optimal profile of a point mass; on a closed path repeated around the loop until periodic),
then jerk smoothing: a linear programme (HiGHS) for the b below the passes' result that keeps every
interval's acceleration in the interval feasible at the passes' speed and the second difference of
b within ``2 J ds^2 / V`` (V bounded above by the passes' speed, and by at least
:data:`JERK_FLOOR_SPEED_M_S`), minimising the lap time linearised (two rounds). Wherever the result's
acceleration is infeasible at its own (lower) speed the pointwise bound is lowered 3 % and the
passes and the programme repeated. At run time ``b`` is the uniform quadratic B-spline of the grid
values (C1, ``b''`` piecewise constant = the grid's second difference), so the bounds hold between
the grid points too; it gives ``V, dV/deta1, d2V/deta1^2``.

:func:`point_mass_lap_time` is the lower bound the profile is compared with: the same passes
without the jerk bound (a point mass under the same acceleration limits).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from pf_offboard.control.feasible import ThrustSet, _max, _min
from pf_offboard.control.types import GRAVITY_M_S2, Limits
from pf_offboard.errors import InputError

if TYPE_CHECKING:
    from pf_offboard.path import Path

G = GRAVITY_M_S2
MAX_PROFILE_SPEED_M_S = 20.0
GRID_STEP_M = 0.02  # arclength grid of the precomputation (finer on short paths)
MIN_GRID_POINTS = 200
MAX_GRID_POINTS = 20000
_FEASIBLE_TOL = 1e-9
_WITHIN_TOL = 1e-6  # a smoothed profile's acceleration counts as feasible this far outside its interval
JERK_FLOOR_SPEED_M_S = 0.25  # speed used in the jerk bound below it (m/s): see _jerk_smooth
# The vehicle's inner loop (its identified lag + delay, s) scales the share of the limits the
# reference may use: accel_share * RESPONSE_REFERENCE_S / (RESPONSE_REFERENCE_S + lag + delay), so
# a slower inner loop plans lower accelerations and leaves the feedback more room. An ideal inner
# loop keeps accel_share; the typical model (0.2 s) gets 5/7 of it (0.5 of the default 0.7): on
# the px4-sih mock at max_speed 3 m/s the full 0.7 saturated the speed loop 45-81 % of the flight
# (14-124 cm off the path), 0.5 flew 2.7-6.2 cm.
RESPONSE_REFERENCE_S = 0.5
# The jerk smoothing uses at most this share of ``max_body_rate_rad_s * g`` as its jerk bound: the
# tangential jerk alone turns the thrust vector at up to ~J/|f| (|f| ~ g), and lowering the speed
# cannot undo a tilt rate the jerk itself causes. Without this cap, a jerk bound above ~10x the rate
# bound (e.g. 30 m/s^3 with 3 rad/s) made the rate loop lower the speed until the 20 rounds ran out:
# 0.6-1.4 m/s planned instead of 2.2-2.7 on the held-out paths at max 3 m/s, and the tilt-rate bound
# still exceeded. 0.5 keeps the planned speed non-decreasing in the jerk bound (0.7 did not at
# accel_share 1) and leaves the defaults (10 m/s^3, 3 rad/s -> 14.7) unchanged.
JERK_RATE_SHARE = 0.5
# The inner loop's response (lag + dead time, s) bounds the jerk too: the smoothing plans with at
# most JERK_RESPONSE_BUDGET_M_S2 / response. A reference whose tangential acceleration turns at J
# (the speed's peaks between two corners, the braking into them) leaves about J x response of that
# acceleration unflown, and the vehicle enters the next corner too fast: its centripetal demand
# grows with the speed squared, the tilt saturates and no braking is left (real PX4 SIH, held-out
# figure-eight at max 3 m/s: at 10 m/s^3 9 of 20 flights went over 20 cm off the path, up to 34 cm,
# at the corner after a speed peak; at 6 m/s^3 none of 28, at 7 % less mean speed). The budget is
# planned with the response before any identification (the model's lag + dead time) in both
# plans: predicting the dead time keeps the feedback stable, but the vehicle still flies each
# change of acceleration that much later.
JERK_RESPONSE_BUDGET_M_S2 = 1.2


def response_jerk_m_s3(response_s: float) -> float:
    """The largest jerk (m/s^3) a reference may plan for an inner loop answering after
    ``response_s`` (lag + dead time; unbounded for the paper's ideal loop, 0)."""
    return math.inf if response_s <= 0.0 else JERK_RESPONSE_BUDGET_M_S2 / response_s


# Once the compensator flies an identified model with the model's lag (its dead time predicted by
# the identified amount, its gain and drag inverted: InnerLoopCompensator.identified), the share is
# discounted for the lag only: the follower re-plans with response_share(accel_share, lag),
# blended in over REPLAN_BLEND_S from the adoption (a smoothstep in time, no step in the reference
# speed). Before an adoption the model's lag + delay discount it. Discounting nothing (the whole
# accel_share) flew the mock px4-sih's tight held-out figure-eight 12.8 cm RMS / 59 cm max.
REPLAN_BLEND_S = 2.0


def replan_weight(elapsed_s: float) -> float:
    """Weight (0..1) of the re-planned profile ``elapsed_s`` after the adoption: a smoothstep over
    :data:`REPLAN_BLEND_S` (C1, largest slope 1.5 / REPLAN_BLEND_S per s)."""
    x = elapsed_s / REPLAN_BLEND_S
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    return x * x * (3.0 - 2.0 * x)


def response_share(accel_share: float, response_s: float) -> float:
    """The share of the limits a reference may use on an inner loop answering after ``response_s``."""
    return accel_share * RESPONSE_REFERENCE_S / (RESPONSE_REFERENCE_S + max(response_s, 0.0))


@dataclass(frozen=True)
class SpeedProfileSpec:
    """What the user asks of the speed profile (config section ``speed_profile``).

    ``max_speed_m_s``: the largest speed (m/s, > 0; the direction of travel is the sign of
    ``speed_m_s``). ``table_eta1_m_speed_m_s``: optional ((eta1_m, speed_m_s), ...) caps,
    interpolated linearly over eta1 (constant beyond an open path's table, periodic on a closed
    one). ``max_tangential_accel_m_s2`` / ``max_tangential_jerk_m_s3``: bounds on dV/dt and
    d2V/dt2 along the path (the smoothing plans with at most ``JERK_RATE_SHARE *
    max_body_rate_rad_s * g``: a larger jerk alone would turn the thrust vector too fast; and at
    most ``JERK_RESPONSE_BUDGET_M_S2 / response``: a slower inner loop flies a jerkier reference
    later). ``accel_share``: share (0, 1] of the limits the reference motion may
    use; the rest is the feedback's margin. ``max_body_rate_rad_s``: the speed is capped where the
    path's own jerk ``|sigma_sss| V^3`` would turn the thrust vector (|f| ~ g) faster than this
    (rates mode bounds the commanded rates: 3.5 rad/s by default).
    """

    max_speed_m_s: float
    table_eta1_m_speed_m_s: tuple[tuple[float, float], ...] = field(default=())
    max_tangential_accel_m_s2: float = 3.0
    max_tangential_jerk_m_s3: float = 10.0
    accel_share: float = 0.7
    max_body_rate_rad_s: float = 3.0

    def __post_init__(self) -> None:
        bounds = {
            "max_speed_m_s": (0.05, MAX_PROFILE_SPEED_M_S),
            "max_tangential_accel_m_s2": (0.05, 50.0),
            "max_tangential_jerk_m_s3": (0.1, 1000.0),
            "accel_share": (0.05, 1.0),
            "max_body_rate_rad_s": (0.1, 20.0),
        }
        for name, (lo, hi) in bounds.items():
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
                raise InputError(f"speed_profile.{name}", f"must be a number in [{lo:g}, {hi:g}], got {v!r}")
            object.__setattr__(self, name, float(v))
        table = tuple((float(a), float(b)) for a, b in self.table_eta1_m_speed_m_s)
        object.__setattr__(self, "table_eta1_m_speed_m_s", table)
        prev = -math.inf
        for i, (s, v) in enumerate(table):
            if not (math.isfinite(s) and math.isfinite(v)):
                raise InputError(f"speed_profile.table[{i}]", "must be finite numbers")
            if s < 0.0:
                raise InputError(f"speed_profile.table[{i}]", f"eta1 must be >= 0 m, got {s:g}")
            if s <= prev:
                raise InputError(f"speed_profile.table[{i}]", "eta1 values must be strictly increasing")
            if not 0.05 <= v <= MAX_PROFILE_SPEED_M_S:
                raise InputError(f"speed_profile.table[{i}]", f"speed must be in [0.05, {MAX_PROFILE_SPEED_M_S:g}] m/s, got {v:g}")
            prev = s


class ProfileStats(NamedTuple):
    """Figures of a computed profile (direction of travel, one lap / the whole open path)."""

    travel_time_s: float  # lap time (closed) or time from start to end (open) at the profile
    point_mass_time_s: float  # the same for the point-mass lower bound (no jerk bound)
    max_speed_m_s: float
    min_speed_m_s: float
    max_tangential_accel_m_s2: float  # on the grid
    max_tangential_jerk_m_s3: float  # on the grid, where V > 0.05 m/s
    max_accel_use: float  # largest share of the limits the reference motion uses (<= accel_share)
    max_tilt_rate_rad_s: float  # largest roll/pitch rate of the reference thrust vector (grid)
    max_tilt_deg: float  # largest tilt of the reference thrust vector g e_z + a_ref from vertical (grid)


# ---------------------------------------------------------------------------------- geometry
class _PathGeometry(NamedTuple):
    """What the grid needs of the path in one direction of travel (no speed caps): shared by the
    profiles planned on one path (:class:`SpeedProfile`'s ``like``)."""

    path: Path  # the path it was sampled from (identity checked before reuse)
    direction: float
    u: NDArray[np.float64]  # distance travelled at the grid points, m (0 .. L or L - ds)
    eta1: NDArray[np.float64]  # arclength at the grid points, m
    t_dir: NDArray[np.float64]  # (n, 3) unit tangent in the direction of travel
    s_ss: NDArray[np.float64]  # (n, 3) d2 sigma / ds2 (the same in both directions)
    ds: float
    s_sss: NDArray[np.float64]  # (n, 3) d3 sigma / ds3 in the direction of travel
    jerk_norm: NDArray[np.float64]  # (n,) max(|sigma_sss|, 1e-9)


class _Geometry(NamedTuple):
    u: NDArray[np.float64]  # distance travelled at the grid points, m (0 .. L or L - ds)
    t_dir: NDArray[np.float64]  # (n, 3) unit tangent in the direction of travel
    s_ss: NDArray[np.float64]  # (n, 3) d2 sigma / ds2 (the same in both directions)
    cap_b: NDArray[np.float64]  # (n,) speed cap squared (max speed, table)
    rate_cap_b: NDArray[np.float64]  # (n,) first guess of the body-rate cap squared
    ds: float
    s_sss: NDArray[np.float64]  # (n, 3) d3 sigma / ds3 in the direction of travel
    path_geo: _PathGeometry


def _path_geometry(path: Path, direction: float) -> _PathGeometry:
    L = float(path.length_m)
    n = int(min(MAX_GRID_POINTS, max(MIN_GRID_POINTS, math.ceil(L / GRID_STEP_M))))
    ds = L / n
    closed = bool(path.closed)
    u = np.arange(n if closed else n + 1) * ds
    eta1 = (L - u) % L if (direction < 0.0 and closed) else (L - u if direction < 0.0 else u)
    lam = np.array([path.lam_at_arclength(e) for e in eta1.tolist()])
    sp = path._spline
    d1 = sp.eval_vectorised(lam, 1)
    d2 = sp.eval_vectorised(lam, 2)
    d3 = sp.eval_vectorised(lam, 3)
    s2 = np.einsum("ij,ij->i", d1, d1)
    sn = np.sqrt(s2)
    sprime = np.einsum("ij,ij->i", d1, d2) / sn
    spp = (np.einsum("ij,ij->i", d2, d2) + np.einsum("ij,ij->i", d1, d3)) / sn - sprime**2 / sn
    t = d1 / sn[:, None]
    s_ss = d2 / s2[:, None] - d1 * (sprime / sn**3)[:, None]
    # sigma_sss (chain rule, as feedforward.onpath_derivatives)
    s_sss = (d3 / sn[:, None] ** 3 - 3.0 * d2 * (sprime / sn**4)[:, None]
             + d1 * ((-spp + 3.0 * sprime**2 / sn) / sn**4)[:, None])  # fmt: skip
    t_dir = t if direction >= 0.0 else -t
    jn = np.maximum(np.linalg.norm(s_sss, axis=1), 1e-9)
    return _PathGeometry(path, direction, u, eta1, t_dir, s_ss, ds, s_sss if direction >= 0.0 else -s_sss, jn)


def _geometry(path: Path, spec: SpeedProfileSpec, direction: float, path_geo: _PathGeometry | None = None) -> _Geometry:
    """The grid with the speed caps of ``spec``; ``path_geo``: this path's sampling in this
    direction already computed (another profile's), else sampled here."""
    if path_geo is None or path_geo.path is not path or (path_geo.direction >= 0.0) != (direction >= 0.0):
        path_geo = _path_geometry(path, direction)
    pg = path_geo
    cap = np.full(len(pg.u), spec.max_speed_m_s)
    # first guess of the body-rate bound: the path's jerk |sigma_sss| V^3 turning f ~ g
    rate_cap = np.cbrt(spec.max_body_rate_rad_s * G / pg.jerk_norm) ** 2
    if spec.table_eta1_m_speed_m_s:
        cap = np.minimum(cap, _table_speed(spec.table_eta1_m_speed_m_s, pg.eta1, float(path.length_m), bool(path.closed)))
    return _Geometry(pg.u, pg.t_dir, pg.s_ss, cap * cap, rate_cap, pg.ds, pg.s_sss, pg)


def _table_speed(table: tuple[tuple[float, float], ...], eta1: NDArray[np.float64], L: float, closed: bool) -> NDArray[np.float64]:
    xs = np.array([p[0] for p in table])
    vs = np.array([p[1] for p in table])
    if closed:
        if xs[-1] >= xs[0] + L:
            raise InputError("speed_profile.table", f"eta1 values must span less than one lap ({L:.3f} m) on a closed path")
        x = xs[0] + (eta1 - xs[0]) % L
        return np.interp(x, np.append(xs, xs[0] + L), np.append(vs, vs[0]))
    return np.interp(eta1, xs, vs)


# ---------------------------------------------------------------------------------- constraints
class _Feasible:
    """Tangential-acceleration interval at (grid point, b = V^2) under the scaled thrust set."""

    def __init__(self, geo: _Geometry, limits: Limits, spec: SpeedProfileSpec, response_s: float = 0.0) -> None:
        self.set = ThrustSet(limits.min_thrust_m_s2, limits.max_thrust_m_s2, limits.tan_tilt)
        self.inv_share = 1.0 / response_share(spec.accel_share, response_s)
        self.a_max = spec.max_tangential_accel_m_s2
        self.t = [tuple(r) for r in geo.t_dir.tolist()]
        self.k = [tuple(r) for r in geo.s_ss.tolist()]
        c = self.inv_share
        self._kx, self._ky, self._kz = (np.ascontiguousarray(geo.s_ss[:, i]) for i in range(3))
        self._tx, self._ty, self._tz = (np.ascontiguousarray(geo.t_dir[:, i]) for i in range(3))
        self._m = (self._tx * c, self._ty * c, self._tz * c)

    def intervals(self, b: NDArray[np.float64], idx: NDArray[np.intp] | None = None
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:  # fmt: skip
        """:meth:`interval` at every grid point i at ``b[i]`` (or at the points ``idx``, ``b`` then
        of their length): ``(lo, hi, ok)`` (lo, hi meaningless where not ok), equal to the
        scalar's bit for bit."""
        c = self.inv_share
        kx, ky, kz = (self._kx, self._ky, self._kz) if idx is None else (self._kx[idx], self._ky[idx], self._kz[idx])
        m = self._m if idx is None else (self._m[0][idx], self._m[1][idx], self._m[2][idx])
        lo, hi, empty = self.set.line_intervals((kx * b * c, ky * b * c, G + kz * b * c), m)
        a_max = self.a_max
        lo = np.where(-a_max > lo, -a_max, lo)
        hi = np.where(a_max < hi, a_max, hi)
        return lo, hi, ~empty & (lo <= hi + _FEASIBLE_TOL)

    def max_bs(self, cap: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`max_b` at every grid point (the same bisection, the points below their cap at once)."""
        out = cap.copy()
        idx = np.flatnonzero(~self.intervals(cap)[2])
        if len(idx) == 0:
            return out
        lo, hi = np.zeros(len(idx)), cap[idx]
        for _ in range(32):
            mid = 0.5 * (lo + hi)
            feasible = self.intervals(mid, idx)[2]
            hi = np.where(feasible, hi, mid)
            lo = np.where(feasible, mid, lo)
        out[idx] = lo
        return out

    def uses(self, b: NDArray[np.float64], a: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`use` at every grid point (the same bisection, all points at once)."""
        ax, ay, az = self._kx * b + self._tx * a, self._ky * b + self._ty * a, self._kz * b + self._tz * a
        n = len(b)
        lo, hi = np.zeros(n), np.ones(n)
        with np.errstate(all="ignore"):
            grow = ~self.set.contains_each(ax / hi, ay / hi, G + az / hi, 0.0) & (hi < 64.0)
            while grow.any():
                lo = np.where(grow, hi, lo)
                hi = np.where(grow, 2.0 * hi, hi)
                grow &= ~self.set.contains_each(ax / hi, ay / hi, G + az / hi, 0.0) & (hi < 64.0)
            for _ in range(40):
                mid = 0.5 * (lo + hi)
                inside = (mid > 0.0) & self.set.contains_each(ax / mid, ay / mid, G + az / mid, 0.0)
                hi = np.where(inside, mid, hi)
                lo = np.where(inside, lo, mid)
        return np.where((b == 0.0) & (a == 0.0), 0.0, hi)

    def interval(self, i: int, b: float) -> tuple[float, float] | None:
        """``{A : g e_z + (sigma_ss b + t A) / share in F, |A| <= a_max}`` or None."""
        k, t, c = self.k[i], self.t[i], self.inv_share
        iv = self.set.line_interval((k[0] * b * c, k[1] * b * c, G + k[2] * b * c), (t[0] * c, t[1] * c, t[2] * c))
        if iv is None:
            return None
        lo, hi = max(iv[0], -self.a_max), min(iv[1], self.a_max)
        return (lo, hi) if lo <= hi + _FEASIBLE_TOL else None

    def max_b(self, i: int, cap: float) -> float:
        """Largest b <= cap at which some tangential acceleration is feasible."""
        if self.interval(i, cap) is not None:
            return cap
        lo, hi = 0.0, cap
        for _ in range(32):
            mid = 0.5 * (lo + hi)
            if self.interval(i, mid) is None:
                hi = mid
            else:
                lo = mid
        return lo

    def use(self, i: int, b: float, a: float) -> float:
        """Share of the limits used by (b, A): the smallest r with g e_z + (...)/r in F (bisection)."""
        k, t = self.k[i], self.t[i]
        if b == 0.0 and a == 0.0:
            return 0.0
        ax, ay, az = k[0] * b + t[0] * a, k[1] * b + t[1] * a, k[2] * b + t[2] * a
        lo, hi = 0.0, 1.0
        while not self.set.contains((ax / hi, ay / hi, G + az / hi), 0.0) and hi < 64.0:
            lo, hi = hi, 2.0 * hi
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if mid > 0.0 and self.set.contains((ax / mid, ay / mid, G + az / mid), 0.0):
                hi = mid
            else:
                lo = mid
        return hi


def _passes(ub: NDArray[np.float64], feas: _Feasible, ds: float, closed: bool) -> NDArray[np.float64]:
    """Forward and backward passes: the largest b <= ub with db/ds = 2A, A feasible (point mass).

    Sequential; the intervals at the sweep's starting b are evaluated for all points at once and
    only the points the sweep itself lowered are evaluated again (the same values as evaluating
    every point in turn)."""
    bl = ub.tolist()
    n = len(bl)
    interval = feas.interval

    def bound(k: int, side: int, at_start: list[float], b0: list[float]) -> float:
        """Point k's interval end ``side`` (0: lo, 1: hi; 0 where infeasible) at its current b:
        the sweep's start evaluation unless the sweep lowered it since."""
        b = bl[k]
        if b == b0[k]:
            return at_start[k]
        iv = interval(k, b)
        return iv[side] if iv is not None else 0.0

    for _ in range(4 if closed else 1):
        changed = False
        # forward: what the vehicle can reach accelerating
        b0 = bl[:]
        _, his, oks = feas.intervals(np.array(b0))
        hi0 = np.where(oks, his, 0.0).tolist()
        rng = range(n) if closed else range(n - 1)
        for i in rng:
            j = i + 1 if i + 1 < n else 0
            lim = bl[i] + 2.0 * max(bound(i, 1, hi0, b0), 0.0) * ds
            if bl[j] > lim:
                bl[j] = lim
                changed = True
        # backward: what it can still stop from
        b0 = bl[:]
        los, _, oks = feas.intervals(np.array(b0))
        lo0 = np.where(oks, los, 0.0).tolist()
        for i in (range(n - 1, -1, -1) if closed else range(n - 2, -1, -1)):
            j = i + 1 if i + 1 < n else 0
            lim = bl[j] - 2.0 * min(bound(j, 0, lo0, b0), 0.0) * ds
            if bl[i] > lim:
                bl[i] = lim
                changed = True
        if not changed:
            break
    return np.maximum(np.array(bl), 0.0)


def _jerk_smooth(
    ub: NDArray[np.float64], feas: _Feasible, ds: float, jerk: float, closed: bool
) -> NDArray[np.float64] | None:
    """The jerk-bounded profile below ``ub`` (the passes' result): a linear programme in b.

    ``0 <= b <= ub``; the tangential acceleration of every grid interval ``(b_{i+1} - b_i)/(2 ds)``
    within the interval that is feasible at ``ub`` (the passes' speed); the jerk
    ``V (b_{i+1} - 2 b_i + b_{i-1}) / (2 ds^2)`` within +-J with V bounded by
    ``max(sqrt(ub_i), JERK_FLOOR_SPEED_M_S)`` (so the bound is conservative, and an open path's
    end is reached with V proportional to the distance left, like the stopping law). The objective
    is the lap time linearised around the previous solution (two rounds). None if the solver fails.
    """
    lo_p, hi_p, ok = feas.intervals(ub)
    b = _jerk_lp(ub.tobytes(), np.where(ok, lo_p, 0.0).tobytes(), np.where(ok, hi_p, 0.0).tobytes(), feas.a_max, ds, jerk, closed)
    return None if b is None else np.array(b)  # a copy: the cached one stays as it was solved


# The same linear programme comes back whenever a path, its limits and the response planned for
# are flown again (each flight of a sweep, a test's flights of one config): solved once per
# process. Keyed by the exact bytes of its inputs, so a hit returns what the solver would; one is
# 0.1-0.2 s of HiGHS on a shipped path, an entry some tens of kB (the last 64 kept).
@functools.lru_cache(maxsize=64)
def _jerk_lp(ub_bytes: bytes, lo_bytes: bytes, hi_bytes: bytes, a_max: float, ds: float, jerk: float,
             closed: bool) -> NDArray[np.float64] | None:  # fmt: skip
    """:func:`_jerk_smooth`'s programme from its inputs' bytes (``lo``, ``hi``: the feasible
    interval at ``ub``, 0 where there is none); the result is read-only."""
    from scipy.optimize import linprog
    from scipy.sparse import coo_matrix

    ub = np.frombuffer(ub_bytes, dtype=np.float64)
    lo_p, hi_p = np.frombuffer(lo_bytes, dtype=np.float64), np.frombuffer(hi_bytes, dtype=np.float64)
    n = len(ub)
    idx = np.arange(n)
    m = n if closed else n - 1  # intervals
    i0, i1 = idx[:m], (idx[:m] + 1) % n
    lo = _max(_max(lo_p[i0], lo_p[i1]), np.full(m, -a_max))
    hi = _min(_min(hi_p[i0], hi_p[i1]), np.full(m, a_max))
    hi = np.maximum(hi, 0.0)
    lo = np.minimum(lo, 0.0)
    # rows: (b_{i+1} - b_i) <= 2 ds hi ; -(b_{i+1} - b_i) <= -2 ds lo
    rows, cols, vals = [], [], []
    r = np.arange(m)
    rows += [r, r, m + r, m + r]
    cols += [i1, i0, i1, i0]
    vals += [np.ones(m), -np.ones(m), -np.ones(m), np.ones(m)]
    rhs = [2.0 * ds * hi, -2.0 * ds * lo]
    # jerk rows at interior points j (closed: all)
    j = idx if closed else idx[1:-1]
    nj = len(j)
    jm, jp = (j - 1) % n, (j + 1) % n
    v_bound = np.maximum(np.sqrt(np.maximum(ub[j], 0.0)), JERK_FLOOR_SPEED_M_S)
    cap = 2.0 * ds * ds * jerk / v_bound
    base = 2 * m
    rj = np.arange(nj)
    for sign, off in ((1.0, base), (-1.0, base + nj)):
        rows += [off + rj, off + rj, off + rj]
        cols += [jp, j, jm]
        vals += [sign * np.ones(nj), -2.0 * sign * np.ones(nj), sign * np.ones(nj)]
        rhs.append(cap)
    a_ub = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * m + 2 * nj, n)).tocsr()
    b_ub = np.concatenate(rhs)
    bounds = np.column_stack([np.zeros(n), ub])
    ref = np.maximum(ub, 1e-3)
    b = None
    for _ in range(2):
        w = ref ** -1.5
        res = linprog(-w, A_ub=a_ub, b_ub=b_ub, bounds=bounds, method="highs")
        if res.status != 0:
            break
        b = np.clip(res.x, 0.0, ub)
        b.setflags(write=False)
        ref = np.maximum(b, 1e-3)
    return b


def _derivatives(b: NDArray[np.float64], ds: float, closed: bool) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(A, jerk) on the grid by central differences of b (A = b'/2, jerk = V A')."""
    if closed:
        a = (np.roll(b, -1) - np.roll(b, 1)) / (4.0 * ds)
        da = (np.roll(a, -1) - np.roll(a, 1)) / (2.0 * ds)
    else:
        a = np.gradient(b, ds) / 2.0
        da = np.gradient(a, ds)
    return a, np.sqrt(np.maximum(b, 0.0)) * da


def _tilt_rate(b: NDArray[np.float64], geo: _Geometry, closed: bool) -> NDArray[np.float64]:
    """Roll/pitch rate (rad/s) of the reference thrust vector on the grid: |h| of eq. (25) with the
    on-path jerk ``sigma_sss V^3 + 3 sigma_ss V A + t V dA/ds`` (travel direction)."""
    a, jt = _derivatives(b, geo.ds, closed)
    v = np.sqrt(np.maximum(b, 0.0))
    j = geo.s_sss * (v**3)[:, None] + 3.0 * geo.s_ss * (v * a)[:, None] + geo.t_dir * jt[:, None]
    f = geo.s_ss * b[:, None] + geo.t_dir * a[:, None]
    f[:, 2] += G
    fn = np.linalg.norm(f, axis=1)
    z = f / fn[:, None]
    h = j - np.einsum("ij,ij->i", j, z)[:, None] * z
    return np.linalg.norm(h, axis=1) / fn


def _tilt_deg(b: NDArray[np.float64], geo: _Geometry, closed: bool) -> NDArray[np.float64]:
    """Tilt (deg) of the reference thrust vector ``g e_z + sigma_ss V^2 + t A`` on the grid."""
    a, _ = _derivatives(b, geo.ds, closed)
    f = geo.s_ss * b[:, None] + geo.t_dir * a[:, None]
    f[:, 2] += G
    return np.degrees(np.arctan2(np.hypot(f[:, 0], f[:, 1]), f[:, 2]))


def _travel_time(b: NDArray[np.float64], ds: float, closed: bool) -> float:
    v = np.sqrt(np.maximum(b, 0.0))
    v1 = np.roll(v, -1) if closed else v[1:]
    v0 = v if closed else v[:-1]
    s = v0 + v1
    return float(np.sum(np.where(s > 0.0, 2.0 * ds / np.where(s > 0.0, s, 1.0), math.inf)))


def _upper_bound(geo: _Geometry, feas: _Feasible, closed: bool) -> NDArray[np.float64]:
    """Pointwise largest feasible b (speed caps, limits; 0 at an open path's end)."""
    ub = feas.max_bs(geo.cap_b)
    if not closed:
        ub[-1] = 0.0
    return ub


# ---------------------------------------------------------------------------------- the profile
class SpeedProfile:
    """eta2_ref(eta1) and its eta1-derivatives for one path, direction and set of limits.

    ``evaluate(eta1) -> (speed, d speed / d eta1, d2 speed / d eta1^2)``: signed (the sign of
    ``direction``), m/s, 1/s, 1/(m s). On a closed path periodic in eta1; on an open path clamped
    to [0, L] (0 at the end travelled towards).
    """

    def __init__(self, path: Path, spec: SpeedProfileSpec, limits: Limits, direction: float, response_s: float = 0.0,
                 like: SpeedProfile | None = None, jerk_response_s: float | None = None) -> None:  # fmt: skip
        """``response_s``: the inner loop's lag + delay (s; 0: the paper's ideal one), which lowers
        the share of the limits the reference uses (:func:`response_share`) and the jerk it plans
        (:func:`response_jerk_m_s3`; ``jerk_response_s``, when given, for the jerk instead).
        ``like``: a profile planned on the same path whose sampling of the path is reused (the
        same plan, computed faster; ignored if its path or direction differ)."""
        self.spec = spec
        self.response_s = float(response_s)
        self.jerk_response_s = self.response_s if jerk_response_s is None else float(jerk_response_s)
        # the jerk the smoothing plans with (see JERK_RATE_SHARE and JERK_RESPONSE_BUDGET_M_S2)
        self.jerk_bound_m_s3 = min(spec.max_tangential_jerk_m_s3, JERK_RATE_SHARE * spec.max_body_rate_rad_s * G,
                                   response_jerk_m_s3(self.jerk_response_s))  # fmt: skip
        self.direction = 1.0 if direction >= 0.0 else -1.0
        self.closed = bool(path.closed)
        self.length_m = float(path.length_m)
        geo = _geometry(path, spec, self.direction, like._geo.path_geo if like is not None else None)
        feas = _Feasible(geo, limits, spec, self.response_s)
        closed = self.closed
        ub = _upper_bound(geo, feas, closed)
        self._pm_b = _passes(ub, feas, geo.ds, closed)  # the lower bound: acceleration limits only
        b = self._smoothed(np.minimum(ub, geo.rate_cap_b), geo, feas)
        self._b_travel = b
        self._geo = geo
        self._feas = feas
        # control points of b over eta1 (increasing), on the grid eta1_j = j ds
        if closed:
            c = b if self.direction > 0 else np.roll(b[::-1], 1)
        else:
            c = b if self.direction > 0 else b[::-1]
        self._c = c.tolist()
        self._n = len(c)
        self._ds = geo.ds
        ds = geo.ds
        a, jerk = _derivatives(b, ds, closed)
        moving = np.sqrt(np.maximum(b, 0.0)) > 0.05
        self.stats = ProfileStats(
            travel_time_s=_travel_time(b, ds, closed),
            point_mass_time_s=_travel_time(self._pm_b, ds, closed),
            max_speed_m_s=float(np.sqrt(b.max())),
            min_speed_m_s=float(np.sqrt(max(b.min(), 0.0))),
            max_tangential_accel_m_s2=float(np.abs(a).max()),
            max_tangential_jerk_m_s3=float(np.abs(jerk[moving]).max()) if moving.any() else 0.0,
            max_accel_use=float(feas.uses(b, a).max()),
            max_tilt_rate_rad_s=float(_tilt_rate(b, geo, closed).max()),
            max_tilt_deg=float(_tilt_deg(b, geo, closed).max()),
        )

    def _smoothed(self, ub: NDArray[np.float64], geo: _Geometry, feas: _Feasible) -> NDArray[np.float64]:
        """Passes + jerk smoothing; lowers ub where the smoothing left an infeasible acceleration."""
        ds, closed = geo.ds, self.closed
        ub = ub.copy()
        b = ub
        for _ in range(20):
            b_pass = _passes(ub, feas, ds, closed)
            smooth = _jerk_smooth(b_pass, feas, ds, self.jerk_bound_m_s3, closed)
            if smooth is None:
                raise InputError("speed_profile", "no jerk-bounded speed profile found (solver failed)")
            b = smooth
            a = (np.roll(b, -1) - b) / (2.0 * ds)
            lo, hi, ok = feas.intervals(b)
            tol = _WITHIN_TOL
            inside = ok & (lo - tol <= a) & (a <= hi + tol)  # point i, interval i
            after = np.roll(ok, -1) & (np.roll(lo, -1) - tol <= a) & (a <= np.roll(hi, -1) + tol)  # point i + 1
            good = inside & after
            bad = np.flatnonzero(~(good if closed else good[:-1])).tolist()
            ratio = _tilt_rate(b, geo, closed) / self.spec.max_body_rate_rad_s
            fast = np.flatnonzero(ratio > 1.0)
            if not bad and len(fast) == 0:
                return b
            for i in bad:
                ub[i] = 0.97 * min(ub[i], b[i])
            # the rate grows like V^3: lower b by the ratio^(2/3), a little more, over +-10 cm
            w = max(1, int(round(0.1 / ds)))
            for i in fast.tolist():
                k = np.arange(i - w, i + w + 1) % len(b) if closed else np.arange(max(i - w, 0), min(i + w + 1, len(b)))
                ub[k] = np.minimum(ub[k], 0.98 * b[i] * float(ratio[i]) ** (-2.0 / 3.0))
        return b

    # ------------------------------------------------------------------ runtime
    def evaluate(self, eta1: float) -> tuple[float, float, float]:
        """(eta2_ref m/s, d eta2_ref / d eta1 1/s, d2 eta2_ref / d eta1^2 1/(m s)) at arclength eta1 (m).

        b = eta2_ref^2 is the uniform quadratic B-spline of the grid values (control points at
        the grid points): C1, with b'' piecewise constant and equal to the grid's second
        difference, so the jerk bound of the grid holds between the grid points too."""
        L, ds, n, c = self.length_m, self._ds, self._n, self._c
        x = eta1 % L if self.closed else (0.0 if eta1 < 0.0 else (L if eta1 > L else eta1))
        u = x / ds
        i = int(math.floor(u + 0.5))
        tau = u - i
        if self.closed:
            cm, c0, cp = c[(i - 1) % n], c[i % n], c[(i + 1) % n]
        else:
            i = n - 1 if i > n - 1 else i
            c0 = c[i]
            cm = c[i - 1] if i > 0 else 2.0 * c[0] - c[1]
            cp = c[i + 1] if i < n - 1 else 2.0 * c[n - 1] - c[n - 2]
        lo, hi = 0.5 - tau, 0.5 + tau
        b = 0.5 * cm * lo * lo + c0 * (0.75 - tau * tau) + 0.5 * cp * hi * hi
        if b <= 1e-12:
            return 0.0, 0.0, 0.0
        db = (cp * hi - cm * lo - 2.0 * tau * c0) / ds
        ddb = (cm - 2.0 * c0 + cp) / (ds * ds)
        v = math.sqrt(b)
        dv = 0.5 * db / v
        ddv = (0.5 * ddb - dv * dv) / v
        s = self.direction
        return s * v, s * dv, s * ddv

    def speed_m_s(self, eta1: float) -> float:
        """|eta2_ref| at eta1 (m/s)."""
        return abs(self.evaluate(eta1)[0])


def point_mass_lap_time(path: Path, spec: SpeedProfileSpec, limits: Limits, direction: float = 1.0, response_s: float = 0.0,
                        like: SpeedProfile | None = None) -> float:  # fmt: skip
    """Travel time (s) of a point mass along the path under the profile's acceleration limits
    (thrust set scaled by ``accel_share``, ``max_tangential_accel``, speed caps) and no jerk bound:
    the lower bound for any profile with those limits (one lap on a closed path). ``like``: as
    :class:`SpeedProfile`'s."""
    geo = _geometry(path, spec, direction, like._geo.path_geo if like is not None else None)
    feas = _Feasible(geo, limits, spec, response_s)
    closed = bool(path.closed)
    return _travel_time(_passes(_upper_bound(geo, feas, closed), feas, geo.ds, closed), geo.ds, closed)


def vehicle_lap_time_bound(path: Path, limits: Limits, max_speed_m_s: float, direction: float = 1.0,
                           like: SpeedProfile | None = None) -> float:  # fmt: skip
    """The fastest a point mass can travel the path at the vehicle's limits (s; one lap on a closed
    path, start to end on an open one, stopping at the end): speed <= ``max_speed_m_s``, and its
    acceleration ``a`` anywhere such that ``g e_z + a`` is in the thrust set of ``limits`` (tilt, min
    / max thrust), so the tangential and normal accelerations are bounded jointly (on a level path
    ``a_t^2 + a_n^2 <= (g tan(max_tilt))^2``). No share kept for the feedback, no jerk bound, no
    tangential-acceleration bound of the profile's own: the lower bound of any lap flown within
    those limits (the forward-backward passes of :func:`point_mass_lap_time`; ``like``: as there)."""
    spec = SpeedProfileSpec(max_speed_m_s=min(float(max_speed_m_s), MAX_PROFILE_SPEED_M_S), max_tangential_accel_m_s2=50.0, accel_share=1.0)
    return point_mass_lap_time(path, spec, limits, direction, like=like)
