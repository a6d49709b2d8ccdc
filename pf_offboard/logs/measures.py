"""What the vehicle did along the path, measured one way everywhere (summary, replay, reports).

- **Speed along the path** is taken from the *position*: its central difference over
  ±:data:`DERIVATIVE_HALF_WINDOW_S` (positions interpolated at ``t - h`` and ``t + h``), projected
  on the path's unit tangent at the step's closest point, signed like η2 (positive along
  increasing λ). An estimator's velocity can be biased while its position is not (PX4's EKF2 on
  SIH: its horizontal velocity reads several cm/s off what the position does); the estimator's
  own figure (η2 from the velocity the controller used) is reported beside it.
- **Converged**: the first time the cross-track error stays ≤ :data:`CONVERGED_TOL_M` for
  :data:`CONVERGED_HOLD_S` without a break; the convergence time is from activation to the start
  of that stretch.
- **Lap times** (closed paths): the time of each whole lap from activation, lap *k* ending when
  the net progress along the path (η1 unwrapped, in the direction of travel) first reaches *k*
  path lengths (interpolated between steps); the first lap includes the approach. Reported beside
  the point-mass bound at the vehicle's limits (:meth:`pf_offboard.control.PathFollower.lap_time_bound_s`).
- **Windows**: "from activation + 8 s" (:data:`SETTLE_S`: what the docs quote) and "whole
  flight" (every active step from activation on). Every figure is given with its window's name.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

SETTLE_S = 8.0
DERIVATIVE_HALF_WINDOW_S = 0.1
CONVERGED_TOL_M = 0.10
CONVERGED_HOLD_S = 1.0

WINDOW_SETTLED = "from activation + 8 s"


def settled_window(settle_s: float) -> str:
    """The name of the window from activation + ``settle_s``."""
    return f"from activation + {settle_s:g} s"

WINDOW_WHOLE = "whole flight"
CONVERGED_DEFINITION = f"first time the cross-track error stays <= {100 * CONVERGED_TOL_M:g} cm for {CONVERGED_HOLD_S:g} s"

Tangent = Callable[[float], NDArray[np.float64]]


def final_slowdown(speed_ref_m_s: Sequence[float], after: Sequence[bool], share: float = 0.99) -> NDArray[np.bool_]:
    """Where the reference speed has begun its final slow-down for an open path's end, among the
    samples ``after`` marks: below ``share`` of its largest value so far among them and never above
    it again (by more than 1 cm/s) until the end. A reference that dips and rises again (a speed
    profile re-planned in flight, blended in from its adoption) is not the end's slow-down, nor is
    a cruise a little below a peak before ``after`` (the start ramp's)."""
    ref = np.abs(np.asarray(speed_ref_m_s, dtype=float))
    if ref.size == 0:
        return np.zeros(0, dtype=bool)
    inside = np.asarray(after, dtype=bool)
    so_far = np.maximum.accumulate(np.where(inside, ref, 0.0))
    later = np.append(np.maximum.accumulate(ref[::-1])[::-1][1:], 0.0)  # the largest after each sample
    return inside & (ref < share * so_far) & (later <= ref + 0.01)


def path_tangent(path: Any) -> Tangent:
    """``lam -> unit tangent`` (ENU) of a :class:`pf_offboard.path.Path`."""

    def tangent(lam: float) -> NDArray[np.float64]:
        d1 = np.asarray(path.eval(path.wrap(lam)).d1, dtype=float)
        n = float(np.linalg.norm(d1))
        return d1 / n if n > 0.0 else np.full(3, math.nan)

    return tangent


def position_speed_along_path(
    time_s: NDArray[np.float64], position_enu_m: NDArray[np.float64], tangents: NDArray[np.float64],
    half_window_s: float = DERIVATIVE_HALF_WINDOW_S,
) -> NDArray[np.float64]:  # fmt: skip
    """Speed along the path (m/s) at each sample from the position's central difference over
    ±``half_window_s`` (linear interpolation between samples), projected on ``tangents`` (N, 3,
    unit). NaN where ``t ± h`` falls outside the samples."""
    t = np.asarray(time_s, dtype=float)
    p = np.asarray(position_enu_m, dtype=float)
    out = np.full(len(t), math.nan)
    if len(t) < 2:
        return out
    order = np.argsort(t, kind="stable")
    ts, ps = t[order], p[order]
    lo, hi = t - half_window_s, t + half_window_s
    ok = (lo >= ts[0]) & (hi <= ts[-1])
    if not ok.any():
        return out
    before = np.column_stack([np.interp(lo[ok], ts, ps[:, k]) for k in range(3)])
    after = np.column_stack([np.interp(hi[ok], ts, ps[:, k]) for k in range(3)])
    vel = (after - before) / (2.0 * half_window_s)
    out[ok] = np.einsum("ij,ij->i", vel, np.asarray(tangents, dtype=float)[ok])
    return out


@dataclass(frozen=True)
class WindowFigures:
    """Tracking over one named window. ``speed_*``: the speed along the path from the position's
    derivative; ``estimator_*``: η2 from the velocity the controller used, against the same
    reference. None where the window holds no finite sample of that kind."""

    window: str
    start_s: float  # after activation
    duration_s: float
    samples: int
    cross_track_rms_m: float | None
    cross_track_max_m: float | None
    speed_mean_m_s: float | None  # along the direction of travel (the reference's sign)
    speed_error_rms_m_s: float | None
    speed_error_mean_m_s: float | None
    estimator_speed_error_rms_m_s: float | None
    estimator_speed_error_mean_m_s: float | None

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}

    def line(self) -> str:
        def f(x: float | None, scale: float, unit: str, fmt: str = ".2f") -> str:
            return "n/a" if x is None else f"{scale * x:{fmt}} {unit}"

        est = ""
        if self.estimator_speed_error_rms_m_s is not None:
            est = (f"; estimator's velocity: error RMS {f(self.estimator_speed_error_rms_m_s, 100, 'cm/s')}, "
                   f"mean {f(self.estimator_speed_error_mean_m_s, 100, 'cm/s', '+.2f')}")  # fmt: skip
        return (
            f"{self.window} ({self.duration_s:.1f} s): cross-track RMS {f(self.cross_track_rms_m, 100, 'cm')}, "
            f"max {f(self.cross_track_max_m, 100, 'cm')}; speed along the path (from the position) mean "
            f"{f(self.speed_mean_m_s, 1, 'm/s', '.3f')}, error RMS {f(self.speed_error_rms_m_s, 100, 'cm/s')}, "
            f"mean {f(self.speed_error_mean_m_s, 100, 'cm/s', '+.2f')}{est}"
        )


class WindowSums:
    """Running sums of one window (constant memory)."""

    def __init__(self, window: str, start_s: float) -> None:
        self.window, self.start_s = window, start_s
        self.t0 = self.t1 = math.nan
        self.n = self.nc = self.ns = self.ne = 0
        self.ct2 = self.sp = self.se = self.se2 = self.ee = self.ee2 = 0.0
        self.ct_max = -math.inf

    def add(self, time_s: float, cross_track_m: float, speed_m_s: float, est_speed_m_s: float, ref_m_s: float) -> None:
        if self.n == 0:
            self.t0 = time_s
        self.t1 = time_s
        self.n += 1
        if math.isfinite(cross_track_m):
            self.nc += 1
            self.ct2 += cross_track_m * cross_track_m
            self.ct_max = max(self.ct_max, cross_track_m)
        sign = 1.0 if ref_m_s >= 0.0 else -1.0
        if math.isfinite(speed_m_s) and math.isfinite(ref_m_s):
            self.ns += 1
            e = speed_m_s - ref_m_s
            self.sp += sign * speed_m_s
            self.se += e
            self.se2 += e * e
        if math.isfinite(est_speed_m_s) and math.isfinite(ref_m_s):
            self.ne += 1
            e = est_speed_m_s - ref_m_s
            self.ee += e
            self.ee2 += e * e

    def copy(self) -> WindowSums:
        other = WindowSums(self.window, self.start_s)
        other.__dict__.update(self.__dict__)
        return other

    def result(self) -> WindowFigures | None:
        if self.n == 0:
            return None
        return WindowFigures(
            window=self.window,
            start_s=self.start_s,
            duration_s=float(self.t1 - self.t0),
            samples=self.n,
            cross_track_rms_m=math.sqrt(self.ct2 / self.nc) if self.nc else None,
            cross_track_max_m=self.ct_max if self.nc else None,
            speed_mean_m_s=self.sp / self.ns if self.ns else None,
            speed_error_rms_m_s=math.sqrt(self.se2 / self.ns) if self.ns else None,
            speed_error_mean_m_s=self.se / self.ns if self.ns else None,
            estimator_speed_error_rms_m_s=math.sqrt(self.ee2 / self.ne) if self.ne else None,
            estimator_speed_error_mean_m_s=self.ee / self.ne if self.ne else None,
        )


class Convergence:
    """:data:`CONVERGED_DEFINITION`, fed one active sample at a time."""

    def __init__(self, tol_m: float = CONVERGED_TOL_M, hold_s: float = CONVERGED_HOLD_S) -> None:
        self.tol_m, self.hold_s = tol_m, hold_s
        self._run: float | None = None
        self.time_s: float | None = None  # vehicle time the converged stretch began

    def add(self, time_s: float, cross_track_m: float) -> None:
        if self.time_s is not None:
            return
        if not cross_track_m <= self.tol_m:  # NaN breaks the stretch too
            self._run = None
            return
        if self._run is None:
            self._run = time_s
        if time_s - self._run >= self.hold_s:
            self.time_s = self._run


class LapTimer:
    """Lap times of a closed path from the η1 of active steps (constant memory but the laps)."""

    def __init__(self, length_m: float) -> None:
        self.length_m = float(length_m)
        self.laps_s: list[float] = []
        self._t_lap = math.nan  # start of the lap being flown (the first: activation)
        self._last: tuple[float, float] | None = None
        self._progress = 0.0  # signed net progress (m)
        self._sign = 0.0  # direction of travel (the first non-zero reference speed's sign)

    def add(self, time_s: float, eta1_m: float, speed_ref_m_s: float) -> None:
        if not (math.isfinite(time_s) and math.isfinite(eta1_m)) or self.length_m <= 0.0:
            return
        if self._sign == 0.0 and math.isfinite(speed_ref_m_s) and speed_ref_m_s != 0.0:
            self._sign = 1.0 if speed_ref_m_s > 0.0 else -1.0
        if self._last is None:
            self._t_lap = time_s
            self._last = (time_s, eta1_m)
            return
        t0, e0 = self._last
        L = self.length_m
        d = (eta1_m - e0 + 0.5 * L) % L - 0.5 * L
        before = self._progress
        self._progress += d
        self._last = (time_s, eta1_m)
        if self._sign == 0.0:
            return
        done = len(self.laps_s) + 1
        while self._sign * self._progress >= done * L:
            p0, p1 = self._sign * before, self._sign * self._progress
            t = t0 + (time_s - t0) * (done * L - p0) / (p1 - p0) if p1 > p0 else time_s
            self.laps_s.append(t - self._t_lap)
            self._t_lap = t
            done += 1


@dataclass(frozen=True)
class Tracking:
    """Convergence and the two windows of one flight."""

    activation_time_s: float
    convergence_time_s: float | None  # after activation
    settled: WindowFigures | None  # from activation + 8 s
    whole: WindowFigures | None

    def lines(self) -> list[str]:
        conv = "never" if self.convergence_time_s is None else f"{self.convergence_time_s:.2f} s after activation"
        return [f"converged: {conv} ({CONVERGED_DEFINITION})"] + [w.line() for w in (self.settled, self.whole) if w is not None]


def tracking(
    time_s: Sequence[float], position_enu_m: NDArray[np.float64], lam: Sequence[float], cross_track_m: Sequence[float],
    est_speed_m_s: Sequence[float], speed_ref_m_s: Sequence[float], active: Sequence[bool], tangent: Tangent | None,
    settle_s: float = SETTLE_S,
) -> Tracking | None:  # fmt: skip
    """Offline: the same figures as :class:`pf_offboard.logs.summary.SummaryAccumulator` from
    arrays (every step: positions before activation feed the derivative; only active steps count).
    None without an active step."""
    t = np.asarray(time_s, dtype=float)
    act = np.asarray(active, dtype=bool)
    if not act.any():
        return None
    if tangent is not None:
        tang = np.array([tangent(float(x)) if math.isfinite(x) else np.full(3, math.nan) for x in lam])
        speed = position_speed_along_path(t, np.asarray(position_enu_m, dtype=float), tang)
    else:
        speed = np.full(len(t), math.nan)
    t_act = float(t[np.flatnonzero(act)[0]])
    conv = Convergence()
    settled, whole = WindowSums(settled_window(settle_s), settle_s), WindowSums(WINDOW_WHOLE, 0.0)
    for i in np.flatnonzero(act):
        ti = float(t[i])
        conv.add(ti, float(cross_track_m[i]))
        args = (ti, float(cross_track_m[i]), float(speed[i]), float(est_speed_m_s[i]), float(speed_ref_m_s[i]))
        whole.add(*args)
        if ti >= t_act + settle_s:
            settled.add(*args)
    return Tracking(t_act, None if conv.time_s is None else conv.time_s - t_act, settled.result(), whole.result())


def tracking_of_records(records: Sequence[Any], tangent: Tangent | None, settle_s: float = SETTLE_S) -> Tracking | None:
    """:func:`tracking` of step records (:class:`pf_offboard.logs.steplog.StepRecord`)."""
    return tracking(
        [r.time_s for r in records], np.array([r.position_enu_m for r in records], dtype=float).reshape(-1, 3),
        [r.lam for r in records], [r.cross_track_m for r in records], [r.eta2_m_s for r in records],
        [r.speed_ref_m_s for r in records], [r.active for r in records], tangent, settle_s,
    )  # fmt: skip
