"""PathFollower: projection -> exact transverse coordinates -> TFL with limits -> feed-forward.

Pure and I/O-free (it never reads a file or a config: :meth:`PathFollower.from_config` takes a loaded
one). The law is time-invariant; the state is the projector's warm start, the start ramp's origin
and, with the inner-loop compensation, the compensator's. World ENU z up, body FLU.
"""

from __future__ import annotations

import math
import os
import warnings
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pf_offboard.control.compensator import InnerLoopCompensator
from pf_offboard.control.feedforward import (
    YawProfile,
    attitude_from_thrust,
    body_rates,
    onpath_derivatives,
    quaternion_from_axes,
)
from pf_offboard.control.law import BISECTION_STEPS, ControlLaw, LawOutput
from pf_offboard.control.profile import SpeedProfile, SpeedProfileSpec, replan_weight, vehicle_lap_time_bound
from pf_offboard.control.transverse import ExactTerms, exact_terms
from pf_offboard.control.tuning import gains_for_vehicle
from pf_offboard.control.types import (
    ANY_STATE_NEEDS_NO_COMPENSATION,
    DEFAULT_SPEED_M_S,
    FEEDFORWARD_MODES,
    GRAVITY_M_S2,
    Command,
    Compensation,
    Gains,
    Limits,
    Saturation,
    TransverseState,
    VehicleModel,
    YawSpec,
)
from pf_offboard.errors import InputError
from pf_offboard.frames import wrap_pi

if TYPE_CHECKING:
    from pf_offboard.path import Path

G = GRAVITY_M_S2
Vec = tuple[float, float, float]
MAX_SPEED_M_S = 20.0

# Tube measure q = <sigma'', r>/|sigma'|^2 (= kappa xi1 for the Frenet frame): the exact law is
# used for q <= TUBE_INNER, the approach fallback for q >= TUBE_OUTER, a convex blend in between
# (the feasible set is convex, so the blend is feasible too).
TUBE_INNER = 0.8
TUBE_OUTER = 0.9
# Past an open path's end the approach to the end point takes over within this distance (m).
END_BLEND_M = 0.05
# Far from the path the transverse coordinates rotate with the moving frame about a lever arm of
# the offset, and holding (xi2, phi2) would whirl the vehicle around the path: beyond
# FAR_OUTER_M the Cartesian approach law is used, within FAR_INNER_M the exact law, a blend between.
FAR_INNER_M = 0.5
FAR_OUTER_M = 1.0
# Any-state feed-forward: time step (s) of the central difference along the closed-loop flow,
# the allocation's bisection steps there (2^-40: smooth to rounding), and the cap on |jerk| / |f|
# (1/s, i.e. a tilt rate) where the law has a jump (projection branch switch far from the path).
ANY_STATE_STEP_S = 5e-5
FINE_BISECTION_STEPS = 40
ANY_STATE_MAX_JERK_RATIO = 50.0
# Start ramp (limits.max_tangential_accel_m_s2): its feed-forward fades out over its last RAMP_END_S
# seconds (no acceleration step where it ends); within RAMP_DONE_M_S of the reference it is done.
RAMP_END_S = 0.3
RAMP_DONE_M_S = 1e-3
PAPER_WARNING = (
    "PathFollower.paper: the paper's gains (6 Hz / 4 Hz) and law without inner-loop compensation "
    "assume an ideal inner loop (an acceleration flown at once, no drag); on a real PX4 / ArduPilot "
    "vehicle they limit-cycle. Use PathFollower(path, speed) (the default) for a real one"
)


class ControllerConfig(Protocol):
    """What :meth:`PathFollower.from_config` reads (``pf_offboard.config.Config`` has it)."""

    path: Any  # with .spline() -> Path
    speed_m_s: float
    gains: Gains
    yaw: YawSpec
    limits: Limits
    vehicle: VehicleModel
    compensation: Compensation
    speed_profile: SpeedProfileSpec | None
    feedforward: str


class _Evaluation(NamedTuple):
    state: TransverseState
    eta2_ref: float
    deta2_ref: float
    ddeta2_ref: float
    w: float  # weight of the approach fallback
    res: LawOutput
    tan: Vec
    s_ss: Vec
    s_sss: Vec
    dist: float


def _approach_weight(tube: float, dist_m: float) -> float:
    """Weight of the approach fallback before clipping to [0, 1]: the larger of the tube ramp
    (TUBE_INNER..TUBE_OUTER) and the distance ramp (FAR_INNER_M..FAR_OUTER_M)."""
    return max((tube - TUBE_INNER) / (TUBE_OUTER - TUBE_INNER), (dist_m - FAR_INNER_M) / (FAR_OUTER_M - FAR_INNER_M))


def _blended_speed(eta2: float, w: float, tan: Vec, v: Vec) -> float:
    """eta2 (m/s) faded into the speed along the unit tangent ``tan`` with the approach weight
    ``w`` in [0, 1], as the law fades its inputs: far from the path (w = 1) the exact eta2 is
    singular (1 - kappa xi1 -> 0) and only the tangential speed is used."""
    if w <= 0.0:
        return eta2
    v_t = tan[0] * v[0] + tan[1] * v[1] + tan[2] * v[2]
    return v_t if w >= 1.0 else (1.0 - w) * eta2 + w * v_t


def evaluate_terms(path: Path, lam: float, position: ArrayLike, velocity: ArrayLike) -> ExactTerms:
    """T(x), alpha, beta at a given closest-point parameter ``lam`` (no projection, no state)."""
    s = path.eval_floats(lam)
    (_, _, _), (e2, de2, dde2), (e3, de3, dde3) = path.frame_jets(lam)
    y = _vec(position, "position", MAX_POSITION_ABS_M)
    v = _vec(velocity, "velocity", MAX_VELOCITY_ABS_M_S)
    return exact_terms(
        path.arclength(lam), s[0:3], s[3:6], s[6:9], s[9:12], e2, de2, dde2, e3, de3, dde3, y, v
    )


# Beyond these magnitudes the input is not a quadrotor's state (and squares of it overflow to
# inf, which would turn the command into NaN): rejected like NaN.
MAX_POSITION_ABS_M = 1e6  # per component
MAX_VELOCITY_ABS_M_S = 1e3  # per component


def _vec(value: ArrayLike, name: str, bound: float) -> Vec:
    p = value.tolist() if isinstance(value, np.ndarray) else value
    try:
        if len(p) != 3:  # type: ignore[arg-type]
            raise InputError(name, f"expected 3 numbers (m, ENU), got {len(p)}")  # type: ignore[arg-type]
        x, y, z = float(p[0]), float(p[1]), float(p[2])  # type: ignore[index]
    except (TypeError, ValueError):
        raise InputError(name, f"expected 3 numbers, got {value!r}") from None
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        raise InputError(name, f"not finite: {[x, y, z]}")
    if abs(x) > bound or abs(y) > bound or abs(z) > bound:
        raise InputError(name, f"component beyond {bound:g} (not a vehicle state): {[x, y, z]}")
    return x, y, z


def _finite(*groups: tuple[float, ...]) -> bool:
    for g in groups:
        for x in g:
            if not math.isfinite(x):
                return False
    return True


class _StartRamp:
    """Start gently, then never again: the reference speed's magnitude rises from the speed along
    the path at activation as ``sqrt(v0^2 + 2 a s)`` over the distance ``s`` travelled along the
    path since then (``a`` = ``limits.max_tangential_accel_m_s2``), with its feed-forward ``a``,
    and the speed loop's correction is bounded by ``a`` meanwhile. Once the ramp reaches the
    reference it is done until :meth:`reset` (activation): in steady state the speed loop is never
    bounded, whatever drag or estimator noise it has to hold against. A function of the distance
    travelled, not of time: like the projector's warm start, the only memory is where it began."""

    def __init__(self, accel_m_s2: float | None, lap_m: float | None, speed: float) -> None:
        self.accel = accel_m_s2
        self.lap = lap_m
        self.sign = 1.0 if speed > 0.0 else -1.0
        self.reset()

    def reset(self) -> None:
        self.done = self.accel is None
        self._eta1: float | None = None
        self._s = 0.0
        self._v0 = 0.0

    def _travelled(self, eta1: float) -> float:
        assert self._eta1 is not None
        d = eta1 - self._eta1
        if self.lap is not None:
            half = 0.5 * self.lap
            d = (d + half) % self.lap - half
        s = self._s + self.sign * d
        return s if s > 0.0 else 0.0

    def advance(self, eta1: float, speed_along_m_s: float) -> None:
        """Record the state of one control step (arclength m, speed along the tangent m/s)."""
        if self.done:
            return
        if self._eta1 is None:
            v0 = self.sign * speed_along_m_s
            self._v0 = v0 if v0 > 0.0 and math.isfinite(v0) else 0.0
            self._s = 0.0
        else:
            self._s = self._travelled(eta1)
        self._eta1 = eta1

    def speed(self, eta1: float) -> float | None:
        """|eta2_ref| the ramp allows at arclength ``eta1`` (m/s); None once done (or not started)."""
        if self.done or self._eta1 is None:
            return None
        assert self.accel is not None
        return math.sqrt(self._v0 * self._v0 + 2.0 * self.accel * self._travelled(eta1))


class PathFollower:
    """Time-invariant path-following controller of Kumar & Gill for one path.

    ``speed``: eta2_ref (m/s); its sign picks the direction of travel along the path parameter.
    ``projector``: anything with ``update(position) -> lam`` and ``reset()``; default
    :class:`pf_offboard.path.Projector`.
    """

    def __init__(
        self,
        path: Path,
        speed: float = DEFAULT_SPEED_M_S,
        *,
        gains: Gains | None = None,
        yaw: YawSpec | None = None,
        limits: Limits | None = None,
        projector: Any = None,
        vehicle: VehicleModel | None = None,
        compensation: Compensation | None = None,
        compensator: InnerLoopCompensator | None = None,
        speed_profile: SpeedProfileSpec | None = None,
        feedforward: str = "on_path",
    ) -> None:
        """The defaults are the shipped controller (the same a config with only ``path`` and
        ``speed_m_s`` builds): ``vehicle`` :meth:`VehicleModel.typical`, ``compensation``
        :class:`Compensation` () (observer + predictor + inversion + integral action; it acts when
        :meth:`update` gets ``time_s``), ``gains`` derived from the vehicle with the compensation's
        phase margins (``Gains()`` for the typical vehicle), ``limits`` :class:`Limits` ().
        ``compensator``: a ready :class:`InnerLoopCompensator` instead of the one ``vehicle`` and
        ``compensation`` describe. :meth:`paper` builds the paper's law as published."""
        try:
            speed = float(speed)
        except (TypeError, ValueError):
            raise InputError("speed_m_s", f"must be a number, got {speed!r}") from None
        if not math.isfinite(speed) or speed == 0.0 or abs(speed) > MAX_SPEED_M_S:
            raise InputError("speed_m_s", f"must be non-zero with |speed| <= {MAX_SPEED_M_S} m/s, got {speed}")
        self.path = path
        self.speed = speed
        self.vehicle = vehicle if vehicle is not None else VehicleModel.typical()
        self.compensation = compensation if compensation is not None else Compensation()
        if gains is None:
            c = self.compensation
            gains = gains_for_vehicle(self.vehicle, c.phase_margin_deg, c.tangential_phase_margin_deg)
        self.gains = gains
        self.yaw = yaw if yaw is not None else YawSpec()
        self.limits = limits if limits is not None else Limits()
        if projector is None:
            from pf_offboard.path import Projector

            projector = Projector(path)
        self.projector = projector
        # Inner-loop compensation (observer + predictor + inversion); None: the paper's ideal
        # inner loop. The measured state then gets its own projector for honest reporting.
        if compensator is None and self.compensation.enabled:
            c = self.compensation
            compensator = InnerLoopCompensator(
                self.vehicle, observer_rad_s=c.observer_rad_s,
                speed_integral_rad_s=c.integral_rad_s, offset_integral_rad_s=c.integral_rad_s,
                adapt=c.identify_online and self.vehicle == VehicleModel.typical(),
            )  # fmt: skip
        self.compensator = compensator
        self._measured_projector: Any = None
        if compensator is not None:
            from pf_offboard.path import Projector

            self._measured_projector = Projector(path)
        self.law = ControlLaw(self.gains, self.limits)
        if feedforward not in FEEDFORWARD_MODES:
            raise InputError("feedforward", f"must be one of {', '.join(FEEDFORWARD_MODES)}, got {feedforward!r}")
        if feedforward == "any_state" and compensator is not None:
            raise InputError("feedforward", ANY_STATE_NEEDS_NO_COMPENSATION)
        self.feedforward = feedforward
        # eta2_ref(eta1) from a speed profile (None: the constant ``speed``, as in the paper)
        # planned for the inner loop's response (lag + delay of the vehicle model; the paper's ideal
        # loop: 0): a slower loop plans lower accelerations
        response_s = max(self.vehicle.accel_lag_xy_s, self.vehicle.accel_lag_z_s) + self.vehicle.accel_delay_s
        self.profile = (SpeedProfile(path, speed_profile, self.limits, speed, response_s)
                        if speed_profile is not None else None)  # fmt: skip
        self._speed_profile_spec, self._response_s = speed_profile, response_s
        # re-planned for the identified response once the compensator adopts one (blended in from
        # then: replan_weight); None without a profile or without online identification
        self._replan_t0: float | None = None  # when the weight last started moving (None: never)
        self._replan_w = 0.0
        self._replan_target = False  # the re-planned profile wanted: an adopted model it was planned for
        self._replan_from = 0.0  # the weight when it started moving
        self.identified_profile = self._identified_profile()
        self._yaw = YawProfile(self.yaw, path.length_m, path.closed, speed)
        self._closed = bool(path.closed)
        self._lam_max = float(path.lam_max)
        self._length = float(path.length_m)
        self._eval = path.eval_floats
        self._jets = path.frame_jets
        self._arclength = path.arclength
        self._ramp = _StartRamp(self.limits.max_tangential_accel_m_s2, self._length if self._closed else None, speed)

    def cap_tilt(self, max_tilt_deg: float) -> None:
        """Plan and fly within ``max_tilt_deg`` (the autopilot's own tilt limit, read at connect)
        when it is below :attr:`limits`' ``max_tilt_deg``: the law's limits and the speed profile
        are rebuilt with it (before activation); otherwise nothing changes."""
        limits = self.limits.with_tilt_at_most(max_tilt_deg)
        if limits is self.limits:
            return
        self.limits = limits
        self.law = ControlLaw(self.gains, self.limits)
        if self._speed_profile_spec is not None:
            self.profile = SpeedProfile(self.path, self._speed_profile_spec, self.limits, self.speed, self._response_s, like=self.profile)
            self.identified_profile = self._identified_profile()

    def _replans(self, identified: Any) -> bool:
        """Whether an adopted model re-plans the speed profile: one with the model's lag (its dead
        time, gain and drag identified). A longer lag (ArduPilot's ``rates`` output through its
        attitude target, 0.15 s) is a slower loop: the profile planned for the model stays."""
        return identified is not None and identified.lag_s <= self.vehicle.accel_lag_xy_s + 1e-9

    def _identified_profile(self) -> SpeedProfile | None:
        """The speed profile flown once the compensator's identifier adopts a model with the
        model's lag: its dead time is then predicted by the identified amount, so the share of the
        limits is discounted for the lag only (``profile.py``, ``response_share``); the jerk stays
        planned for the model's lag + dead time (``JERK_RESPONSE_BUDGET_M_S2``). None when
        nothing can be identified or the plan would not change."""
        spec, comp = self._speed_profile_spec, self.compensator
        if spec is None or comp is None or getattr(comp, "identifier", None) is None:
            return None
        response_s = max(self.vehicle.accel_lag_xy_s, self.vehicle.accel_lag_z_s)
        if response_s >= self._response_s:
            return None
        return SpeedProfile(self.path, spec, self.limits, self.speed, response_s, like=self.profile, jerk_response_s=self._response_s)

    @classmethod
    def paper(
        cls, path: Path, speed: float = DEFAULT_SPEED_M_S, *, yaw: YawSpec | None = None, limits: Limits | None = None,
        projector: Any = None, speed_profile: SpeedProfileSpec | None = None, feedforward: str = "on_path",
    ) -> PathFollower:  # fmt: skip
        """The paper's law as published: :meth:`Gains.paper` (6 Hz / 0.7, 4 Hz / 0.8), no inner-loop
        compensation, no start ramp (``limits.max_tangential_accel_m_s2`` None unless ``limits``
        says otherwise). It needs the paper's ideal inner loop — an acceleration flown at once, no
        drag, no delay — and warns (:class:`UserWarning`) that a real vehicle is not one."""
        warnings.warn(PAPER_WARNING, UserWarning, stacklevel=2)
        if limits is None:
            limits = Limits(max_tangential_accel_m_s2=None)
        return cls(
            path, speed, gains=Gains.paper(), yaw=yaw, limits=limits, projector=projector, vehicle=VehicleModel(),
            compensation=Compensation.off(), speed_profile=speed_profile, feedforward=feedforward,
        )  # fmt: skip

    @classmethod
    def from_config(cls, config: ControllerConfig) -> PathFollower:
        """Build the path and follower from a loaded config (``pf_offboard.config.load_config``;
        the core never reads files)."""
        if isinstance(config, (str, os.PathLike)):
            raise InputError("config", "PathFollower.from_config takes a loaded config: "
                             "PathFollower.from_config(pf_offboard.config.load_config(path))")  # fmt: skip
        path = config.path.spline()
        return cls(
            path, config.speed_m_s, gains=config.gains, yaw=config.yaw, limits=config.limits,
            vehicle=config.vehicle, compensation=config.compensation,
            speed_profile=config.speed_profile, feedforward=config.feedforward,
        )  # fmt: skip

    def reset(self) -> None:
        """Forget the projection warm start and the compensator's state (activation, estimator
        reset, position jump)."""
        self.projector.reset()
        self._ramp.reset()
        if self.compensator is not None:
            self.compensator.reset()
            self._measured_projector.reset()

    def hold_heading(self, yaw_rad: float) -> bool:
        """With ``YawSpec.hold``, fly ``yaw_rad`` (ENU, rad) from now on: the app calls
        it at activation with the vehicle's heading, so following starts without a turn. Other yaw
        modes are left as they are. True if the heading was taken."""
        return self._yaw.hold(yaw_rad)

    # ------------------------------------------------------------------ exact coordinates
    def _terms(self, y: Vec, v: Vec) -> tuple[float, tuple[float, ...], ExactTerms]:
        lam = float(self.projector.update(y))
        s = self._eval(lam)
        (_, _, _), (e2, de2, dde2), (e3, de3, dde3) = self._jets(lam)
        terms = exact_terms(
            self._arclength(lam), s[0:3], s[3:6], s[6:9], s[9:12], e2, de2, dde2, e3, de3, dde3, y, v
        )
        return lam, s, terms

    def transverse_state(self, position: ArrayLike, velocity: ArrayLike) -> TransverseState:
        """T(x) = (eta1, eta2, xi1, xi2, phi1, phi2) (m, m/s) at this state (updates the warm start)."""
        return self._terms(_vec(position, "position", MAX_POSITION_ABS_M), _vec(velocity, "velocity", MAX_VELOCITY_ABS_M_S))[2].state

    def decoupling(self, position: ArrayLike, velocity: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(alpha (3,), beta (3, 3)) with d/dt (eta2, xi2, phi2) = alpha + beta a (updates the warm start)."""
        t = self._terms(_vec(position, "position", MAX_POSITION_ABS_M), _vec(velocity, "velocity", MAX_VELOCITY_ABS_M_S))[2]
        return np.array(t.alpha), np.array((t.beta1, t.beta2, t.beta3))

    def lap_time_bound_s(self) -> float:
        """The point-mass lower bound of the lap time at this follower's limits (s; an open path:
        start to end): the largest speed it flies (the speed profile's ``max_speed_m_s``, else
        ``|speed|``) and the thrust set of :attr:`limits` (:func:`~pf_offboard.control.profile.vehicle_lap_time_bound`)."""
        v = self.profile.spec.max_speed_m_s if self.profile is not None else abs(self.speed)
        return vehicle_lap_time_bound(self.path, self.limits, v, self.speed, like=self.profile)

    # ------------------------------------------------------------------ control
    def reference_speed(self, eta1: float) -> float:
        """eta2_ref at arclength eta1: ``speed`` (or the speed profile), slowed down to stop at the
        end of an open path."""
        if self.profile is not None:
            return self.reference(eta1)[0]
        if self._closed:
            return self.speed
        ahead = self._length - eta1 if self.speed > 0.0 else eta1
        stop = self.law.stopping_speed(ahead)
        return self.speed if abs(self.speed) <= stop else math.copysign(stop, self.speed)

    def reference(self, eta1: float) -> tuple[float, float, float]:
        """(eta2_ref m/s, d eta2_ref / d eta1 1/s, d2 eta2_ref / d eta1^2 1/(m s)) at arclength eta1.

        Without a speed profile: ``speed`` (slowed down at an open path's end) and zero
        derivatives, exactly the constant-speed law. With one: the profile, and on an open path
        the law's stopping speed where that is lower (with its derivatives)."""
        if self.profile is None:
            return self.reference_speed(eta1), 0.0, 0.0
        e, de, dde = self.profile.evaluate(eta1)
        w = self._replan_w
        if w > 0.0:
            assert self.identified_profile is not None
            e1, de1, dde1 = self.identified_profile.evaluate(eta1)
            k = 1.0 - w
            e, de, dde = k * e + w * e1, k * de + w * de1, k * dde + w * dde1
        if self._closed:
            return e, de, dde
        sign = 1.0 if self.speed > 0.0 else -1.0
        ahead = self._length - eta1 if sign > 0.0 else eta1
        stop = self.law.stopping_speed(ahead)
        if stop >= abs(e):
            return e, de, dde
        if ahead <= 0.0:
            return 0.0, 0.0, 0.0
        # d/d eta1 = -sign d/d ahead; linear k d or braking sqrt(2 a d) (law.stopping_speed)
        lin = self.law.k_pos_t * ahead
        if lin <= stop:
            return sign * stop, -self.law.k_pos_t, 0.0
        a_dec = self.law.a_dec
        return sign * stop, -a_dec / stop, sign * -a_dec * a_dec / stop**3

    def _reference_at(self, eta1: float) -> float:
        """eta2_ref at arclength ``eta1`` as :meth:`_evaluate` takes it: the profile (or speed),
        capped by the start ramp while it runs (no integral offsets)."""
        e = self.reference(eta1)[0]
        ramp = self._ramp.speed(eta1)
        return math.copysign(ramp, e) if ramp is not None and ramp < abs(e) else e

    def _evaluate(
        self, y: Vec, v: Vec, lam: float, s: tuple[float, ...], terms: ExactTerms,
        offsets: tuple[float, float, float] | None, bisection_steps: int | None = None,
    ) -> _Evaluation:  # fmt: skip
        """The law's acceleration (before the compensator) at one state and closest point: the
        map a_des(x) whose derivative along the closed-loop flow is the any-state feed-forward."""
        st = terms.state
        eta2_ref, deta2, ddeta2 = self.reference(st.eta1)
        # speed profile: the tangential feed-forward d(eta2_ref)/dt = eta2_ref'(eta1) eta2
        ff = deta2 * st.eta2
        cap = math.inf
        ramp = self._ramp.speed(st.eta1)
        if ramp is not None and ramp < abs(eta2_ref):
            # the start ramp: its speed, its feed-forward (a constant acceleration, faded out over
            # the ramp's last RAMP_END_S: no acceleration step where it ends), a bounded correction
            assert self._ramp.accel is not None
            cap = self._ramp.accel
            ff = self._ramp.sign * cap * min(1.0, (abs(eta2_ref) - ramp) / (cap * RAMP_END_S))
            eta2_ref, deta2, ddeta2 = math.copysign(ramp, eta2_ref), 0.0, 0.0
        # blend weight of the approach fallback
        r = (y[0] - s[0], y[1] - s[1], y[2] - s[2])
        dist = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
        w = _approach_weight(terms.tube, dist)
        past_end = False
        if not self._closed and (lam <= 0.0 or lam >= self._lam_max):
            out = terms.tangential_offset_m if lam > 0.0 else -terms.tangential_offset_m
            if out > 0.0:
                # beyond the end we travel towards: stop at the end point; beyond the start:
                # join at the start and go on (the approach law keeps eta2_ref along t)
                past_end = (lam > 0.0) == (self.speed > 0.0)
                w = max(w, out / END_BLEND_M)
        w = 0.0 if w <= 0.0 else (1.0 if w >= 1.0 else w)
        law = self.law
        eta2_ref_law = eta2_ref
        if offsets is not None and w < 1.0:
            # integral action as reference offsets: the law's limits and shaping act unchanged
            b_eta2, b_xi1, b_phi1 = offsets
            if not self._closed and abs(eta2_ref) < abs(self.speed):
                # slowing down to stop at an open path's end: the speed offset fades with the
                # reference (a negative one would otherwise stall the vehicle short of the end)
                b_eta2 *= abs(eta2_ref) / abs(self.speed)
            eta2_ref_law = eta2_ref + b_eta2
            terms = terms._replace(state=st._replace(xi1=st.xi1 + b_xi1, phi1=st.phi1 + b_phi1))
        tube: LawOutput | None = None
        if w < 1.0:
            tube = law.tube(terms, eta2_ref_law, ff, bisection_steps or BISECTION_STEPS, cap)
        if tube is None:
            w = 1.0
        # unit tangent and arclength derivatives at lam* (approach law, yaw, jerk feed-forward)
        tan, s_ss, s_sss = onpath_derivatives(s[3:6], s[6:9], s[9:12])
        if w > 0.0:
            app = law.approach(r, v, tan, 0.0 if past_end else eta2_ref, cap)
            if tube is None:
                res = app
            else:
                k = 1.0 - w
                res = LawOutput(
                    (
                        k * tube.accel[0] + w * app.accel[0],
                        k * tube.accel[1] + w * app.accel[1],
                        k * tube.accel[2] + w * app.accel[2],
                    ),
                    tube.tangential or app.tangential,
                    tube.transversal or app.transversal,
                    tube.approach_speed or app.approach_speed,
                )
        else:
            assert tube is not None
            res = tube
        return _Evaluation(st, eta2_ref, deta2, ddeta2, w, res, tan, s_ss, s_sss, dist)

    def _onpath_jerk(self, ev: _Evaluation) -> Vec:
        """d/dt of the on-path acceleration at eta2_ref(eta1) (m/s^3), faded out with the fallback
        weight. Constant speed E: sigma_sss E^3 (eqs. 25-27); with a profile E(eta1) also
        ``3 sigma_ss E^2 E' + t E (E'' E + E'^2)``."""
        e, w, s_sss = ev.eta2_ref, ev.w, ev.s_sss
        k3 = (1.0 - w) * e * e * e
        jerk = (s_sss[0] * k3, s_sss[1] * k3, s_sss[2] * k3)
        if self.profile is None:
            return jerk
        de, dde = ev.deta2_ref, ev.ddeta2_ref
        k2 = (1.0 - w) * 3.0 * e * e * de
        k1 = (1.0 - w) * e * (dde * e + de * de)
        t, ss = ev.tan, ev.s_ss
        return (jerk[0] + ss[0] * k2 + t[0] * k1, jerk[1] + ss[1] * k2 + t[1] * k1, jerk[2] + ss[2] * k2 + t[2] * k1)

    def _local_terms(self, lam0: float, y: Vec, v: Vec) -> tuple[float, tuple[float, ...], ExactTerms]:
        """Closest point near ``lam0`` by Newton on <sigma', sigma - y> = 0 (no projector state)
        and the exact terms there; an open path's parameter stays clamped to [0, lam_max]."""
        lam = lam0
        ev = self._eval
        clamped = not self._closed and (lam <= 0.0 or lam >= self._lam_max)
        if not clamped:
            for _ in range(3):
                q = ev(lam)
                rx, ry, rz = y[0] - q[0], y[1] - q[1], y[2] - q[2]
                f = q[3] * rx + q[4] * ry + q[5] * rz
                d = q[3] * q[3] + q[4] * q[4] + q[5] * q[5] - (q[6] * rx + q[7] * ry + q[8] * rz)
                if d <= 0.0:
                    break
                lam += f / d
            if not self._closed:
                lam = 0.0 if lam < 0.0 else (self._lam_max if lam > self._lam_max else lam)
        q = ev(lam)
        (_, _, _), (e2, de2, dde2), (e3, de3, dde3) = self._jets(lam)
        terms = exact_terms(
            self._arclength(lam), q[0:3], q[3:6], q[6:9], q[9:12], e2, de2, dde2, e3, de3, dde3, y, v
        )
        return lam, q, terms

    def _closed_loop_jerk(
        self, y: Vec, v: Vec, lam: float, terms: ExactTerms, accel: Vec, offsets: tuple[float, float, float] | None
    ) -> Vec:
        """d/dt a_des along the closed-loop flow (y' = v, v' = a_des; the ideal inner loop) at
        this state (m/s^3): a central directional derivative of the whole state feedback
        (projection, exact terms, limits, blends) over +-ANY_STATE_STEP_S, the bisections of the
        allocation refined so that the map is smooth. Capped at ANY_STATE_MAX_JERK_RATIO |f|
        where the law is not differentiable (a branch switch of the projection far away)."""
        h = ANY_STATE_STEP_S
        ld = terms.lam_dot
        out: list[Vec] = []
        for sgn in (1.0, -1.0):
            k = sgn * h
            yp = (y[0] + k * v[0], y[1] + k * v[1], y[2] + k * v[2])
            vp = (v[0] + k * accel[0], v[1] + k * accel[1], v[2] + k * accel[2])
            lp, sp, tp = self._local_terms(lam + k * ld, yp, vp)
            out.append(self._evaluate(yp, vp, lp, sp, tp, offsets, FINE_BISECTION_STEPS).res.accel)
        inv = 0.5 / h
        j = ((out[0][0] - out[1][0]) * inv, (out[0][1] - out[1][1]) * inv, (out[0][2] - out[1][2]) * inv)
        n = math.sqrt(j[0] * j[0] + j[1] * j[1] + j[2] * j[2])
        fz = accel[2] + G
        cap = ANY_STATE_MAX_JERK_RATIO * math.sqrt(accel[0] * accel[0] + accel[1] * accel[1] + fz * fz)
        if n > cap:
            c = cap / n
            j = (j[0] * c, j[1] * c, j[2] * c)
        return j

    def update(self, position: ArrayLike, velocity: ArrayLike, time_s: float | None = None) -> Command:
        """One control step at position (m) and velocity (m/s), world ENU.

        ``time_s``: the sample's time (s, any monotonic clock: the autopilot's boot time). With a
        :attr:`compensator` it drives the disturbance observer and the delay predictor (the law
        then acts on the predicted state and the command is the inverted setpoint); without a
        time, or without a compensator, the step is the paper's stateless law.

        Raises :class:`InputError` for non-finite input (never a command computed from NaN).
        """
        y = _vec(position, "position", MAX_POSITION_ABS_M)
        v = _vec(velocity, "velocity", MAX_VELOCITY_ABS_M_S)
        comp = self.compensator if time_s is not None else None
        y_meas, v_meas = y, v
        if comp is not None:
            t_s = float(time_s)  # type: ignore[arg-type]
            if not math.isfinite(t_s):
                raise InputError("time_s", f"must be finite, got {time_s!r}")
            y, v = comp.predict(t_s, y, v)
            if not _finite(y, v):
                comp.reset()
                y, v = y_meas, v_meas
            if self.identified_profile is not None:
                # the identified response's profile, blended in from its adoption; blended out again
                # if the rollback guard returns to a model it was not planned for (the typical one)
                want = self._replans(comp.identified)
                if want != self._replan_target:
                    self._replan_target, self._replan_from, self._replan_t0 = want, self._replan_w, t_s
                if self._replan_t0 is not None:
                    k, target = replan_weight(t_s - self._replan_t0), (1.0 if self._replan_target else 0.0)
                    self._replan_w = self._replan_from + (target - self._replan_from) * k
        lam_meas: float | None = None
        if comp is not None:
            # the measured state's closest point first; the law's (at the prediction) is searched
            # from it, so both stay on one branch: on a helix whose turns are closer than the
            # vehicle's offset, separate global searches put them on neighbouring turns (the law
            # then slowed for the end one turn early and the vehicle stalled between turns)
            lam_meas = float(self._measured_projector.update(y_meas))
            seed = getattr(self.projector, "seed", None)
            if seed is not None:
                seed(lam_meas, y, y_meas)
        lam, s, terms = self._terms(y, v)
        ramp = self._ramp
        if not ramp.done:
            d1 = s[3:6]
            n1 = math.sqrt(d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2])
            eta1 = terms.state.eta1
            ramp.advance(eta1, (v[0] * d1[0] + v[1] * d1[1] + v[2] * d1[2]) / n1)
            allowed = ramp.speed(eta1)
            if allowed is not None and allowed >= abs(self.reference(eta1)[0]) - RAMP_DONE_M_S:
                ramp.done = True
        offsets = comp.integral_offsets() if comp is not None else None
        ev = self._evaluate(y, v, lam, s, terms, offsets)
        st, eta2_ref, w, res, tan, s_ss = ev.state, ev.eta2_ref, ev.w, ev.res, ev.tan, ev.s_ss
        dist = ev.dist
        law = self.law
        ax, ay, az = res.accel
        # on-path jerk at eta2_ref (eqs. 25-27: jerk = sigma_sss eta2_ref^3), faded out with the
        # fallback weight (no on-path motion to anticipate far away): feed-forward of the body
        # rates (the paper's ideal inner loop) or of the identified inner loop's lag (compensated)
        jerk = self._onpath_jerk(ev)
        if comp is not None:
            # the setpoint that makes the identified vehicle fly res.accel, kept feasible; the
            # lag's phase is inverted along the path by leading with lag * jerk. That lead
            # replaces the roll/pitch rate feed-forward: the attitude loop tracks the led
            # setpoint, and omega_ff on top of it would lead twice
            # the drag is inverted at the on-path reference velocity, the deviation's share bounded
            v_ref = (tan[0] * eta2_ref, tan[1] * eta2_ref, tan[2] * eta2_ref)
            sp = comp.invert(t_s, comp.lead((ax, ay, az), jerk), v, v_ref)
            # feasible, recorded, and the faster axis group's held back (InnerLoopCompensator.horizon_s)
            ax, ay, az = comp.commit(t_s, sp, law.thrust_set.clip)
            jerk_rates: Vec = (0.0, 0.0, 0.0)
        elif self.feedforward == "any_state":  # refused with a compensator (constructor)
            jerk_rates = self._closed_loop_jerk(y, v, lam, terms, res.accel, offsets)
        else:
            jerk_rates = jerk
        f = (ax, ay, az + G)
        thrust = math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
        tilt, thrust_sat = law.thrust_set.active(f)
        psi, dpsi = self._yaw.evaluate(st.eta1, tan, s_ss)
        eta2 = _blended_speed(st.eta2, w, tan, v)
        yaw_rate = dpsi * eta2
        axes = attitude_from_thrust(f, psi)
        q = quaternion_from_axes(*axes)
        omega = body_rates(axes, thrust, jerk_rates, yaw_rate)
        if not _finite((ax, ay, az), q, omega, (thrust, psi, yaw_rate)):  # last line of defence
            raise InputError("state", f"no finite command at position {list(y)}, velocity {list(v)}")
        if comp is not None:
            # report the measured state, not the prediction the law acted on
            assert lam_meas is not None
            lam = lam_meas
            sm = self._eval(lam)
            dist = math.sqrt((y_meas[0] - sm[0]) ** 2 + (y_meas[1] - sm[1]) ** 2 + (y_meas[2] - sm[2]) ** 2)
            mt = evaluate_terms(self.path, lam, y_meas, v_meas)
            # report eta2 faded into the tangential speed outside the tube, as the law does
            t_m = sm[3:6]
            n_t = math.sqrt(t_m[0] * t_m[0] + t_m[1] * t_m[1] + t_m[2] * t_m[2])
            w_m = min(_approach_weight(mt.tube, dist), 1.0)
            st = mt.state._replace(eta2=_blended_speed(mt.state.eta2, w_m, (t_m[0] / n_t, t_m[1] / n_t, t_m[2] / n_t), v_meas))
            # integrate the measured errors only in the exact tube and while nothing saturates
            free = w == 0.0 and not (res.tangential or res.transversal or tilt or thrust_sat)
            comp.integrate(t_s, eta2_ref - st.eta2, st.xi1, st.phi1, free)
            comp.watch(t_s, dist, eta2_ref - st.eta2)  # the rollback guard's errors (measured)
            # report the reference at the measured state's arclength too: the law's is at the
            # prediction's (a horizon ahead, PX4 0.13 s), which on a speed profile read as a speed
            # error of the vehicle (real PX4 SIH figure-eight at 3 m/s: 31 cm/s, 12-16 against this)
            eta2_ref = self._reference_at(st.eta1)
        return Command(
            acceleration=np.array((ax, ay, az)),
            thrust=thrust,
            attitude=np.array(q),
            body_rates=np.array(omega),
            yaw=wrap_pi(psi),
            yaw_rate=yaw_rate,
            state=st,
            lam=lam,
            cross_track_m=dist,
            saturation=Saturation(res.tangential, res.transversal, tilt, thrust_sat, res.approach_speed),
            eta2_ref_m_s=eta2_ref,
        )
