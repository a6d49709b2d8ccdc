"""The flight envelope: where and how the vehicle may fly while the app commands it. Pure.

:class:`EnvelopeMonitor` sits between the controller and the link: the bridge feeds it every
state sample (:meth:`EnvelopeMonitor.check_state`) and every setpoint *before* it is sent
(:meth:`EnvelopeMonitor.check_setpoint`); a :class:`Verdict` with ``breach`` set ends following
with the configured action. No clocks and no I/O: time is the vehicle's (the samples' own
``time_s``, the autopilot's clock without its jumps), so the same telemetry always gives the same
verdicts (tests, ``replay``).

Everything here is in the core's frames (world ENU, body FLU); nothing is converted.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

SHAPES = ("box", "cylinder")
ACTIONS = ("hold", "land")

# MAVLink MAV_LANDED_STATE (EXTENDED_SYS_STATE.landed_state); local so this module imports nothing heavy.
LANDED_STATE_ON_GROUND = 1


@dataclass(frozen=True)
class SafetyConfig:
    """The ``safety:`` config section (docs/app.md). Defaults are on: the envelope always applies.

    Fence: ``fence_min_enu_m`` / ``fence_max_enu_m`` (box) or ``fence_center_enu_m`` +
    ``fence_radius_m`` (cylinder) when given; otherwise built around the path (its bounding box,
    or the smallest vertical cylinder about its centre, grown by ``fence_margin_m``). The floor is
    never below ``min_altitude_m``; ``max_altitude_m`` caps the ceiling.
    """

    enabled: bool = True
    action: str = "hold"  # what to ask the autopilot for on a breach: hold | land
    fence_shape: str = "box"
    fence_margin_m: float = 2.0
    fence_min_enu_m: tuple[float, float, float] | None = None
    fence_max_enu_m: tuple[float, float, float] | None = None
    fence_center_enu_m: tuple[float, float] | None = None
    fence_radius_m: float | None = None
    min_altitude_m: float = 0.5
    max_altitude_m: float = 120.0
    max_path_distance_at_activation_m: float = 3.0
    max_path_distance_m: float = 3.0
    max_tilt_deg: float = 60.0  # measured, and commanded (attitude setpoints)
    max_body_rate_rad_s: float = 4.0  # body-rate setpoints: roll/pitch pair and yaw (PX4 MC_ROLLRATE_MAX 220 deg/s)
    max_attitude_error_deg: float = 35.0  # rates mode: measured vs commanded thrust axis (own loop diverging) ...
    attitude_error_time_s: float = 0.5  # ... for longer than this (a step demand at activation is transient)
    max_descent_speed_m_s: float = 5.0  # falling faster than this while following: motors lost / crash ...
    falling_confirm_s: float = 0.02  # ... on every sample for at least this long, two samples or more (never one)
    max_estimator_reset_m: float = 0.5  # an estimator reset (position jump) larger than this while following ends it
    no_progress_s: float = 5.0  # while following: neither along-path progress nor approach for this long
    min_progress_m: float = 0.5
    safe_mode_timeout_s: float = 10.0  # retry the hold/land request until confirmed, at most this long
    heartbeat_timeout_s: float = 3.0  # no autopilot HEARTBEAT for this long: mode unknown, stop commanding
    tilt_lookahead_s: float = 0.1  # a tilt beyond the demanded one is extrapolated this far (telemetry lags)


@dataclass(frozen=True)
class Fence:
    """A box (``min_enu_m``..``max_enu_m``) or a vertical cylinder (``center_xy_m``, ``radius_m``)
    between ``floor_m`` and ``ceiling_m`` (altitudes, ENU z)."""

    shape: str
    floor_m: float
    ceiling_m: float
    min_xy_m: tuple[float, float] = (0.0, 0.0)
    max_xy_m: tuple[float, float] = (0.0, 0.0)
    center_xy_m: tuple[float, float] = (0.0, 0.0)
    radius_m: float = 0.0

    def violation(self, position_enu_m: ArrayLike) -> str:
        """Why ``position_enu_m`` is outside ("" if inside)."""
        x, y, z = (float(v) for v in np.asarray(position_enu_m, dtype=float)[:3])
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            return "position not finite"
        if z < self.floor_m:
            return f"altitude {z:.2f} m below the floor {self.floor_m:g} m"
        if z > self.ceiling_m:
            return f"altitude {z:.2f} m above the ceiling {self.ceiling_m:g} m"
        if self.shape == "cylinder":
            r = math.hypot(x - self.center_xy_m[0], y - self.center_xy_m[1])
            if r > self.radius_m:
                return f"({x:.2f}, {y:.2f}) is {r - self.radius_m:.2f} m outside the fence cylinder (radius {self.radius_m:g} m)"
            return ""
        for axis, v, lo, hi in (("x", x, self.min_xy_m[0], self.max_xy_m[0]), ("y", y, self.min_xy_m[1], self.max_xy_m[1])):
            if not lo <= v <= hi:
                return f"{axis} = {v:.2f} m outside the fence [{lo:g}, {hi:g}] m"
        return ""

    def describe(self) -> str:
        if self.shape == "cylinder":
            c = self.center_xy_m
            return f"cylinder r {self.radius_m:.2f} m about ({c[0]:.2f}, {c[1]:.2f}), z {self.floor_m:.2f}..{self.ceiling_m:.2f} m"
        return (
            f"box x {self.min_xy_m[0]:.2f}..{self.max_xy_m[0]:.2f}, y {self.min_xy_m[1]:.2f}..{self.max_xy_m[1]:.2f}, "
            f"z {self.floor_m:.2f}..{self.ceiling_m:.2f} m"
        )


def fence_for_path(config: SafetyConfig, path_points_enu_m: Sequence[ArrayLike]) -> Fence:
    """The configured fence, or one grown around the path's sampled points by the margin."""
    pts = np.asarray(path_points_enu_m, dtype=float).reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    m = config.fence_margin_m
    if config.fence_min_enu_m is not None and config.fence_max_enu_m is not None:
        fmin, fmax = config.fence_min_enu_m, config.fence_max_enu_m
        floor, ceiling = fmin[2], fmax[2]
    else:
        fmin = (float(lo[0] - m), float(lo[1] - m), float(lo[2] - m))
        fmax = (float(hi[0] + m), float(hi[1] + m), float(hi[2] + m))
        floor, ceiling = fmin[2], fmax[2]
    floor = max(floor, config.min_altitude_m)
    ceiling = min(ceiling, config.max_altitude_m)
    if config.fence_shape == "cylinder":
        if config.fence_center_enu_m is not None and config.fence_radius_m is not None:
            center, radius = config.fence_center_enu_m, config.fence_radius_m
        else:
            center = (float(lo[0] + hi[0]) / 2.0, float(lo[1] + hi[1]) / 2.0)
            radius = float(np.max(np.hypot(pts[:, 0] - center[0], pts[:, 1] - center[1]))) + m
        return Fence("cylinder", floor, ceiling, center_xy_m=(float(center[0]), float(center[1])), radius_m=float(radius))
    return Fence("box", floor, ceiling, min_xy_m=(fmin[0], fmin[1]), max_xy_m=(fmax[0], fmax[1]))


def check_path(fence: Fence, path_points_enu_m: Iterable[ArrayLike]) -> str:
    """Why the path cannot be flown inside the fence ("" if it can). Checked before any traffic."""
    for p in path_points_enu_m:
        why = fence.violation(p)
        if why:
            x, y, z = (float(v) for v in p)
            return f"the path leaves the fence ({fence.describe()}) at ({x:.2f}, {y:.2f}, {z:.2f}) m: {why}"
    return ""


# How far inside the fence's floor / ceiling a take-off ends: the autopilot's take-off counts as
# done some 0.2 m short of its target (PX4), and following must not start in a breach.
TAKEOFF_CLEARANCE_M = 0.5


def takeoff_height_in_fence(fence: Fence, height_m: float, clearance_m: float = TAKEOFF_CLEARANCE_M) -> tuple[float, str]:
    """The take-off height (ENU z, m) to fly so that following starts inside the fence, and a
    note saying why it differs from ``height_m`` ("" when it does not).

    A height below the fence's floor (or above its ceiling) would arm, climb and end the flight
    in an envelope breach at activation; the vehicle climbs to ``clearance_m`` above the floor
    (below the ceiling) instead, or to the middle of a band narrower than twice the clearance."""
    lo, hi = fence.floor_m + clearance_m, fence.ceiling_m - clearance_m
    if lo > hi:
        lo = hi = 0.5 * (fence.floor_m + fence.ceiling_m)
    if height_m < lo:
        return lo, (f"take-off height {height_m:g} m is below the path's fence floor {fence.floor_m:.2f} m: "
                    f"taking off to {lo:.2f} m instead")  # fmt: skip
    if height_m > hi:
        return hi, (f"take-off height {height_m:g} m is above the path's fence ceiling {fence.ceiling_m:.2f} m: "
                    f"taking off to {hi:.2f} m instead")  # fmt: skip
    return height_m, ""


def tilt_rad(q_enu_flu: ArrayLike) -> float:
    """Angle between the body z axis (thrust) and world up, for a unit quaternion (w, x, y, z)."""
    w, x, y, z = (float(v) for v in np.asarray(q_enu_flu, dtype=float))
    zz = 1.0 - 2.0 * (x * x + y * y)  # world-up component of body z
    return math.acos(max(-1.0, min(1.0, zz)))


def tilt_rate_rad_s(q_enu_flu: ArrayLike, rates_flu_rad_s: ArrayLike) -> float:
    """d(tilt)/dt from an attitude and the body rates of the same sample (positive: tilting
    further). With u = body z · world up, du/dt = R20·ω_y − R21·ω_x and tilt = acos(u)."""
    w, x, y, z = (float(v) for v in np.asarray(q_enu_flu, dtype=float))
    wx, wy = (float(v) for v in np.asarray(rates_flu_rad_s, dtype=float)[:2])
    r20, r21 = 2.0 * (x * z - w * y), 2.0 * (y * z + w * x)
    sin_tilt = math.sin(tilt_rad((w, x, y, z)))
    if sin_tilt < 1e-3:
        return math.hypot(wx, wy)  # level: any roll/pitch rate tilts it
    return -(r20 * wy - r21 * wx) / sin_tilt


def bound_body_rates(rates_frd_rad_s: Sequence[float], limit_rad_s: float) -> tuple[tuple[float, float, float], bool]:
    """Body rates bounded by ``limit_rad_s``: roll and pitch scaled together (the tilting axis is
    kept), yaw clipped on its own (a large heading error at activation must not slow the tilt).
    Returns (rates, True if any was bounded)."""
    p, q, r = (float(v) for v in rates_frd_rad_s)
    peak = max(abs(p), abs(q))
    bounded = peak > limit_rad_s or abs(r) > limit_rad_s
    if peak > limit_rad_s:
        p, q = p * limit_rad_s / peak, q * limit_rad_s / peak
    return (p, q, max(-limit_rad_s, min(limit_rad_s, r))), bounded


def _body_z(q: ArrayLike) -> tuple[float, float, float]:
    w, x, y, z = (float(v) for v in np.asarray(q, dtype=float))
    return (2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y))


def thrust_axis_error_rad(q_a: ArrayLike, q_b: ArrayLike) -> float:
    """Angle between the thrust (body z) axes of two attitudes. Yaw is left out on purpose: a
    large heading error is harmless (and normal when following starts), a thrust axis far from
    the commanded one is the vehicle going somewhere else."""
    a, b = _body_z(q_a), _body_z(q_b)
    return math.acos(max(-1.0, min(1.0, a[0] * b[0] + a[1] * b[1] + a[2] * b[2])))


class Breach(enum.Enum):
    """What kind of limit was hit; ``CRASH`` kinds end the flight with a different exit code."""

    NONE = "none"
    FENCE = "fence"
    PATH_DISTANCE = "path_distance"
    TILT = "tilt"
    ATTITUDE_ERROR = "attitude_error"
    BODY_RATE = "body_rate"
    NO_PROGRESS = "no_progress"
    FALLING = "falling"
    DISARMED = "disarmed"
    LANDED = "landed"
    SETPOINT = "setpoint"
    ESTIMATOR = "estimator"  # the position estimate reset (jumped) or reports itself degraded


CRASH_KINDS = frozenset({Breach.FALLING, Breach.DISARMED, Breach.LANDED})


@dataclass(frozen=True)
class Verdict:
    """The monitor's answer: ``kind`` NONE means carry on; otherwise a one-line ``reason``."""

    kind: Breach = Breach.NONE
    reason: str = ""

    @property
    def breach(self) -> bool:
        return self.kind is not Breach.NONE

    @property
    def crash(self) -> bool:
        """The vehicle is down or falling (disarmed, landed, free fall): nothing left to hold."""
        return self.kind in CRASH_KINDS


OK = Verdict()


@dataclass(frozen=True)
class VehicleSample:
    """What the monitor looks at for one state sample (world ENU, body FLU). ``time_s`` is only
    used for durations: give a continuous clock (the bridge gives the estimator's flight clock,
    the autopilot's time without its jumps)."""

    time_s: float
    position_enu_m: NDArray[np.float64]
    velocity_enu_m_s: NDArray[np.float64]
    q_enu_flu: NDArray[np.float64] | None
    armed: bool
    landed_state: int | None = None  # EXTENDED_SYS_STATE.landed_state, None until heard
    cross_track_m: float | None = None  # None: the controller gave none this step
    eta1_m: float | None = None
    q_cmd_enu_flu: NDArray[np.float64] | None = None  # rates mode: the attitude our own loop tracks
    rates_flu_rad_s: NDArray[np.float64] | None = None  # measured body rates (same sample as the attitude)
    q_demand_enu_flu: NDArray[np.float64] | None = None  # the core's demanded attitude (any output mode)


class EnvelopeMonitor:
    """Verdicts on state samples and setpoints. State: the no-progress window only.

    ``path_length_m`` / ``path_closed`` let the watchdog measure net progress along a closed path
    (η1 wraps at the length).
    """

    def __init__(self, config: SafetyConfig, fence: Fence, path_length_m: float, path_closed: bool) -> None:
        self.config = config
        self.fence = fence
        self.path_length_m = path_length_m
        self.path_closed = path_closed
        self._window_start_s: float | None = None
        self._window_eta1_m = math.nan
        self._window_best_cross_m = math.inf
        self.max_tilt_seen_rad = 0.0
        self._attitude_error_since_s: float | None = None
        self._falling_since_s: float | None = None
        self._falling_samples = 0

    # ------------------------------------------------------------------ activation
    def check_activation(self, sample: VehicleSample) -> Verdict:
        """At the moment following starts: inside the fence and near enough to the path."""
        if not self.config.enabled:
            return OK
        verdict = self._fence(sample)
        if verdict.breach:
            return verdict
        d = sample.cross_track_m
        limit = self.config.max_path_distance_at_activation_m
        if d is not None and math.isfinite(d) and d > limit:
            return Verdict(Breach.PATH_DISTANCE, f"{d:.2f} m from the path at activation (safety.max_path_distance_at_activation_m {limit:g})")
        self.reset_watchdog()
        return OK

    def reset_watchdog(self) -> None:
        self._window_start_s = None

    # ------------------------------------------------------------------ every state sample
    def check_state(self, sample: VehicleSample, following: bool = True) -> Verdict:
        """Crash / disarm / landed and measured tilt always; fence, path distance, attitude error
        and the no-progress watchdog while ``following``."""
        cfg = self.config
        if not cfg.enabled:
            return OK
        if not sample.armed:
            return Verdict(Breach.DISARMED, "the vehicle disarmed in flight (crash, kill switch or autopilot failsafe)")
        if sample.landed_state == LANDED_STATE_ON_GROUND and following:
            return Verdict(Breach.LANDED, "the autopilot reports the vehicle on the ground (EXTENDED_SYS_STATE) while following")
        descent = -float(sample.velocity_enu_m_s[2])
        if following and descent > cfg.max_descent_speed_m_s:
            # never on one sample: every sample over falling_confirm_s (and at least two) says so
            if self._falling_since_s is None:
                self._falling_since_s, self._falling_samples = sample.time_s, 0
            self._falling_samples += 1
            lasted = sample.time_s - self._falling_since_s
            if self._falling_samples >= 2 and lasted >= cfg.falling_confirm_s:
                return Verdict(Breach.FALLING, f"descending at {descent:.1f} m/s for {lasted:.2f} s (safety.max_descent_speed_m_s "
                                               f"{cfg.max_descent_speed_m_s:g}): falling")  # fmt: skip
        else:
            self._falling_since_s = None
        if sample.q_enu_flu is not None:
            tilt = tilt_rad(sample.q_enu_flu)
            self.max_tilt_seen_rad = max(self.max_tilt_seen_rad, tilt)
            if math.degrees(tilt) > cfg.max_tilt_deg:
                return Verdict(Breach.TILT, f"measured tilt {math.degrees(tilt):.0f} deg > safety.max_tilt_deg {cfg.max_tilt_deg:g}")
            # Telemetry lags the vehicle and a level command takes a moment to stop a rotation: a
            # tilt already beyond the demanded one (overshooting, not a commanded manoeuvre) and
            # growing fast enough to pass the limit within the look-ahead is a breach now.
            rate = tilt_rate_rad_s(sample.q_enu_flu, sample.rates_flu_rad_s) if sample.rates_flu_rad_s is not None else 0.0
            demanded = tilt_rad(sample.q_demand_enu_flu) if sample.q_demand_enu_flu is not None else 0.0
            ahead = math.degrees(tilt + max(rate, 0.0) * cfg.tilt_lookahead_s)
            if tilt > demanded and ahead > cfg.max_tilt_deg:
                return Verdict(
                    Breach.TILT,
                    f"measured tilt {math.degrees(tilt):.0f} deg growing at {math.degrees(rate):.0f} deg/s: past safety.max_tilt_deg "
                    f"{cfg.max_tilt_deg:g} within {cfg.tilt_lookahead_s:g} s",
                )
            if following and sample.q_cmd_enu_flu is not None:
                err = math.degrees(thrust_axis_error_rad(sample.q_enu_flu, sample.q_cmd_enu_flu))
                if err <= cfg.max_attitude_error_deg:
                    self._attitude_error_since_s = None
                elif self._attitude_error_since_s is None:
                    self._attitude_error_since_s = sample.time_s
                elif sample.time_s - self._attitude_error_since_s > cfg.attitude_error_time_s:
                    return Verdict(
                        Breach.ATTITUDE_ERROR,
                        f"thrust axis {err:.0f} deg off the commanded one for {sample.time_s - self._attitude_error_since_s:.2f} s "
                        f"(safety.max_attitude_error_deg {cfg.max_attitude_error_deg:g}): the attitude loop is diverging",
                    )
        if not following:
            return OK
        verdict = self._fence(sample)
        if verdict.breach:
            return verdict
        d = sample.cross_track_m
        if d is not None and math.isfinite(d) and d > cfg.max_path_distance_m:
            return Verdict(Breach.PATH_DISTANCE, f"{d:.2f} m from the path (safety.max_path_distance_m {cfg.max_path_distance_m:g})")
        return self._watchdog(sample)

    def check_estimator(self, reset_enu_m: ArrayLike | None = None, degraded: str = "") -> Verdict:
        """While following: an estimator reset (the confirmed jump of the position estimate, ENU m)
        larger than ``max_estimator_reset_m`` — the path moved under the vehicle, and following on
        would fly it there (a 1.6 m vertical reset flew a vehicle to 3 cm above the ground) — or an
        estimate that reports itself degraded (``degraded``: why) ends following."""
        cfg = self.config
        if not cfg.enabled:
            return OK
        if degraded:
            return Verdict(Breach.ESTIMATOR, f"position estimate degraded ({degraded})")
        if reset_enu_m is not None:
            jump = np.asarray(reset_enu_m, dtype=float)
            size = float(np.linalg.norm(jump))
            if not math.isfinite(size) or size > cfg.max_estimator_reset_m:
                return Verdict(Breach.ESTIMATOR, f"estimator reset moved the position estimate {size:.2f} m "
                                                 f"(vertical {float(jump[2]):+.2f} m; safety.max_estimator_reset_m {cfg.max_estimator_reset_m:g})")  # fmt: skip
        return OK

    def _fence(self, sample: VehicleSample) -> Verdict:
        why = self.fence.violation(sample.position_enu_m)
        return Verdict(Breach.FENCE, f"outside the fence: {why}") if why else OK

    def _watchdog(self, sample: VehicleSample) -> Verdict:
        """No progress: in ``no_progress_s`` the vehicle neither moved ``min_progress_m`` along the
        path (net, either direction) nor got ``min_progress_m`` closer to it."""
        d, eta1 = sample.cross_track_m, sample.eta1_m
        if d is None or eta1 is None or not (math.isfinite(d) and math.isfinite(eta1)):
            return OK
        cfg = self.config
        if self._window_start_s is None:
            self._window_start_s, self._window_eta1_m, self._window_best_cross_m = sample.time_s, eta1, d
            return OK
        moved = eta1 - self._window_eta1_m
        if self.path_closed and self.path_length_m > 0:
            moved = (moved + 0.5 * self.path_length_m) % self.path_length_m - 0.5 * self.path_length_m
        if abs(moved) >= cfg.min_progress_m or d <= self._window_best_cross_m - cfg.min_progress_m:
            self._window_start_s, self._window_eta1_m, self._window_best_cross_m = sample.time_s, eta1, d
            return OK
        stalled = sample.time_s - self._window_start_s
        if stalled > cfg.no_progress_s:
            return Verdict(
                Breach.NO_PROGRESS,
                f"no progress for {stalled:.1f} s (moved {abs(moved):.2f} m along the path, {d:.2f} m off it; safety.no_progress_s {cfg.no_progress_s:g})",
            )
        return OK

    def bound_rates(self, rates_frd_rad_s: Sequence[float]) -> tuple[tuple[float, float, float], bool]:
        """Body rates bounded by ``max_body_rate_rad_s``: roll and pitch scaled together (the
        tilting axis is kept), yaw clipped on its own (a large heading error at activation must not
        slow the tilt). A saturation, not a breach: the app's attitude loop asks for large rates
        for a moment at activation; what leaves is bounded, as the autopilot's own loops are.
        Returns (rates, True if any was bounded)."""
        if not self.config.enabled:
            p, q, r = (float(v) for v in rates_frd_rad_s)
            return (p, q, r), False
        return bound_body_rates(rates_frd_rad_s, self.config.max_body_rate_rad_s)

    # ------------------------------------------------------------------ every setpoint, before it is sent
    def check_setpoint(
        self,
        q_cmd_enu_flu: ArrayLike | None = None,
        rates_frd_rad_s: Sequence[float] | None = None,
        position_target_enu_m: ArrayLike | None = None,
        accel_cmd_enu_m_s2: ArrayLike | None = None,
    ) -> Verdict:
        """A setpoint that would take the vehicle out of the envelope is never sent: commanded tilt
        (attitude, or the thrust direction of an acceleration), body rates, position targets."""
        cfg = self.config
        if not cfg.enabled:
            return OK
        if q_cmd_enu_flu is not None:
            tilt = math.degrees(tilt_rad(q_cmd_enu_flu))
            if tilt > cfg.max_tilt_deg:
                return Verdict(Breach.SETPOINT, f"setpoint tilt {tilt:.0f} deg > safety.max_tilt_deg {cfg.max_tilt_deg:g}: not sent")
        if accel_cmd_enu_m_s2 is not None:
            a = np.asarray(accel_cmd_enu_m_s2, dtype=float)
            f = (float(a[0]), float(a[1]), float(a[2]) + 9.81)
            tilt = math.degrees(math.atan2(math.hypot(f[0], f[1]), f[2]))
            if tilt > cfg.max_tilt_deg:
                return Verdict(Breach.SETPOINT, f"acceleration setpoint tilts {tilt:.0f} deg > safety.max_tilt_deg {cfg.max_tilt_deg:g}: not sent")
        if rates_frd_rad_s is not None:
            peak = max(abs(float(r)) for r in rates_frd_rad_s)
            if not math.isfinite(peak):
                return Verdict(Breach.BODY_RATE, "body-rate setpoint not finite: not sent")
        if position_target_enu_m is not None:
            why = self.fence.violation(position_target_enu_m)
            if why:
                return Verdict(Breach.SETPOINT, f"position setpoint outside the fence: {why}: not sent")
        return OK
