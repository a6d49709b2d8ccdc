"""A short, bounded excitation at hover, flown through the app's own pipeline.

:class:`ExcitationFollower` stands in for the path follower (same ``update(position, velocity) ->
Command`` / ``reset()`` interface), so ``fly``'s machinery — :class:`~pf_offboard.app.pipeline.Pipeline`,
the encoders of every output mode, :class:`~pf_offboard.app.flight.Flight` (activation, keep-alive,
stale-state watchdog, take-over, hand-back), the ``.tlog`` / ``.csv`` logs — flies it unchanged.
:func:`excite` is ``identify --connect``: it connects like ``fly``, flies the excitation, hands back in
the hold mode and returns the log directory for :mod:`.cli` to fit.

The excitation (world ENU, m/s²): first ``settle_s`` of stiff position hold around the start ``p0``
(PID, its integral learns a constant disturbance such as a wrong hover thrust), then per axis a
sequence of doublets ``+A`` for T then ``−A`` for T (T random in ``dwell_s``, a rest of random length
between doublets, amplitudes and default signs from an explicit seeded generator, independent per
axis; the sign steers towards p0 when the vehicle is off it) on top of a soft hold
``−ω²(p − p0) − 2ζω v − I`` (integral I frozen). A doublet returns the velocity to zero, so the
vehicle stays within about ``A·T²`` (0.4 m horizontal, 0.3 m vertical at the defaults) of p0.

Limits (checked every step; any one aborts): position outside the ``box_m`` half-width cube around
p0, speed above ``max_speed_m_s``, measured tilt above ``max_tilt_deg``. On abort the follower
commands the position hold alone (no excitation) and the bridge is asked to hand back (hold mode).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pf_offboard.control.feedforward import attitude_from_thrust, quaternion_from_axes
from pf_offboard.control.types import GRAVITY_M_S2, Command, Saturation, TransverseState
from pf_offboard.errors import InputError

_NAN_STATE = TransverseState(math.nan, math.nan, math.nan, math.nan, math.nan, math.nan)


@dataclass(frozen=True)
class ExcitationSpec:
    """The excitation and its limits. World ENU; units in the names."""

    duration_s: float = 16.0  # excitation time after the settle
    settle_s: float = 3.0  # stiff hold (with integral) at the start before the first doublet
    amplitude_xy_m_s2: float = 0.6
    amplitude_z_m_s2: float = 0.5
    dwell_s: tuple[float, float] = (0.4, 0.8)  # half-length T of a doublet, uniform
    rest_s: tuple[float, float] = (0.0, 0.5)  # pause between doublets, uniform
    hold_bandwidth_rad_s: float = 0.6  # ω of the position hold (soft: see ExcitationSignal)
    hold_damping: float = 0.5  # ζ of the position hold (soft: see ExcitationSignal)
    settle_bandwidth_rad_s: float = 1.5  # ω of the settle hold: PID with a triple pole at −ω
    box_m: float = 1.0  # abort when |p − p0| exceeds this on any axis
    max_speed_m_s: float = 2.0
    max_tilt_deg: float = 35.0
    max_accel_m_s2: float = 4.0  # |commanded acceleration| clip (hold + excitation)
    seed: int = 0

    def __post_init__(self) -> None:
        checks = {
            "--duration": (self.duration_s, 2.0, 60.0),
            "settle_s": (self.settle_s, 0.0, 10.0),
            "amplitude_xy_m_s2": (self.amplitude_xy_m_s2, 0.05, 3.0),
            "amplitude_z_m_s2": (self.amplitude_z_m_s2, 0.05, 3.0),
            "hold_bandwidth_rad_s": (self.hold_bandwidth_rad_s, 0.1, 5.0),
            "hold_damping": (self.hold_damping, 0.1, 3.0),
            "settle_bandwidth_rad_s": (self.settle_bandwidth_rad_s, 0.2, 5.0),
            "--box": (self.box_m, 0.2, 5.0),
            "--max-speed": (self.max_speed_m_s, 0.2, 10.0),
            "--max-tilt": (self.max_tilt_deg, 5.0, 60.0),
            "max_accel_m_s2": (self.max_accel_m_s2, 0.5, 10.0),
        }
        for name, (v, lo, hi) in checks.items():
            if not (math.isfinite(v) and lo <= v <= hi):
                raise InputError(name, f"must be in [{lo:g}, {hi:g}], got {v}")
        for name, (lo, hi) in (("dwell_s", self.dwell_s), ("rest_s", self.rest_s)):
            if not (0.0 <= lo <= hi <= 5.0):
                raise InputError(name, f"must be 0 <= min <= max <= 5 s, got ({lo}, {hi})")
        if not 0 <= self.seed < 2**63:
            raise InputError("--seed", f"must be in [0, 2^63), got {self.seed}")

    @property
    def total_s(self) -> float:
        """Settle + excitation + 1 s of hold at the end (the flight's length after activation)."""
        return self.settle_s + self.duration_s + 1.0


@dataclass(frozen=True)
class ExcitationSignal:
    """Per axis (x, y, z; ENU), a schedule of doublets: doublet ``k`` starts ``start_s[k]`` seconds
    after the excitation's start, is ``level_m_s2[k]`` for ``half_s[k]`` then the opposite for as
    long. Its sign is chosen when it starts (:meth:`sign_for`): towards the start position when the
    vehicle is off it, else ``random_sign[k]``; so the excitation itself keeps the vehicle near the
    start and the position hold can stay soft (a stiff hold would make the setpoint a copy of the
    velocity, and drag could not be told from gain)."""

    start_s: tuple[NDArray[np.float64], ...]
    half_s: tuple[NDArray[np.float64], ...]
    level_m_s2: tuple[NDArray[np.float64], ...]
    random_sign: tuple[NDArray[np.float64], ...]
    end_s: float

    @classmethod
    def doublets(cls, spec: ExcitationSpec) -> ExcitationSignal:
        """Random doublets per axis from ``np.random.default_rng(spec.seed)`` (see the module)."""
        rng = np.random.default_rng(spec.seed)
        starts, halves, levels, signs = [], [], [], []
        for amplitude in (spec.amplitude_xy_m_s2, spec.amplitude_xy_m_s2, spec.amplitude_z_m_s2):
            t, st, hf, lv, sg = 0.0, [], [], [], []
            while True:
                t += float(rng.uniform(*spec.rest_s))
                half = float(rng.uniform(*spec.dwell_s))
                if t + 2.0 * half > spec.duration_s:
                    break
                st.append(t)
                hf.append(half)
                lv.append(amplitude * float(rng.uniform(0.6, 1.0)))
                sg.append(1.0 if rng.random() < 0.5 else -1.0)
                t += 2.0 * half
            starts.append(np.array(st))
            halves.append(np.array(hf))
            levels.append(np.array(lv))
            signs.append(np.array(sg))
        return cls(tuple(starts), tuple(halves), tuple(levels), tuple(signs), spec.duration_s)

    def doublet_at(self, axis: int, t_s: float) -> int:
        """Index of the doublet running on ``axis`` at ``t_s`` (−1: none, resting)."""
        k = int(np.searchsorted(self.start_s[axis], t_s, side="right")) - 1
        if k < 0 or t_s >= self.start_s[axis][k] + 2.0 * self.half_s[axis][k]:
            return -1
        return k

    def sign_for(self, axis: int, k: int, offset_m: float, deadband_m: float = 0.1) -> float:
        """Sign of doublet ``k``'s first half given the offset from the start on that axis (m)."""
        if abs(offset_m) > deadband_m:
            return -1.0 if offset_m > 0.0 else 1.0
        return float(self.random_sign[axis][k])

    def value(self, axis: int, k: int, t_s: float, sign: float) -> float:
        """Acceleration (m/s²) of doublet ``k`` at ``t_s`` with its first half's ``sign``."""
        first = t_s < self.start_s[axis][k] + self.half_s[axis][k]
        return float(sign * self.level_m_s2[axis][k] * (1.0 if first else -1.0))


@dataclass
class ExcitationFollower:
    """Excitation + position hold around the first position seen (``update`` like PathFollower).

    ``clock`` returns the current vehicle time (s; the state sample's autopilot clock), so the
    excitation is a deterministic function of the telemetry (``replay`` reproduces it).
    ``yaw_rad``: heading held (ENU, rad); None: the heading ``attitude()`` reports at the first
    update (0 if unknown). After :attr:`abort_reason` is set, only the hold is flown.
    """

    spec: ExcitationSpec
    clock: Callable[[], float]
    yaw_rad: float | None = None
    attitude: Callable[[], NDArray[np.float64] | None] = field(default=lambda: None)
    signal: ExcitationSignal = field(init=False)
    start_position_enu_m: NDArray[np.float64] | None = field(default=None, init=False)
    start_time_s: float | None = field(default=None, init=False)
    abort_reason: str = field(default="", init=False)
    _signs: dict[tuple[int, int], float] = field(default_factory=dict, init=False)
    _integral_m_s2: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3), init=False)
    _last_time_s: float | None = field(default=None, init=False)
    speed = math.nan  # no path speed (Pipeline reads it for the step log)

    def __post_init__(self) -> None:
        self.signal = ExcitationSignal.doublets(self.spec)

    def reset(self) -> None:
        """An estimator reset: the position may have jumped, so hold where we are now."""
        self.start_position_enu_m = None

    def limit_violation(self, position: NDArray[np.float64], velocity: NDArray[np.float64]) -> str:
        """Which limit the state breaks ("" if none)."""
        s = self.spec
        assert self.start_position_enu_m is not None
        off = np.abs(position - self.start_position_enu_m)
        if float(np.max(off)) > s.box_m:
            return f"left the {s.box_m:g} m box around the start (offset {np.round(position - self.start_position_enu_m, 2).tolist()} m ENU)"
        speed = float(np.linalg.norm(velocity))
        if speed > s.max_speed_m_s:
            return f"speed {speed:.2f} m/s above {s.max_speed_m_s:g} m/s"
        q = self.attitude()
        if q is not None:
            w, x, y, z = q
            cos_tilt = 1.0 - 2.0 * (x * x + y * y)  # body z · world z
            tilt = math.degrees(math.acos(max(-1.0, min(1.0, cos_tilt))))
            if tilt > s.max_tilt_deg:
                return f"tilt {tilt:.0f} deg above {s.max_tilt_deg:g} deg"
        return ""

    def excitation_time_s(self) -> float:
        """Seconds since the excitation started (negative while settling)."""
        assert self.start_time_s is not None
        return self.clock() - self.start_time_s - self.spec.settle_s

    def _excitation(self, offset_enu_m: NDArray[np.float64]) -> NDArray[np.float64]:
        t = self.excitation_time_s()
        out = np.zeros(3)
        if t < 0.0 or t >= self.signal.end_s:
            return out
        for axis in range(3):
            k = self.signal.doublet_at(axis, t)
            if k < 0:
                continue
            if (axis, k) not in self._signs:  # decided once, when the doublet starts
                self._signs[(axis, k)] = self.signal.sign_for(axis, k, float(offset_enu_m[axis]))
            out[axis] = self.signal.value(axis, k, t, self._signs[(axis, k)])
        return out

    def update(self, position: ArrayLike, velocity: ArrayLike, time_s: float | None = None) -> Command:
        """Acceleration = hold + excitation (clipped); attitude and thrust from it (ENU, FLU).

        ``time_s`` is accepted as a compensated follower's is (a pipeline built for one passes the
        sample time) and not used: the excitation runs on the vehicle clock it was given."""
        p = np.asarray(position, dtype=float)
        v = np.asarray(velocity, dtype=float)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(v))):
            raise InputError("state", "non-finite position or velocity")
        if self.start_position_enu_m is None:
            self.start_position_enu_m = p.copy()
        if self.start_time_s is None:
            self.start_time_s = self.clock()
        if self.yaw_rad is None:
            from pf_offboard.app.encoders import yaw_of

            q = self.attitude()
            self.yaw_rad = yaw_of(q) if q is not None else 0.0
        s = self.spec
        if not self.abort_reason:
            self.abort_reason = self.limit_violation(p, v)
        now = self.clock()
        dt = 0.0 if self._last_time_s is None else min(max(now - self._last_time_s, 0.0), 0.1)
        self._last_time_s = now
        e = p - self.start_position_enu_m
        if self.excitation_time_s() < 0.0 or self.abort_reason:
            # settle (and after an abort): stiff PID, triple pole at -ω; the integral learns the
            # constant disturbance (a hover-thrust error, wind) so the soft hold need not fight it
            w = s.settle_bandwidth_rad_s
            self._integral_m_s2 = self._integral_m_s2 + (w**3) * e * dt
            accel = -3.0 * w * w * e - 3.0 * w * v - self._integral_m_s2
        else:
            # excitation: soft PD, integral frozen, doublets on top
            w = s.hold_bandwidth_rad_s
            accel = -w * w * e - 2.0 * s.hold_damping * w * v - self._integral_m_s2
            accel = accel + self._excitation(e)
        norm = float(np.linalg.norm(accel))
        if norm > s.max_accel_m_s2:
            accel *= s.max_accel_m_s2 / norm
        f = (float(accel[0]), float(accel[1]), float(accel[2]) + GRAVITY_M_S2)
        thrust = math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
        yaw = float(self.yaw_rad)
        q = quaternion_from_axes(*attitude_from_thrust(f, yaw))
        return Command(
            acceleration=accel,
            thrust=thrust,
            attitude=np.array(q),
            body_rates=np.zeros(3),
            yaw=yaw,
            yaw_rate=0.0,
            state=_NAN_STATE,
            lam=math.nan,
            cross_track_m=float(np.linalg.norm(p - self.start_position_enu_m)),
            saturation=Saturation(False, False, False, norm > s.max_accel_m_s2, False),
        )


# ---------------------------------------------------------------------------------- identify --connect
def excitation_status(line: str, follower: ExcitationFollower, record: Any, rate_hz: float) -> str:
    """The status line of an excitation: it has no path (the path-following line would show
    η1 nan), so its time and its offset from the start, after the line's mode and arming."""
    if record is None or follower.start_position_enu_m is None or follower.start_time_s is None:
        return line
    head = line.split("  η1", 1)[0].split("  rate", 1)[0]
    off = np.asarray(record.position_enu_m, dtype=float) - follower.start_position_enu_m
    t = follower.excitation_time_s()
    when = f"excitation {t:5.1f} s of {follower.spec.duration_s:.0f}" if t >= 0.0 else f"settling, excitation in {-t:.1f} s"
    return (f"{head}  {when}  "
            f"offset from the start E {off[0]:+5.2f} N {off[1]:+5.2f} U {off[2]:+5.2f} m  rate {rate_hz:5.0f} Hz")  # fmt: skip


@dataclass(frozen=True)
class ExciteOutcome:
    """How the excitation flight ended."""

    exit_code: int  # as fly's: 0 ok, 3 link, 4 taken over
    reason: str
    log_dir: Path | None
    tlog: Path | None
    aborted: str  # the limit that aborted the excitation ("" if none)


@dataclass(frozen=True)
class ExciteRequest:
    """``identify --connect``'s flags, typed (built once from the command line)."""

    connect: str
    config_path: str
    takeoff_m: float | None = None  # None: airborne
    output: str | None = None
    autopilot: str = "auto"
    target_system: int | None = None
    heartbeat_timeout_s: float = 10.0
    set_guid_options: bool = False
    log_dir: str | None = None
    quiet: bool = False

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> ExciteRequest:
        return cls(
            connect=args.connect, config_path=str(args.config), takeoff_m=args.takeoff, output=args.output,
            autopilot=args.autopilot, target_system=args.target_system, heartbeat_timeout_s=args.heartbeat_timeout,
            set_guid_options=bool(args.set_guid_options), log_dir=args.log_dir, quiet=bool(args.quiet),
        )  # fmt: skip


def excite(args: argparse.Namespace | ExciteRequest, spec: ExcitationSpec, stream: TextIO) -> ExciteOutcome:
    """Connect, fly the excitation (``--airborne`` or ``--takeoff``), hand back; never hangs."""
    import asyncio

    from pf_offboard.app.settings import flight_settings_for
    from pf_offboard.app.link import parse_endpoint
    from pf_offboard.config import load_config
    from pf_offboard.errors import LinkError

    request = args if isinstance(args, ExciteRequest) else ExciteRequest.from_args(args)
    endpoint = parse_endpoint(request.connect)
    endpoint.check_local()
    config = load_config(request.config_path)
    settings = flight_settings_for(config, output=request.output)
    if request.takeoff_m is not None and not (math.isfinite(request.takeoff_m) and 0.3 <= request.takeoff_m <= 100.0):
        raise InputError("--takeoff", f"height must be in [0.3, 100] m, got {request.takeoff_m}")
    if request.log_dir:
        from pf_offboard.logs._io import make_dir

        make_dir(request.log_dir, "--log-dir")
    try:
        return asyncio.run(_excite(request, endpoint, config, settings, spec, stream))
    except LinkError as exc:
        print(f"pf-offboard identify: link error: {exc}", file=stream)
        return ExciteOutcome(3, str(exc), None, None, "")


async def _excite(request: ExciteRequest, endpoint: Any, config: Any, settings: Any, spec: ExcitationSpec, stream: TextIO) -> ExciteOutcome:
    """The excitation as a client of the API (:mod:`pf_offboard.api`): one flight with the
    excitation follower in place of a path's, handed back in hold; Ctrl-C hands back as fly does."""
    import asyncio
    import signal

    from pf_offboard.api.vehicle import ConnectSettings, FlightHooks, FollowSettings, Vehicle
    from pf_offboard.app.settings import default_log_dir
    from pf_offboard.errors import FlightError

    followers: list[ExcitationFollower] = []

    def make_follower(estimator: Any) -> ExcitationFollower:
        # as fly: the velocity made consistent with the position. EKF2's velocity is 10-40 cm/s off
        # its position's derivative on PX4 SIH; the soft hold's damping on it alone drifted the
        # real vehicle out of the 1 m box 3 s into the excitation (docs/identify.md)
        def vehicle_time() -> float:
            est = estimator.latest
            return est.time_s if est is not None else 0.0

        def attitude() -> NDArray[np.float64] | None:
            est = estimator.latest
            return est.q_enu_flu if est is not None else None

        followers.append(ExcitationFollower(spec, vehicle_time, attitude=attitude))
        return followers[-1]

    def on_step(step: Any, flight: Any) -> None:
        follower = followers[-1]
        if follower.abort_reason and step.record.mode == "following":
            flight.request_stop(f"excitation aborted: {follower.abort_reason}")

    loop = asyncio.get_running_loop()

    def started(flight: Any) -> None:
        loop.add_signal_handler(signal.SIGINT, flight.request_stop)  # Ctrl-C: hand back, as fly does
        # no path: the status line shows the excitation's time and offset, never η1 nan
        flight.status_hook = lambda line, f: excitation_status(
            line, followers[-1], None if f.last_step is None else f.last_step.record, f.loop_rate_hz
        )

    def ended(flight: Any) -> None:
        loop.remove_signal_handler(signal.SIGINT)

    connect = ConnectSettings(endpoint, request.autopilot, request.target_system, request.heartbeat_timeout_s, None, request.quiet)
    follow = FollowSettings(
        launch="takeoff" if request.takeoff_m is not None else "airborne",
        height_m=request.takeoff_m if request.takeoff_m is not None else math.nan,
        duration_s=spec.total_s, open_path_end=False, output=settings.output_mode, end_action="hold",
        set_guid_options=request.set_guid_options, log_dir=request.log_dir or str(default_log_dir()),
    )  # fmt: skip
    hooks = FlightHooks(
        on_start=started, on_end=ended, config_path=request.config_path, log_name="identify", follower_factory=make_follower,
        flight_config=config, on_step=on_step, wait_for_streams=False, output_warnings=False,
    )  # fmt: skip
    async with Vehicle(connect, stream) as vehicle:
        try:
            result = await vehicle._run(None, follow, hooks)
        except FlightError as exc:
            if exc.result is None:
                raise
            result = exc.result
    # the flight's own outcome; identify's exit code comes after the fit (a flight that ended well
    # can still be too short or too poor to fit)
    ended = "flown; fitting its log next" if result.exit_code == 0 else f"ended (exit {result.exit_code})"
    print(f"pf-offboard identify: excitation flight {ended}: {result.reason}", file=stream)
    tlog = result.log_dir / "identify.tlog" if result.log_dir is not None else None
    return ExciteOutcome(result.exit_code, result.reason, result.log_dir, tlog, followers[-1].abort_reason if followers else "")


# ---------------------------------------------------------------------------------- in process (sim)
def simulate_excitation(
    config_path: str | Path,
    sim_spec: Any,
    spec: ExcitationSpec,
    out_dir: str | Path,
    prepare: Callable[[Any], None] | None = None,
) -> Any:
    """The excitation flown in process against the mock (``pf_offboard.sim``'s lockstep flight,
    the excitation follower in place of the path follower). ``sim_spec``: a
    :class:`pf_offboard.sim.flight.SimSpec` (vehicle preset, output mode, rate, start, duration).
    ``prepare(flight)`` may change the mock before it flies (tests: a wrong hover-thrust parameter).
    Returns its :class:`~pf_offboard.sim.flight.SimResult`; the ``.tlog`` is what ``identify`` reads.
    """
    from pf_offboard.sim.flight import SimFlight

    flight = SimFlight(config_path, sim_spec, out_dir)
    estimator = flight.pipeline.estimator

    def vehicle_time() -> float:
        est = estimator.latest
        return est.time_s if est is not None else 0.0

    def attitude() -> NDArray[np.float64] | None:
        est = estimator.latest
        return est.q_enu_flu if est is not None else None

    flight.pipeline.follower = ExcitationFollower(spec, vehicle_time, attitude=attitude)
    flight.pipeline.speed_ref_m_s = math.nan
    if prepare is not None:
        prepare(flight)
    return flight.run()
