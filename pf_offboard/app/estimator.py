"""Vehicle state from MAVLink telemetry, in the core's frames (world ENU, body FLU).

Pure: messages in, :class:`StateEstimate` out; no clocks, no I/O. The one place where telemetry
(NED / FRD) is turned into the core's frames, always through :mod:`pf_offboard.frames`.

Sources: position + velocity from LOCAL_POSITION_NED or ODOMETRY (whichever arrives first is
used from then on, so one sample is never counted twice); attitude and body rates from
ATTITUDE_QUATERNION (or ODOMETRY's pose when that is the source). Non-finite or malformed
samples are rejected and counted, never passed to the controller; so are duplicated or reordered
ones (a sample time not newer than the last), which are not fresh.

Plausibility (telemetry can be late, duplicated, corrupt in ways the CRC passes, or spoofed):

- time: each stream (position/velocity; ATTITUDE_QUATERNION) keeps its own clock. A sample up to
  FORWARD_JUMP_S newer than the last accepted one is accepted; one older by less than
  REORDER_WINDOW_S (or equal) is a duplicate / reordered datagram, rejected. Anything else — a
  jump forward beyond FORWARD_JUMP_S (a future-dated sample) or back beyond the window (a reboot)
  — is a *candidate* new timeline, rejected, and adopted only when the very next sample of the
  stream confirms it (newer than the candidate by at most CONFIRM_WINDOW_S). A sample continuing
  the accepted timeline drops the candidate: one future-dated sample cannot make the genuine
  ones "not newer", and spoofs interleaved with the genuine stream never make a "reboot".
- position: a sample farther from the last accepted one than the vehicle could have moved
  (``JUMP_MARGIN_M + (speed + JUMP_SPEED_SLACK_M_S) * dt``) is rejected (``rejected_jumps``);
  if the next sample confirms the new place it is accepted as an estimator reset
  (``position_resets``, ``reset_pending`` with ``reset_reason``). ODOMETRY's reset_counter
  announces a reset itself and is believed.
- physical limits: a sample claiming more than MAX_SPEED_M_S, or a velocity change from the last
  trusted sample beyond what MAX_ACCEL_M_S2 allows, is refused like a position jump (until the next
  sample confirms it). The distance a vehicle may have moved is bounded by the *previous trusted*
  speed, never by the new sample's own claim (a corrupt x = 40 m with vx = 5000 m/s is refused).
- resets of any size: a sample whose position step differs from the one its velocity explains by
  more than RESET_STEP_M (plus what the velocity change explains) is accepted but flagged as an
  estimator reset (``position_resets``, ``last_reset_enu_m``); so is an ODOMETRY reset_counter
  change. What a reset means for the flight is the envelope's decision (safety.max_estimator_reset_m).
- health: ODOMETRY ``quality`` -1 (estimate lost) refuses that sample; ESTIMATOR_STATUS (PX4) and
  EKF_STATUS_REPORT (ArduPilot) reports missing a needed solution (attitude, velocity, relative
  horizontal and vertical position), flagging a glitch / constant-position mode, or with a test
  ratio / variance at or above 1 make the estimate *degraded* once HEALTH_CONFIRM reports in a row
  say so (never on one report): position samples are then refused (``rejected_unhealthy``,
  ``health_reason`` says why) until a healthy report; the state goes stale and following ends.
- ``StateEstimate.clock_s`` is one continuous clock over the flight (jumps excluded), for
  durations: a clock jump does not make a duration span two clocks.

Velocity consistency (``velocity_correction_s``, off when None): the controller steers the
*position* estimate onto the path and damps with the *velocity* estimate, so the two must agree. On
PX4 SIH they do not: EKF2's velocity is 10-40 cm/s RMS off the derivative of its own position
(biased, drifting over ~10 s) while that derivative is close to the true velocity (ground truth),
and a velocity bias b leaves the position a lap-periodic ~(k_d / k_p)·|b| off the path. The
correction adds to the reported velocity a low-pass (time constant ``velocity_correction_s``) of
(Δposition / Δt − mean velocity) between consecutive samples: the velocity's high-frequency content
is kept, its low-frequency content becomes the position's. Each sample's residual is bounded by
VELOCITY_RESIDUAL_MAX_M_S and the correction by VELOCITY_CORRECTION_MAX_M_S; a sample after a gap,
a reset or a clock re-anchoring does not update it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pf_offboard import frames

MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_BODY_FRD = 12

SOURCES = ("auto", "local_position", "odometry")


@dataclass(frozen=True)
class StateEstimate:
    """Latest vehicle state, core frames. ``time_s`` is the autopilot's clock (s since boot)."""

    time_s: float
    position_enu_m: NDArray[np.float64]
    velocity_enu_m_s: NDArray[np.float64]
    q_enu_flu: NDArray[np.float64] | None  # (w, x, y, z) body FLU -> world ENU; None until known
    rates_flu_rad_s: NDArray[np.float64] | None
    sample: int  # count of position/velocity samples accepted so far
    # continuous time of the accepted samples (s from the first), clock jumps excluded; None: time_s
    clock_s: float | None = None


def flight_clock_s(est: StateEstimate) -> float:
    """The estimate's time on one continuous clock (for durations across autopilot clock jumps)."""
    return est.clock_s if est.clock_s is not None else est.time_s


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def rotate(q_wxyz: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotate a vector by a unit quaternion (body -> world, same frame convention both sides)."""
    w, x, y, z = q_wxyz
    u = np.array([x, y, z])
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _unit_quat(q: Any) -> NDArray[np.float64] | None:
    a = np.asarray(q, dtype=float)
    if a.shape != (4,) or not all(map(math.isfinite, a.tolist())):
        return None
    n = float(np.linalg.norm(a))
    if abs(n - 1.0) > 1e-2:  # MAVLink quaternions are unit; anything else is corrupt
        return None
    return a / n


# A sample not newer than the last one, by less than this, is a duplicated or reordered datagram
# (not fresh: it must not step the controller or feed the stale-state watchdog).
REORDER_WINDOW_S = 10.0
# A sample newer than the last accepted one by more than this is not simply the next one (a blackout
# longer than this has already ended following through the state timeout, <= 5 s): a candidate.
FORWARD_JUMP_S = 1.0
# A candidate timeline is adopted when the next sample is newer than it by at most this.
CONFIRM_WINDOW_S = 1.0
# Position plausibility: a vehicle moves at most (speed + slack) * dt between samples, plus a margin
# for estimator noise and small corrections. 1 m: PX4 / ArduPilot fuse GPS in steps well below it;
# 5 m/s: a hard manoeuvre's speed change over one sample interval, generously.
JUMP_MARGIN_M = 1.0
JUMP_SPEED_SLACK_M_S = 5.0
# Physical limits of the vehicles this app flies (generous): a sample beyond them is corrupt.
MAX_SPEED_M_S = 40.0
MAX_ACCEL_M_S2 = 40.0  # ~4 g between two samples
VELOCITY_MARGIN_M_S = 3.0  # velocity noise / small estimator velocity corrections between samples
# A position step this much larger than the velocity explains is an estimator reset (flagged).
RESET_STEP_M = 0.3
# Estimator health reports (ESTIMATOR_STATUS / EKF_STATUS_REPORT): this many bad in a row degrade it.
HEALTH_CONFIRM = 2
# ESTIMATOR_STATUS_FLAGS (PX4) and EKF_STATUS_FLAGS (ArduPilot) share these bits.
_NEEDED_FLAGS = 1 | 2 | 4 | 8 | 32  # attitude, horizontal / vertical velocity, relative horizontal and vertical position
_BAD_FLAGS = {128: "constant position mode", 1024: "GPS glitch / uninitialised", 2048: "accelerometer error", 32768: "GPS glitching"}

NEW, OLD, PENDING, REANCHOR = "new", "old", "pending", "reanchor"

# Velocity consistency: one sample's (Δposition / Δt − velocity) beyond this is a GPS step or a
# reset, not a bias (bounded so that it moves the correction by at most this · Δt / τ); a correction
# beyond this is a broken estimator, not one the app should fly on (it is held there); samples more
# than VELOCITY_CORRECTION_GAP_S apart do not update it.
VELOCITY_RESIDUAL_MAX_M_S = 2.0
VELOCITY_CORRECTION_MAX_M_S = 1.0
VELOCITY_CORRECTION_GAP_S = 0.5


def velocity_correction_step(
    correction: NDArray[np.float64],
    dt_s: float,
    tau_s: float,
    position_step_m: NDArray[np.float64],
    velocity_before_m_s: NDArray[np.float64],
    velocity_m_s: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The velocity correction after one more sample (any one frame, m/s): a first-order low-pass
    (time constant ``tau_s``) of Δposition / Δt − the two samples' mean velocity, each residual
    bounded by VELOCITY_RESIDUAL_MAX_M_S and the result by VELOCITY_CORRECTION_MAX_M_S. Unchanged
    when the samples are not 0 < ``dt_s`` <= VELOCITY_CORRECTION_GAP_S apart. One rule for the app's
    :class:`Estimator` and for ``identify``, which fits the velocity the app flew on."""
    if not 0.0 < dt_s <= VELOCITY_CORRECTION_GAP_S:
        return correction
    residual = position_step_m / dt_s - 0.5 * (velocity_m_s + velocity_before_m_s)
    residual = np.clip(residual, -VELOCITY_RESIDUAL_MAX_M_S, VELOCITY_RESIDUAL_MAX_M_S)
    out = correction + (1.0 - math.exp(-dt_s / tau_s)) * (residual - correction)
    norm = float(np.linalg.norm(out))
    return out * (VELOCITY_CORRECTION_MAX_M_S / norm) if norm > VELOCITY_CORRECTION_MAX_M_S else out


def position_consistent_velocity(
    time_s: NDArray[np.float64], position_m: NDArray[np.float64], velocity_m_s: NDArray[np.float64], tau_s: float
) -> NDArray[np.float64]:
    """A whole recorded series (N samples, any one frame) corrected as :class:`Estimator` corrects
    it live: each velocity plus the correction after its own sample (zero at the first)."""
    out = np.array(velocity_m_s, dtype=float, copy=True)
    correction = np.zeros(out.shape[1])
    for k in range(1, len(out)):
        correction = velocity_correction_step(
            correction, float(time_s[k] - time_s[k - 1]), tau_s, position_m[k] - position_m[k - 1], velocity_m_s[k - 1], velocity_m_s[k]
        )
        out[k] += correction
    return out


class _Clock:
    """Sample-time acceptance of one stream (see the module docstring). Pure."""

    def __init__(self) -> None:
        self.last_s: float | None = None
        self.candidate_s: float | None = None

    def classify(self, t_s: float) -> str:
        last = self.last_s
        if last is None:
            return NEW
        d = t_s - last
        if 0.0 < d <= FORWARD_JUMP_S:
            return NEW
        if -REORDER_WINDOW_S < d <= 0.0:
            return OLD
        c = self.candidate_s
        if c is not None and 0.0 < t_s - c <= CONFIRM_WINDOW_S:
            return REANCHOR
        return PENDING

    def commit(self, t_s: float, verdict: str) -> None:
        """Record an accepted sample (NEW / REANCHOR) or a new candidate (PENDING)."""
        if verdict == PENDING:
            self.candidate_s = t_s
        elif verdict in (NEW, REANCHOR):
            self.last_s, self.candidate_s = t_s, None


class Estimator:
    """Fold telemetry into a :class:`StateEstimate`.

    :meth:`on_message` returns True when the message brought a fresh position/velocity sample
    (the pipeline steps the controller exactly then). ``reset_pending`` turns True when the
    position may have jumped (ODOMETRY ``reset_counter`` changed, a confirmed position jump, a
    confirmed clock jump); ``reset_reason`` says which. The caller resets the follower's warm start.

    Counters for monitors (e.g. a flight-envelope check ending following on an estimator reset):
    ``rejected`` (all refused samples), ``rejected_old`` (duplicated / reordered),
    ``rejected_jumps`` (implausible position jumps refused), ``position_resets`` (jumps confirmed
    and accepted as estimator resets), ``clock_jumps`` (candidate timelines refused),
    ``clock_reanchors`` (timelines adopted); ``last_event`` describes the latest of these.
    """

    def __init__(self, source: str = "auto", velocity_correction_s: float | None = None) -> None:
        if source not in SOURCES:
            raise ValueError(f"state source must be one of {SOURCES}, got {source!r}")
        if velocity_correction_s is not None and not (math.isfinite(velocity_correction_s) and velocity_correction_s > 0.0):
            raise ValueError(f"velocity_correction_s must be > 0 s or None, got {velocity_correction_s!r}")
        self._source = source
        self._vc_tau_s = velocity_correction_s
        self._vc_bias_ned = np.zeros(3)
        self._vc_last: tuple[float, NDArray[np.float64], NDArray[np.float64]] | None = None  # t, pos, raw vel (NED)
        self._vc_skip = False
        self._q_ned_frd: NDArray[np.float64] | None = None
        self._rates_frd: NDArray[np.float64] | None = None
        self._latest: StateEstimate | None = None
        self._reset_counter: int | None = None
        self._pos_clock = _Clock()
        self._att_clock = _Clock()
        self._jump_candidate: tuple[float, NDArray[np.float64], NDArray[np.float64]] | None = None
        self._clock_s = 0.0
        self.samples = 0
        self.attitude_samples = 0  # attitudes accepted (ATTITUDE_QUATERNION, or ODOMETRY's pose)
        self.rejected = 0
        self.rejected_old = 0
        self.rejected_jumps = 0
        self.rejected_unhealthy = 0  # samples refused: ODOMETRY quality -1, or the estimator reports degraded
        self.position_resets = 0
        self.last_reset_enu_m: NDArray[np.float64] | None = None  # the latest reset's jump (ENU m)
        self.health_reason = ""  # why the estimate is degraded ("" healthy)
        self._bad_reports = 0
        self.clock_jumps = 0
        self.clock_reanchors = 0
        self.last_event = ""
        self.reset_pending = False
        self.reset_reason = ""

    @property
    def source(self) -> str:
        return self._source

    @property
    def latest(self) -> StateEstimate | None:
        return self._latest

    @property
    def velocity_correction_enu_m_s(self) -> NDArray[np.float64]:
        """The correction added to the reported velocity, world ENU m/s (zeros when off)."""
        return frames.ned_to_enu(self._vc_bias_ned)

    def _corrected_velocity(self, time_s: float, pos_ned: NDArray[np.float64], vel_ned: NDArray[np.float64], verdict: str) -> NDArray[np.float64]:
        """The velocity made consistent with the position's derivative (module docstring), NED m/s."""
        tau = self._vc_tau_s
        if tau is None:
            return vel_ned
        prev, self._vc_last = self._vc_last, (time_s, pos_ned, vel_ned)
        skip, self._vc_skip = self._vc_skip, False
        if prev is not None and verdict == NEW and not skip:
            self._vc_bias_ned = velocity_correction_step(self._vc_bias_ned, time_s - prev[0], tau, pos_ned - prev[1], prev[2], vel_ned)
        return vel_ned + self._vc_bias_ned

    def on_message(self, msg: Any) -> bool:
        kind = msg.get_type()
        if kind == "ATTITUDE_QUATERNION":
            self._attitude(msg)
            return False
        if kind == "LOCAL_POSITION_NED" and self._source in ("auto", "local_position"):
            return self._local_position(msg)
        if kind == "ODOMETRY" and self._source in ("auto", "odometry"):
            return self._odometry(msg)
        if kind in ("ESTIMATOR_STATUS", "EKF_STATUS_REPORT"):
            self._health_report(kind, msg)
        return False

    def _health_report(self, kind: str, msg: Any) -> None:
        """ESTIMATOR_STATUS (PX4) / EKF_STATUS_REPORT (ArduPilot): degraded after HEALTH_CONFIRM
        bad reports in a row, healthy again on the first good one."""
        why = estimator_report_problem(kind, msg)
        if not why:
            self._bad_reports = 0
            if self.health_reason:
                self.last_event = f"estimator healthy again ({kind})"
            self.health_reason = ""
            return
        self._bad_reports += 1
        if self._bad_reports >= HEALTH_CONFIRM and not self.health_reason:
            self.health_reason = f"{kind}: {why}"
            self.last_event = f"estimator degraded: {self.health_reason}"

    def _unhealthy(self) -> bool:
        """Refuse a position sample while the estimator reports itself degraded (counted)."""
        if not self.health_reason:
            return False
        self.rejected += 1
        self.rejected_unhealthy += 1
        return True

    def _reset(self, reason: str, jump_ned_m: NDArray[np.float64] | None = None) -> None:
        # None: a reset of unknown size (a clock re-anchoring): no size to judge it by
        self.last_reset_enu_m = frames.ned_to_enu(jump_ned_m) if jump_ned_m is not None else None
        self._vc_skip = True  # the position jumped: this sample's Δposition is not a velocity
        self.reset_pending = True
        self.reset_reason = reason
        self.last_event = reason

    def _time_verdict(self, clock: _Clock, time_s: float, what: str) -> str:
        """Classify a sample time; count and commit the refusals (OLD / PENDING)."""
        verdict = clock.classify(time_s)
        if verdict == OLD:
            self.rejected += 1
            self.rejected_old += 1
        elif verdict == PENDING:
            self.rejected += 1
            self.clock_jumps += 1
            last = clock.last_s if clock.last_s is not None else math.nan
            self.last_event = f"{what} time jumped {time_s - last:+.3f} s; sample refused until confirmed"
            clock.commit(time_s, verdict)
        return verdict

    def _attitude(self, msg: Any) -> None:
        q = _unit_quat((msg.q1, msg.q2, msg.q3, msg.q4))
        rates = (msg.rollspeed, msg.pitchspeed, msg.yawspeed)
        if q is None or not _finite(*rates):
            self.rejected += 1
            return
        t = msg.time_boot_ms * 1e-3
        verdict = self._time_verdict(self._att_clock, t, "attitude")
        if verdict in (OLD, PENDING):
            return  # an older attitude than the one we have (or an unconfirmed clock) is never used
        self._att_clock.commit(t, verdict)
        if verdict == REANCHOR:
            self.clock_reanchors += 1
        self._q_ned_frd = q
        self._rates_frd = np.array(rates, dtype=float)
        self.attitude_samples += 1

    def _plausible(self, time_s: float, pos_ned: NDArray[np.float64], vel_ned: NDArray[np.float64], verdict: str, announced: bool) -> bool:
        """Position-jump and physical-limit check of a sample whose time was accepted; False:
        refused (counted). Resets of any size are flagged here (accepted)."""
        last = self._latest
        if last is None or verdict == REANCHOR:
            self._jump_candidate = None
            return _norm3(vel_ned) <= MAX_SPEED_M_S or self._refuse_jump(time_s, pos_ned, vel_ned, last)
        prev_pos = frames.enu_to_ned(last.position_enu_m)
        prev_vel = frames.enu_to_ned(last.velocity_enu_m_s)
        if announced or _consistent(prev_pos, prev_vel, last.time_s, pos_ned, vel_ned, time_s):
            self._jump_candidate = None  # continues the accepted track (drops an unconfirmed jump)
            step = _unexplained_step(prev_pos, prev_vel, last.time_s, pos_ned, vel_ned, time_s)
            if not announced and _norm3(step) > RESET_STEP_M + 0.5 * _norm3(vel_ned - prev_vel) * max(time_s - last.time_s, 0.0):
                self.position_resets += 1
                self._reset(f"position stepped {float(np.linalg.norm(step)):.2f} m beyond its velocity (estimator reset)", step)
            return True
        jump_m = float(np.linalg.norm(pos_ned - prev_pos))
        c = self._jump_candidate
        if c is not None and 0.0 < time_s - c[0] <= CONFIRM_WINDOW_S and _consistent(c[1], c[2], c[0], pos_ned, vel_ned, time_s):
            self._jump_candidate = None
            self.position_resets += 1
            self._reset(f"position jumped {jump_m:.2f} m in {time_s - last.time_s:.3f} s (confirmed: estimator reset)",
                        _unexplained_step(prev_pos, prev_vel, last.time_s, pos_ned, vel_ned, time_s))  # fmt: skip
            return True
        return self._refuse_jump(time_s, pos_ned, vel_ned, last)

    def _refuse_jump(self, time_s: float, pos_ned: NDArray[np.float64], vel_ned: NDArray[np.float64], last: StateEstimate | None) -> bool:
        self._jump_candidate = (time_s, pos_ned, vel_ned)
        self.rejected += 1
        self.rejected_jumps += 1
        speed = float(np.linalg.norm(vel_ned))
        if last is None:
            self.last_event = f"sample claims {speed:.1f} m/s (beyond {MAX_SPEED_M_S:g} m/s); refused"
        else:
            jump_m = float(np.linalg.norm(pos_ned - frames.enu_to_ned(last.position_enu_m)))
            dv = float(np.linalg.norm(vel_ned - frames.enu_to_ned(last.velocity_enu_m_s)))
            self.last_event = (f"position jumped {jump_m:.2f} m, velocity {dv:.1f} m/s in {time_s - last.time_s:.3f} s "
                               "(beyond the vehicle's limits); refused until confirmed")  # fmt: skip
        return False

    def _accept(self, time_s: float, pos_ned: NDArray[np.float64], vel_ned: NDArray[np.float64], source: str, verdict: str) -> bool:
        if self._source == "auto":
            self._source = source  # lock onto the first source seen
        self.samples += 1
        last = self._latest
        if last is not None and verdict == NEW:
            self._clock_s += time_s - last.time_s  # a confirmed jump (REANCHOR) adds no time
        self._pos_clock.commit(time_s, verdict)
        vel_ned = self._corrected_velocity(time_s, pos_ned, vel_ned, verdict)
        q = None if self._q_ned_frd is None else frames.quat_ned_frd_to_enu_flu(self._q_ned_frd)
        rates = None if self._rates_frd is None else frames.frd_to_flu(self._rates_frd)
        self._latest = StateEstimate(
            time_s=time_s,
            position_enu_m=frames.ned_to_enu(pos_ned),
            velocity_enu_m_s=frames.ned_to_enu(vel_ned),
            q_enu_flu=q,
            rates_flu_rad_s=rates,
            sample=self.samples,
            clock_s=self._clock_s,
        )
        return True

    def _position_time(self, time_s: float) -> str | None:
        """The time verdict of a position sample, or None when it is refused."""
        verdict = self._time_verdict(self._pos_clock, time_s, "state")
        return None if verdict in (OLD, PENDING) else verdict

    def _reanchored(self, time_s: float) -> None:
        """A confirmed new timeline: the continuous clock does not count the jump."""
        last = self._latest
        self.clock_reanchors += 1
        jump = time_s - last.time_s if last is not None else 0.0
        if jump > 0.0:
            # forward and confirmed: the stream resumed after a gap (the state timeout, not the
            # estimator, decides whether following survives one); no position reset implied
            self.last_event = f"state resumed {jump:.3f} s later (confirmed by the next sample)"
            return
        self._reset(f"autopilot clock jumped {jump:+.3f} s (confirmed: reboot or clock reset)")

    def _local_position(self, msg: Any) -> bool:
        values = (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz)
        t = msg.time_boot_ms * 1e-3
        if not _finite(*values):
            self.rejected += 1
            return False
        if self._unhealthy():
            return False
        verdict = self._position_time(t)
        if verdict is None:
            return False
        pos, vel = np.array(values[:3], dtype=float), np.array(values[3:], dtype=float)
        if not self._plausible(t, pos, vel, verdict, announced=False):
            return False
        if verdict == REANCHOR:
            self._reanchored(t)
        return self._accept(t, pos, vel, "local_position", verdict)

    def _odometry(self, msg: Any) -> bool:
        if msg.frame_id != MAV_FRAME_LOCAL_NED:  # LOCAL_FRD is heading-aligned, not NED
            self.rejected += 1
            return False
        t = msg.time_usec * 1e-6
        pos = np.array((msg.x, msg.y, msg.z), dtype=float)
        vel = np.array((msg.vx, msg.vy, msg.vz), dtype=float)
        q = _unit_quat(msg.q)
        rates = np.array((msg.rollspeed, msg.pitchspeed, msg.yawspeed), dtype=float)
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(vel))) or q is None:
            self.rejected += 1
            return False
        if int(getattr(msg, "quality", 0)) < 0:  # -1: the estimate has failed (MAVLink ODOMETRY.quality)
            self.rejected += 1
            self.rejected_unhealthy += 1
            self.last_event = "ODOMETRY quality -1 (estimate lost): sample refused"
            return False
        if self._unhealthy():
            return False
        verdict = self._position_time(t)
        if verdict is None:
            return False
        if msg.child_frame_id == MAV_FRAME_BODY_FRD:
            vel = rotate(q, vel)  # PX4 reports ODOMETRY velocity in the body frame
        counter = int(msg.reset_counter)
        announced = self._reset_counter is not None and counter != self._reset_counter
        if not self._plausible(t, pos, vel, verdict, announced):
            return False
        if verdict == REANCHOR:
            self._reanchored(t)
        self._q_ned_frd = q
        if np.all(np.isfinite(rates)):
            self._rates_frd = rates
        self.attitude_samples += 1
        if announced:
            self.position_resets += 1
            last = self._latest
            jump = None
            if last is not None:
                jump = _unexplained_step(frames.enu_to_ned(last.position_enu_m), frames.enu_to_ned(last.velocity_enu_m_s), last.time_s, pos, vel, t)
            self._reset(f"estimator reset_counter {self._reset_counter} -> {counter}", jump)
        self._reset_counter = counter
        return self._accept(t, pos, vel, "odometry", verdict)


def _norm3(v: NDArray[np.float64]) -> float:
    """Euclidean length of a 3-vector on plain floats (the gates run on every sample; np.linalg.norm
    costs ~3 us per call)."""
    x, y, z = v.tolist()
    return math.sqrt(x * x + y * y + z * z)


def _consistent(
    p0_ned: NDArray[np.float64], v0_ned: NDArray[np.float64], t0_s: float, p1_ned: NDArray[np.float64], v1_ned: NDArray[np.float64], t1_s: float
) -> bool:
    """Could a vehicle at p0 with velocity v0 (trusted) at t0 be at p1 with velocity v1 at t1?
    (generous bounds: speed, acceleration; the distance from the *trusted* speed only)"""
    dt = max(t1_s - t0_s, 0.0)
    speed0 = _norm3(v0_ned)
    if _norm3(v1_ned) > MAX_SPEED_M_S or speed0 > MAX_SPEED_M_S:
        return False
    if _norm3(v1_ned - v0_ned) > VELOCITY_MARGIN_M_S + MAX_ACCEL_M_S2 * dt:
        return False
    allowed = JUMP_MARGIN_M + (speed0 + JUMP_SPEED_SLACK_M_S) * dt
    return _norm3(p1_ned - p0_ned) <= allowed


def _unexplained_step(
    p0_ned: NDArray[np.float64], v0_ned: NDArray[np.float64], t0_s: float, p1_ned: NDArray[np.float64], v1_ned: NDArray[np.float64], t1_s: float
) -> NDArray[np.float64]:
    """The part of a position step the two samples' mean velocity does not explain (NED m)."""
    dt = max(t1_s - t0_s, 0.0)
    return (p1_ned - p0_ned) - 0.5 * (v0_ned + v1_ned) * dt


def estimator_report_problem(kind: str, msg: Any) -> str:
    """Why an ESTIMATOR_STATUS / EKF_STATUS_REPORT says the position estimate is not fit to fly
    on ("" if it is): a needed solution missing, a glitch flag, a test ratio / variance >= 1."""
    try:
        flags = int(msg.flags)
    except (AttributeError, TypeError, ValueError):
        return "no flags"
    missing = _NEEDED_FLAGS & ~flags
    if missing:
        return f"flags 0x{flags:x} lack a needed solution (0x{missing:x})"
    for bit, name in _BAD_FLAGS.items():
        if flags & bit:
            return f"flags 0x{flags:x}: {name}"
    ratios = ("vel_ratio", "pos_horiz_ratio", "pos_vert_ratio") if kind == "ESTIMATOR_STATUS" else ("velocity_variance", "pos_horiz_variance", "pos_vert_variance")
    for name in ratios:
        value = float(getattr(msg, name, 0.0))
        if not math.isfinite(value) or value >= 1.0:
            return f"{name} {value:.2f} (>= 1: the estimate fails its own consistency test)"
    return ""
