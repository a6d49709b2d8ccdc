"""Fit the inner-loop model of :class:`~pf_offboard.control.VehicleModel` to setpoints and velocity.

Pure functions on arrays (no I/O). Per axis group (horizontal x/y, vertical z), world frame:

    dv/dt = gain · u(t) − drag · v + c,     u = lag(delay(a_sp)),  lag: 1 / (lag_s · s + 1)

``c`` is one constant per axis (m/s²): what the model does not explain and that does not change
over the flight (a hover-thrust error, a steady wind's drag).

Vertically, when the log has the measured attitude, the input is the thrust *magnitude* through
the lag and delay, along the thrust axis as measured: ``u_z = lag(delay(|a_sp + g·e_z|)) · cos(tilt)
− g``. A multirotor's vertical acceleration is its thrust times the cosine of its actual tilt, and
the tilt follows the horizontal group's slower response: while it tilts further the vehicle climbs
on the thrust meant for the larger tilt, while it levels it sinks. Fitting ``a_sp,z`` alone reads
that coupling as vertical lag: on the `px4-sih` mock's noise-free 20 s path log the vertical rise
comes out 0.106 s for its 0.062 s, along the measured tilt 0.060 s (with the estimate's noise,
which the closed loop feeds into the input, 0.062-0.092 s, and 0.094-0.114 s alone). On the real PX4 SIH's recorded flights the acceleration and
attitude flights then agree on the vertical gain (0.865 / 0.855; the setpoint alone: 1.070 /
0.812), and the drag comes out 0.93-1.07 for SIH's 1.0 on nine real flights (setpoint alone
0.93-1.20); docs/identify.md, *Vertical*. Without attitude telemetry: ``lag(delay(a_sp,z))``.

Method:

1. For a candidate (lag, delay), ``u`` is computed from the held setpoint (fractional delay by
   linear interpolation, the lag by its exact zero-order-hold discretisation, started in steady
   state at the segment's first setpoint; the first ``BURN_IN_S`` of each segment only warm up).
2. **Integral equation error** on short windows [t0, t0 + W] (W = ``WINDOW_S``, 0.2 s):
   ``v(t0+W) − v(t0) = gain·∫u − drag·∫v + c·W`` is linear in (gain, drag, c) and solved by least
   squares. Integrating, instead of differentiating, the measured velocity keeps the velocity noise
   out of the regressors' slopes (an EKF velocity differentiated at 100 Hz is mostly noise).
3. (lag, delay) per group by grid search (coarse, then fine around the best). VehicleModel has one
   delay: it gets the smaller of the two, and the other group's excess delay is added to its lag,
   which keeps each group's 63 % rise time (delay + lag) — the figure a step response measures.
4. Quality: ``r2``, the fitted model's share of the velocity change over ``QUALITY_WINDOW_S``
   (0.6 s) windows, and ``nrmse``: the model's velocity simulated over
   ``SIM_WINDOW_S`` windows from the measured velocity at each window's start, RMS error divided
   by the measured velocity's standard deviation (an output-error check the fit did not minimise).

Also the body-rate loop (rates-mode logs): roll/pitch rate ≈ lag(delay(rate setpoint)), output
error on the rates directly, reported as its 63 % rise time (``rate_time_constant_s``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from pf_offboard.control.types import GRAVITY_M_S2, VehicleModel
from pf_offboard.errors import InputError
from pf_offboard.identify.logdata import Segment

GROUPS: dict[str, tuple[int, ...]] = {"xy": (0, 1), "z": (2,)}
VERTICAL = GROUPS["z"]
# A vehicle section is flown only from a fit that explains most of the response. On the real PX4
# SIH, `identify --connect` with the default excitation fitted R^2 0.65 / 0.71 (xy / z) and its
# section flew 14.0 cm/s speed error RMS at 8.2 cm; amplitude 1 m/s^2 over 30 s fitted 0.90 / 0.88
# and flew 7.3 cm/s at 4.3 cm; path-following logs fit 0.93-0.96 (docs/identify.md).
FLYABLE_R2 = 0.85
STRONGER_EXCITATION = ("fit a path-following flight's log instead (pf-offboard identify LOG_DIR/flight.tlog, or a PX4 .ulg; "
                       "add --velocity-correction 0.3 on PX4 SIH), or fly a stronger, longer excitation "
                       "(e.g. --amplitude 1.5 --box 2)")
# Integral-equation window (s). Short windows time the response sharply and difference out an
# estimate error that drifts slower than they last: on 20 s path logs of the noisy `px4-sih` mock
# (velocity made position-consistent, eight seeds) 0.2 s gave the xy rise within 5 % and gain and
# drag within 8 % (0.6 s: 21 % and 8 %, 0.15 s: 3 % and 8 %), the same on noise-free logs; on the
# real PX4 SIH's recorded 1.5 Hz flights it gives lag 0.10-0.11 s and delay 0.13-0.14 s, the model
# that flies that vehicle best (0.6 s: 0.06 s and 0.17 s). docs/identify.md, Method.
WINDOW_S = 0.2
WINDOW_STRIDE_S = 0.1
# R^2 (the flyable gate's figure) is the fitted model's share of the velocity change it explains
# over windows of this length: the gate was calibrated on it (FLYABLE_R2), and a shorter window's
# R^2 is lower for the same fit (more of a short change is the estimate's noise).
QUALITY_WINDOW_S = 0.6
SIM_WINDOW_S = 2.0  # output-error check window (s)
BURN_IN_S = 0.6  # filter warm-up at each segment start, not in the cost
LAG_GRID_S = (0.0, 0.8)
DELAY_GRID_S = (0.0, 0.3)
MIN_EXCITATION_M_S2 = 0.1  # setpoint std (after removing its mean) needed per axis group
MIN_ACTIVE_S = 5.0


@dataclass(frozen=True)
class AxisFit:
    """Fitted response of one axis group (world frame).

    ``rise_63_s``: the model's 63 % step-rise time (``delay_s + lag_s``), the figure comparable to
    a measured step response. ``bias_m_s2``: the constant ``c`` per axis (x, y or z; ENU).
    """

    group: str  # "xy" | "z"
    lag_s: float
    delay_s: float
    gain: float
    drag_1_s: float
    bias_m_s2: tuple[float, ...]
    r2: float  # share of the velocity change over QUALITY_WINDOW_S windows the fitted model explains
    nrmse: float  # simulated velocity over SIM_WINDOW_S windows: RMS error / std of v
    samples: int  # grid samples used (per axis)
    excitation_m_s2: float  # std of the acceleration setpoint, m/s^2
    # share of the samples whose input was the thrust along the measured tilt (z only; 0..1)
    measured_tilt_share: float = 0.0

    @property
    def rise_63_s(self) -> float:
        return self.delay_s + self.lag_s


@dataclass(frozen=True)
class RateFit:
    """Body-rate loop (roll/pitch): first-order lag + delay; ``time_constant_s`` = their sum."""

    lag_s: float
    delay_s: float
    r2: float
    samples: int

    @property
    def time_constant_s(self) -> float:
        return self.lag_s + self.delay_s


@dataclass(frozen=True)
class Identification:
    """Result of :func:`identify`: per-group fits, the rate loop (if any) and notes."""

    xy: AxisFit
    z: AxisFit
    rate: RateFit | None
    duration_s: float  # active flight time used
    notes: tuple[str, ...]  # clamps and warnings, one line each

    def unflyable(self) -> str:
        """Why this fit should not be flown ("" if it may): a group below FLYABLE_R2."""
        poor = [f"{f.group} R^2 {f.r2:.2f}" for f in (self.xy, self.z) if not f.r2 >= FLYABLE_R2]  # NaN: not measured, poor
        if not poor:
            return ""
        return f"fit too uncertain to fly ({', '.join(poor)} < {FLYABLE_R2:g}); {STRONGER_EXCITATION}"

    def vehicle_model(self) -> VehicleModel:
        """The fit as a :class:`VehicleModel` (drag clamped at 0, values inside its bounds)."""
        return VehicleModel(**model_fields(self))


def model_fields(ident: Identification) -> dict[str, float | None]:
    """VehicleModel's field values from a fit, clamped to VehicleModel's bounds, rounded.

    A vertical group that answers sooner than the horizontal one (PX4: thrust before tilt) is
    written with the horizontal dead time — ``accel_delay_z_s: None`` — and the lag that keeps its
    63 % rise (none when its whole rise is shorter than that dead time): it then acts earlier than
    the prediction assumes, which flew better than its own delay, held back so that every axis acts
    at one instant (real PX4 SIH, five laps: 5.0 cm/s against 5.9; docs/identify.md, *Two
    delays*). A slower vertical group keeps its own delay.

    ``rate_time_constant_s`` only when the log had body-rate setpoints (else it is not known)."""

    def clamp(v: float, lo: float, hi: float, nd: int = 3) -> float:
        return round(min(max(v, lo), hi), nd)

    delay_xy = clamp(ident.xy.delay_s, 0.0, 1.0)
    delay_z = clamp(ident.z.delay_s, 0.0, 1.0)
    lag_z = clamp(ident.z.lag_s, 0.0, 2.0)
    faster_z = delay_z < delay_xy
    if faster_z:
        lag_z = clamp(delay_z + lag_z - delay_xy, 0.0, 2.0)
    return {
        "accel_lag_xy_s": clamp(ident.xy.lag_s, 0.0, 2.0),
        "accel_lag_z_s": lag_z,
        "accel_delay_s": delay_xy,
        "accel_delay_z_s": None if faster_z else delay_z,
        "accel_gain_xy": clamp(ident.xy.gain, 0.2, 5.0),
        "accel_gain_z": clamp(ident.z.gain, 0.2, 5.0),
        "drag_xy_1_s": clamp(ident.xy.drag_1_s, 0.0, 10.0),
        "drag_z_1_s": clamp(ident.z.drag_1_s, 0.0, 10.0),
    } | ({"rate_time_constant_s": clamp(ident.rate.time_constant_s, 0.0, 1.0)} if ident.rate is not None else {})


# ------------------------------------------------------------------------------- signal models
def delayed(u: NDArray[np.float64], dt_s: float, delay_s: float) -> NDArray[np.float64]:
    """``u(t − delay)`` on the same grid (linear interpolation, the first value held before t0)."""
    if delay_s <= 0.0:
        return u
    shift = delay_s / dt_s
    k = int(math.floor(shift))
    frac = shift - k
    n = len(u)
    idx0 = np.clip(np.arange(n) - k, 0, n - 1)
    idx1 = np.clip(idx0 - 1, 0, n - 1)
    return (1.0 - frac) * u[idx0] + frac * u[idx1]


def lagged(u: NDArray[np.float64], dt_s: float, lag_s: float) -> NDArray[np.float64]:
    """First-order lag ``1/(lag s + 1)`` of ``u`` (axis 0; ``u[k]`` held over [t_k, t_k+1)),
    sampled at the grid times: exact, started at rest on ``u[0]``."""
    if lag_s <= 1e-6:
        return u
    alpha = math.exp(-dt_s / lag_s)
    zi = np.asarray(u[0], dtype=float) * alpha  # steady state: y = u[0]
    y, _ = lfilter([0.0, 1.0 - alpha], [1.0, -alpha], u, axis=0, zi=zi[np.newaxis, ...])
    return np.asarray(y)


def lag_increments(u: NDArray[np.float64], dt_s: float, lag_s: float) -> NDArray[np.float64]:
    """∫ of the lag's output over each grid interval [t_k, t_k+1) (exact for ``u`` held)."""
    if lag_s <= 1e-6:
        return u * dt_s
    y = lagged(u, dt_s, lag_s)
    return u * dt_s + (y - u) * lag_s * (1.0 - math.exp(-dt_s / lag_s))


# ------------------------------------------------------------------------------- regression
@dataclass(frozen=True)
class _Windows:
    """Window start / end indices of one segment and the measured velocity change."""

    i0: NDArray[np.int64]
    i1: NDArray[np.int64]


def _windows(n: int, dt_s: float, window_s: float) -> _Windows:
    w = max(2, int(round(window_s / dt_s)))
    stride = max(1, int(round(WINDOW_STRIDE_S / dt_s)))
    burn = int(round(BURN_IN_S / dt_s))
    i0 = np.arange(burn, n - w, stride)
    return _Windows(i0, i0 + w)


def _cumtrapz(x: NDArray[np.float64], dt_s: float) -> NDArray[np.float64]:
    c = np.zeros_like(x)
    c[1:] = np.cumsum(0.5 * (x[1:] + x[:-1]), axis=0) * dt_s
    return c


@dataclass(frozen=True)
class _GroupData:
    """Per segment: setpoint and velocity of one axis group, with the windows and ∫v."""

    segments: tuple[Segment, ...]
    axes: tuple[int, ...]
    windows: tuple[_Windows, ...]
    dv: NDArray[np.float64]  # stacked targets (rows: segment windows × axes)
    iv: NDArray[np.float64]  # stacked ∫v over each window
    span: NDArray[np.float64]  # window length (s) per row
    axis_of_row: NDArray[np.int64]


def _group_data(segments: Sequence[Segment], axes: tuple[int, ...], window_s: float = WINDOW_S) -> _GroupData:
    dv, iv, span, axis_rows, wins = [], [], [], [], []
    for seg in segments:
        win = _windows(len(seg.time_s), seg.dt_s, window_s)
        wins.append(win)
        v = seg.velocity_enu_m_s[:, axes]
        cv = _cumtrapz(v, seg.dt_s)
        for j in range(len(axes)):
            dv.append(v[win.i1, j] - v[win.i0, j])
            iv.append(cv[win.i1, j] - cv[win.i0, j])
            span.append((win.i1 - win.i0) * seg.dt_s)
            axis_rows.append(np.full(len(win.i0), j))
    return _GroupData(
        tuple(segments), axes, tuple(wins), np.concatenate(dv), np.concatenate(iv),
        np.concatenate(span), np.concatenate(axis_rows),
    )  # fmt: skip


def _along_measured_tilt(seg: Segment, axes: tuple[int, ...]) -> bool:
    return axes == VERTICAL and seg.thrust_axis_up is not None


def _model_input(seg: Segment, axes: tuple[int, ...], delay_s: float) -> NDArray[np.float64]:
    """What goes through the delay and lag: the setpoint's axes, or (vertical, attitude measured)
    the thrust magnitude |a_sp + g e_z| (module docstring)."""
    if _along_measured_tilt(seg, axes):
        f = seg.accel_sp_enu_m_s2 + np.array([0.0, 0.0, GRAVITY_M_S2])
        return delayed(np.linalg.norm(f, axis=1)[:, np.newaxis], seg.dt_s, delay_s)
    return delayed(seg.accel_sp_enu_m_s2[:, axes], seg.dt_s, delay_s)


def input_samples(seg: Segment, axes: tuple[int, ...], lag_s: float, delay_s: float) -> NDArray[np.float64]:
    """The model's input ``u`` at the grid times (m/s², world ENU; columns: ``axes``)."""
    y = lagged(_model_input(seg, axes, delay_s), seg.dt_s, lag_s)
    if _along_measured_tilt(seg, axes):
        return y * seg.thrust_axis_up[:, np.newaxis] - GRAVITY_M_S2  # type: ignore[index]
    return y


def _increments(seg: Segment, axes: tuple[int, ...], delayed_input: NDArray[np.float64], lag_s: float) -> NDArray[np.float64]:
    """∫ u over each grid interval [t_k, t_k+1) (m/s) from the delayed model input
    (:func:`_model_input`): exact for the lag of the held input; the measured tilt's cosine, which
    changes slowly, at the interval's mean of its end values."""
    inc = lag_increments(delayed_input, seg.dt_s, lag_s)
    if _along_measured_tilt(seg, axes):
        up = seg.thrust_axis_up
        assert up is not None
        mid = np.append(0.5 * (up[1:] + up[:-1]), up[-1])
        return inc * mid[:, np.newaxis] - GRAVITY_M_S2 * seg.dt_s
    return inc


def _model_inputs(gd: _GroupData, delay_s: float) -> list[NDArray[np.float64]]:
    """Each segment's delayed model input: computed once per dead time, shared by every lag."""
    return [_model_input(seg, gd.axes, delay_s) for seg in gd.segments]


def _input_integrals(gd: _GroupData, lag_s: float, inputs: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
    """∫ u over each window; ``inputs``: :func:`_model_inputs` at the dead time."""
    out = []
    for seg, win, u in zip(gd.segments, gd.windows, inputs):
        inc = _increments(seg, gd.axes, u, lag_s)
        cu = np.zeros_like(inc)
        cu[1:] = np.cumsum(inc[:-1], axis=0)
        for j in range(len(gd.axes)):
            out.append(cu[win.i1, j] - cu[win.i0, j])
    return np.concatenate(out)


def _design(gd: _GroupData, iu: NDArray[np.float64]) -> NDArray[np.float64]:
    cols = [iu, -gd.iv]
    for j in range(len(gd.axes)):
        cols.append(np.where(gd.axis_of_row == j, gd.span, 0.0))
    return np.column_stack(cols)


def _solve(gd: _GroupData, lag_s: float, inputs: Sequence[NDArray[np.float64]]) -> tuple[NDArray[np.float64], float]:
    a = _design(gd, _input_integrals(gd, lag_s, inputs))
    theta, *_ = np.linalg.lstsq(a, gd.dv, rcond=None)
    r = gd.dv - a @ theta
    return theta, float(r @ r)


def _grid(lo: float, hi: float, step: float) -> NDArray[np.float64]:
    return np.round(np.arange(lo, hi + 0.5 * step, step), 6)


def _best_lag(gd: _GroupData, delay_s: float, lags: NDArray[np.float64]) -> tuple[float, float]:
    inputs = _model_inputs(gd, delay_s)
    costs = [_solve(gd, float(lag), inputs)[1] for lag in lags]
    k = int(np.argmin(costs))
    return float(lags[k]), float(costs[k])


def _search(gd: _GroupData) -> tuple[float, float]:
    """(lag, delay) of one group minimising the window SSE (coarse grid, then fine around the best)."""

    def evaluate(delays: NDArray[np.float64], lags: NDArray[np.float64]) -> tuple[float, float, float]:
        best = (math.inf, 0.0, 0.0)
        for d in delays:
            lag, cost = _best_lag(gd, float(d), lags)
            if cost < best[0]:
                best = (cost, lag, float(d))
        return best

    _, lag, delay = evaluate(_grid(DELAY_GRID_S[0], DELAY_GRID_S[1], 0.02), _grid(LAG_GRID_S[0], LAG_GRID_S[1], 0.02))
    fine_delays = _grid(max(DELAY_GRID_S[0], delay - 0.02), min(DELAY_GRID_S[1], delay + 0.02), 0.002)
    fine_lags = _grid(max(LAG_GRID_S[0], lag - 0.02), min(LAG_GRID_S[1], lag + 0.02), 0.002)
    _, lag, delay = evaluate(fine_delays, fine_lags)
    return lag, delay


def _simulate_nrmse(gd: _GroupData, lag_s: float, delay_s: float, gain: float, drag: float, bias: NDArray[np.float64]) -> float:
    """Velocity simulated from each SIM_WINDOW_S window's measured start; RMS error / std(v)."""
    err2, n, vs = 0.0, 0, []
    for seg in gd.segments:
        dt = seg.dt_s
        u = input_samples(seg, gd.axes, lag_s, delay_s)
        v = seg.velocity_enu_m_s[:, gd.axes]
        m = max(2, int(round(SIM_WINDOW_S / dt)))
        burn = int(round(BURN_IN_S / dt))
        decay = math.exp(-drag * dt)
        step = (1.0 - decay) / drag if drag > 1e-9 else dt
        for k0 in range(burn, len(v) - m, m):
            sim = np.empty((m, len(gd.axes)))
            sim[0] = v[k0]
            for k in range(1, m):  # exact for u held over a step
                sim[k] = decay * sim[k - 1] + step * (gain * u[k0 + k - 1] + bias)
            err2 += float(np.sum((sim - v[k0 : k0 + m]) ** 2))
            n += sim.size
            vs.append(v[k0 : k0 + m])
    if n == 0:
        return math.nan
    allv = np.concatenate(vs)
    spread = float(np.sqrt(np.mean((allv - allv.mean(axis=0)) ** 2)))
    return math.sqrt(err2 / n) / spread if spread > 0 else math.nan


def _quality_r2(gd: _GroupData, lag_s: float, delay_s: float, theta: NDArray[np.float64]) -> float:
    """R^2 of the fitted ``theta`` on the QUALITY_WINDOW_S windows of the same data (not refitted)."""
    q = _group_data(gd.segments, gd.axes, QUALITY_WINDOW_S)
    if len(q.dv) < 2:
        return math.nan
    r = q.dv - _design(q, _input_integrals(q, lag_s, _model_inputs(q, delay_s))) @ theta
    sst = float(np.sum((q.dv - q.dv.mean()) ** 2))
    return 1.0 - float(r @ r) / sst if sst > 0 else math.nan


def _fit_group(name: str, gd: _GroupData, lag_s: float, delay_s: float) -> AxisFit:
    theta, _ = _solve(gd, lag_s, _model_inputs(gd, delay_s))
    gain, drag, bias = float(theta[0]), float(theta[1]), np.asarray(theta[2:])
    nrmse = _simulate_nrmse(gd, lag_s, delay_s, gain, drag, bias)
    a = np.concatenate([s.accel_sp_enu_m_s2[:, gd.axes] for s in gd.segments])
    samples = int(sum(len(s.time_s) for s in gd.segments))
    tilted = int(sum(len(s.time_s) for s in gd.segments if _along_measured_tilt(s, gd.axes)))
    return AxisFit(
        group=name, lag_s=lag_s, delay_s=delay_s, gain=gain, drag_1_s=drag,
        bias_m_s2=tuple(float(b) for b in bias), r2=_quality_r2(gd, lag_s, delay_s, theta),
        nrmse=nrmse, samples=samples, excitation_m_s2=float(np.sqrt(np.mean(np.var(a, axis=0)))),
        measured_tilt_share=tilted / samples if samples else 0.0,
    )  # fmt: skip


def fit_rate_loop(segments: Sequence[Segment]) -> RateFit | None:
    """Roll/pitch body rates vs their setpoints (rates-mode segments only); None without any."""
    segs = [s for s in segments if s.rates_sp_frd_rad_s is not None and s.rates_frd_rad_s is not None]
    if not segs:
        return None
    best = (math.inf, 0.0, 0.0)
    sst = sum(float(np.sum((s.rates_frd_rad_s[:, :2] - s.rates_frd_rad_s[:, :2].mean(axis=0)) ** 2)) for s in segs)  # type: ignore[index]
    for d in _grid(0.0, 0.1, 0.005):
        shifted = [delayed(s.rates_sp_frd_rad_s[:, :2], s.dt_s, float(d)) for s in segs]  # type: ignore[index]  # once per dead time
        for lag in _grid(0.0, 0.4, 0.005):
            sse = 0.0
            for s, sp in zip(segs, shifted):
                burn = int(round(BURN_IN_S / s.dt_s))
                y = lagged(sp, s.dt_s, float(lag))
                r = (y - s.rates_frd_rad_s[:, :2])[burn:]  # type: ignore[index]
                sse += float(np.sum(r * r))
            if sse < best[0]:
                best = (sse, float(lag), float(d))
    sse, lag, d = best
    return RateFit(lag, d, 1.0 - sse / sst if sst > 0 else math.nan, int(sum(len(s.time_s) for s in segs)))


def identify(segments: Sequence[Segment], source: str = "log") -> Identification:
    """Fit both axis groups (and the rate loop if rates-mode data is present).

    Raises :class:`InputError` (field ``source``) when there is too little active flight or an
    axis group was not excited.
    """
    segs = tuple(segments)
    total = float(sum(s.duration_s for s in segs))
    if total < MIN_ACTIVE_S:
        raise InputError(source, f"only {total:.1f} s of active flight; identify needs at least {MIN_ACTIVE_S:g} s (a 20 s excitation is recommended)")
    for name, axes in GROUPS.items():
        a = np.concatenate([s.accel_sp_enu_m_s2[:, axes] for s in segs])
        std = float(np.sqrt(np.mean(np.var(a, axis=0))))
        if std < MIN_EXCITATION_M_S2:
            raise InputError(source, f"no excitation in {name}: the acceleration setpoint varies by only {std:.3f} m/s^2 (std; need >= {MIN_EXCITATION_M_S2:g}); fly `identify --connect` or a path with turns and climbs")
    groups = {name: _group_data(segs, axes) for name, axes in GROUPS.items()}
    for name, gd in groups.items():
        if len(gd.dv) < 20:
            raise InputError(source, f"too few {WINDOW_S:g} s windows in {name} ({len(gd.dv)}); the active stretches are too short")
    fits = {name: _fit_group(name, gd, *_search(gd)) for name, gd in groups.items()}
    notes = []
    for f in fits.values():
        if f.drag_1_s < 0.0:
            notes.append(f"{f.group}: fitted drag {f.drag_1_s:.3f} 1/s < 0 (not resolved by this flight); written as 0")
        if not 0.2 <= f.gain <= 5.0:
            raise InputError(source, f"{f.group}: fitted gain {f.gain:.3f} is not physical (expected about 1): setpoints and response do not match (wrong hover thrust? not the log of the vehicle flown?)")
        if not f.r2 >= FLYABLE_R2:
            notes.append(f"{f.group}: poor fit (R^2 {f.r2:.2f} < {FLYABLE_R2:g}): too uncertain to fly; {STRONGER_EXCITATION}")
    return Identification(fits["xy"], fits["z"], fit_rate_loop(segs), total, tuple(notes))
