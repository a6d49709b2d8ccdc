"""What ``identify`` needs from a flight log: setpoints and the vehicle's response, resampled.

Reads a ``fly`` / ``sim`` ``.tlog`` (or ``.tlog.gz``) and returns :class:`Segment` s: stretches of
uniformly resampled data where the app's setpoints were flying the vehicle. This is the only I/O
of :mod:`pf_offboard.identify`; the fitting (:mod:`.fit`) works on these arrays.

Clocks: every sample is put on the **autopilot's boot clock** (seconds). Telemetry carries it
(``time_boot_ms``); so do pf-offboard's setpoints: each is stamped with the boot time of the
telemetry sample it answers and sent at once, which places it exactly (the few milliseconds of
transport then count as delay only where they are not already in the telemetry's own latency).
Whether a log's setpoints carry such stamps is judged by the log's *order* alone: a stamp must lie
near the boot time of the latest LOCAL_POSITION_NED received before the setpoint was sent (no
wall clock involved: a lockstep simulator's boot clock runs at any multiple of wall-clock time,
and not evenly). For setpoints without such stamps the tlog's UNIX stamps are mapped through a
line fitted to the LOCAL_POSITION_NED receptions (slope and offset: a SITL's clock need not run
at wall-clock rate; offset at the lower envelope, the fastest delivery).

Active samples: a setpoint counts when it is an acceleration setpoint (SET_POSITION_TARGET_LOCAL_NED
with position ignored and acceleration used), or a SET_ATTITUDE_TARGET (quaternion + thrust, or
body rates + thrust), sent while the autopilot's latest HEARTBEAT said armed and in the app's mode
(PX4 OFFBOARD / ArduPilot GUIDED). Take-off position setpoints and anything before the mode switch
are left out. A grid sample is used when its setpoint is at most ``MAX_SETPOINT_AGE_S`` old.

Velocity: LOCAL_POSITION_NED's velocity as reported, or (``velocity_correction_s``) made consistent
with the position's derivative as the app's :class:`~pf_offboard.app.estimator.Estimator` does in
flight. Which is better depends on where the estimate errs (docs/identify.md, *Velocity*): on PX4
SIH in path flight EKF2's velocity drifts 10-40 cm/s off its position's derivative, below 1 Hz where
drag acts, and the correction brings the mock's ``px4-sih`` drag from 0.82-0.95 to 0.92-1.03 for its
1.0 (20 s path logs, eight seeds); at hover the position's own wander dominates and the correction
made the real PX4 SIH's excitation fits worse. So it is asked for, not the default.

Frames: velocities and accelerations are converted to world ENU, attitudes to body FLU → ENU,
through :mod:`pf_offboard.frames`; body rates stay body FRD (only their magnitude response is fitted).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pf_offboard import frames
from pf_offboard.app.encoders import flown_when_tilting_from_gravity
from pf_offboard.app.estimator import position_consistent_velocity
from pf_offboard.control.types import GRAVITY_M_S2
from pf_offboard.errors import InputError

SETPOINT_KINDS = ("acceleration", "attitude", "rates")
MAX_SETPOINT_AGE_S = 0.25  # a setpoint older than this no longer describes what the vehicle flies
STAMP_TOLERANCE_S = 1.0  # a setpoint's boot stamp vs the latest telemetry received before it was sent
CLOCK_SLOPE_RANGE = (0.02, 50.0)  # UNIX s per boot s a (lockstep) simulator may plausibly run at
MIN_SEGMENT_S = 1.0  # shorter active stretches are dropped
THRUST_NORM_G_M_S2 = 9.81  # the encoders' thrust normalisation: thrust = T / 9.81 * hover_thrust
HOVER_THRUST_PARAMS = ("MPC_THR_HOVER", "MOT_THST_HOVER")

_MAV_AUTOPILOT_INVALID = 8
_ARMED = 128
_PX4_OFFBOARD_MAIN = 6
_ARDUPILOT_GUIDED = (4, 20)  # GUIDED, GUIDED_NOGPS
_MAV_AUTOPILOT_PX4 = 12
_POS_IGNORE = 0x007
_ACC_IGNORE = 0x1C0
_ATTITUDE_IGNORE = 128
_MAV_FRAME_LOCAL_NED = 1


@dataclass(frozen=True)
class Segment:
    """One stretch of active flight on a uniform grid (autopilot boot clock).

    ``accel_sp_enu_m_s2``: the acceleration the app asked for (world ENU, gravity excluded),
    held from each setpoint to the next; for attitude setpoints ``T·z_b(q_sp) − g·e_z`` with
    ``T = thrust / hover_thrust · 9.81``; for body-rate setpoints the same with the *measured*
    attitude. ``velocity_enu_m_s``: LOCAL_POSITION_NED velocity (position-consistent when asked,
    see the module docstring), linearly interpolated.
    ``rates_sp_frd_rad_s`` / ``rates_frd_rad_s``: body-rate setpoints and ATTITUDE_QUATERNION
    rates (rates-mode logs only, else None).
    ``thrust_axis_up``: the vertical (ENU up) component of the measured thrust axis, i.e. the
    cosine of the measured tilt, from ATTITUDE_QUATERNION (linearly interpolated); None when the
    log has no attitude covering the whole segment.
    """

    source: str
    kind: str  # acceleration | attitude | rates
    time_s: NDArray[np.float64]  # (N,) s, boot clock, uniform step dt_s
    dt_s: float
    accel_sp_enu_m_s2: NDArray[np.float64]  # (N, 3)
    velocity_enu_m_s: NDArray[np.float64]  # (N, 3)
    rates_sp_frd_rad_s: NDArray[np.float64] | None = None  # (N, 3)
    rates_frd_rad_s: NDArray[np.float64] | None = None  # (N, 3)
    thrust_axis_up: NDArray[np.float64] | None = None  # (N,) cos(measured tilt), dimensionless

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0]) if len(self.time_s) > 1 else 0.0


@dataclass(frozen=True)
class LogData:
    """Everything identify took from one log: its active segments and how they were found."""

    source: str
    kind: str  # the setpoint kind flown (acceleration | attitude | rates)
    segments: tuple[Segment, ...]
    hover_thrust: float | None  # used to turn attitude / rates thrust into acceleration
    hover_thrust_source: str  # "--hover-thrust", "config", "MPC_THR_HOVER", ... or "" (not needed)
    clock_slope: float  # UNIX seconds per boot-clock second (1.0 for a real-time SITL)
    velocity_correction_s: float | None = None  # the velocity fitted was made position-consistent (s); None: as reported

    @property
    def duration_s(self) -> float:
        return float(sum(s.duration_s for s in self.segments))


@dataclass
class _Raw:
    lpn_t: list[float]
    lpn_unix: list[float]
    lpn_v_ned: list[tuple[float, float, float]]
    lpn_p_ned: list[tuple[float, float, float]]
    att_t: list[float]
    att_q_ned_frd: list[tuple[float, float, float, float]]
    att_rates_frd: list[tuple[float, float, float]]
    hb_unix: list[float]
    hb_active: list[bool]
    sp_unix: list[float]
    sp_boot: list[float]
    sp_lpn_boot: list[float]  # boot time of the latest LOCAL_POSITION_NED received before it (−inf: none)
    sp_kind: list[str]
    sp_accel_ned: list[tuple[float, float, float]]
    sp_q_ned_frd: list[tuple[float, float, float, float]]
    sp_rates_frd: list[tuple[float, float, float]]
    sp_thrust: list[float]
    params: dict[str, float]
    autopilot: int | None
    param_types: dict[str, int] = field(default_factory=dict)


def _heartbeat_active(msg: Any) -> bool:
    if not msg.base_mode & _ARMED:
        return False
    if msg.autopilot == _MAV_AUTOPILOT_PX4:
        return (msg.custom_mode >> 16) & 0xFF == _PX4_OFFBOARD_MAIN
    return msg.custom_mode in _ARDUPILOT_GUIDED


def _read_raw(path: Path) -> _Raw:
    from pf_offboard.logs.flightlog import FlightLogPaths
    from pf_offboard.logs.foreign import iter_tlog_lenient
    from pf_offboard.logs.tlog import iter_tlog

    raw = _Raw([], [], [], [], [], [], [], [], [], [], [], [], [], [], [], [], [], {}, None)
    last_lpn_t = -math.inf
    # pf-offboard's own logs (its step log beside them) strictly; anyone else's (MAVProxy) leniently
    ours = FlightLogPaths.beside(path).steps_csv.exists() or path.name.endswith(".gz")
    for entry in iter_tlog(path) if ours else iter_tlog_lenient(path):
        msg = entry.message
        kind = msg.get_type()
        if entry.direction == "in":
            if kind == "LOCAL_POSITION_NED":
                t = msg.time_boot_ms * 1e-3
                v = (msg.vx, msg.vy, msg.vz)
                pos = (msg.x, msg.y, msg.z)
                if t > last_lpn_t and all(map(math.isfinite, v + pos)):  # drop duplicated / reordered samples
                    last_lpn_t = t
                    raw.lpn_t.append(t)
                    raw.lpn_unix.append(entry.time_unix_s)
                    raw.lpn_v_ned.append(v)
                    raw.lpn_p_ned.append(pos)
            elif kind == "ATTITUDE_QUATERNION":
                q = (msg.q1, msg.q2, msg.q3, msg.q4)
                r = (msg.rollspeed, msg.pitchspeed, msg.yawspeed)
                if all(map(math.isfinite, q + r)) and abs(math.sqrt(sum(c * c for c in q)) - 1.0) < 1e-2:
                    raw.att_t.append(msg.time_boot_ms * 1e-3)
                    raw.att_q_ned_frd.append(q)
                    raw.att_rates_frd.append(r)
            elif kind == "HEARTBEAT" and msg.autopilot != _MAV_AUTOPILOT_INVALID:
                raw.autopilot = msg.autopilot
                raw.hb_unix.append(entry.time_unix_s)
                raw.hb_active.append(_heartbeat_active(msg))
            elif kind == "PARAM_VALUE":
                pid = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode(errors="replace")
                raw.params[pid.rstrip("\x00")] = float(msg.param_value)
                raw.param_types[pid.rstrip("\x00")] = int(msg.param_type)
            continue
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            mask = msg.type_mask
            ok = msg.coordinate_frame == _MAV_FRAME_LOCAL_NED and mask & _POS_IGNORE == _POS_IGNORE and not mask & _ACC_IGNORE
            raw.sp_unix.append(entry.time_unix_s)
            raw.sp_boot.append(msg.time_boot_ms * 1e-3)
            raw.sp_lpn_boot.append(last_lpn_t)
            raw.sp_kind.append("acceleration" if ok else "other")
            raw.sp_accel_ned.append((msg.afx, msg.afy, msg.afz))
            raw.sp_q_ned_frd.append((1.0, 0.0, 0.0, 0.0))
            raw.sp_rates_frd.append((0.0, 0.0, 0.0))
            raw.sp_thrust.append(math.nan)
        elif kind == "SET_ATTITUDE_TARGET":
            raw.sp_unix.append(entry.time_unix_s)
            raw.sp_boot.append(msg.time_boot_ms * 1e-3)
            raw.sp_lpn_boot.append(last_lpn_t)
            raw.sp_kind.append("rates" if msg.type_mask & _ATTITUDE_IGNORE else "attitude")
            raw.sp_accel_ned.append((math.nan, math.nan, math.nan))
            raw.sp_q_ned_frd.append(tuple(float(c) for c in msg.q))  # type: ignore[arg-type]
            raw.sp_rates_frd.append((msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate))
            raw.sp_thrust.append(float(msg.thrust))
    return raw


def _read_raw_ulog(path: Path, truth: bool = False) -> _Raw:
    """A PX4 ULog as :class:`_Raw`: PX4's own record of the offboard setpoints it received, its
    estimate (``truth``: SIH's ground truth instead) and its mode, all on its boot clock (the
    clock map is then the identity)."""
    from pf_offboard.logs.ulog import read_ulog

    flight = read_ulog(path)
    raw = _Raw([], [], [], [], [], [], [], [], [], [], [], [], [], [], [], [], [], dict(flight.parameters), _MAV_AUTOPILOT_PX4)
    track = flight.truth if truth and flight.truth is not None else flight.estimate
    if truth and flight.truth is None:
        raise InputError(str(path), "no ground truth in this ULog (only PX4's SIH simulator logs it)")
    raw.lpn_t = track.time_s.tolist()
    raw.lpn_unix = track.time_s.tolist()
    raw.lpn_p_ned = [tuple(p) for p in track.position_ned_m.tolist()]
    raw.lpn_v_ned = [tuple(v) for v in track.velocity_ned_m_s.tolist()]
    ok = np.all(np.isfinite(flight.attitude_q_ned_frd), axis=1)
    raw.att_t = flight.attitude_time_s[ok].tolist()
    raw.att_q_ned_frd = [tuple(q) for q in flight.attitude_q_ned_frd[ok].tolist()]
    if len(flight.rates_time_s):
        rates = np.column_stack([np.interp(flight.attitude_time_s[ok], flight.rates_time_s, flight.rates_frd_rad_s[:, k]) for k in range(3)])
    else:
        rates = np.zeros((int(np.sum(ok)), 3))
    raw.att_rates_frd = [tuple(r) for r in rates.tolist()]
    raw.hb_unix = flight.status_time_s.tolist()
    raw.hb_active = flight.offboard_armed.tolist()
    sp = flight.setpoints
    if sp is not None:
        n = len(sp.time_s)
        raw.sp_unix = sp.time_s.tolist()
        raw.sp_boot = sp.time_s.tolist()
        raw.sp_lpn_boot = sp.time_s.tolist()  # PX4's own stamps: exact
        raw.sp_kind = [sp.kind] * n
        nan3 = [(math.nan, math.nan, math.nan)] * n
        raw.sp_accel_ned = [tuple(a) for a in sp.accel_ned_m_s2.tolist()] if sp.accel_ned_m_s2 is not None else nan3
        raw.sp_q_ned_frd = [tuple(q) for q in sp.q_ned_frd.tolist()] if sp.q_ned_frd is not None else [(1.0, 0.0, 0.0, 0.0)] * n
        raw.sp_rates_frd = [tuple(r) for r in sp.rates_frd_rad_s.tolist()] if sp.rates_frd_rad_s is not None else [(0.0, 0.0, 0.0)] * n
        raw.sp_thrust = sp.thrust.tolist() if sp.thrust is not None else [math.nan] * n
    raw.param_types = {k: 9 for k in raw.params}  # values as logged (floats), not MAVLink's bytewise encoding
    return raw


def _clock_map(raw: _Raw) -> tuple[float, float]:
    """UNIX time ≈ offset + slope · boot time, from LOCAL_POSITION_NED receptions (lower envelope)."""
    t = np.asarray(raw.lpn_t)
    u = np.asarray(raw.lpn_unix)
    slope, offset = np.polyfit(t - t[0], u - u[0], 1)
    # a lockstep simulator runs its boot clock at whatever rate the host allows (often several
    # times wall-clock time); only a slope no simulator could run at means "not a clock" (a paused
    # or replayed log): then assume real time
    if not CLOCK_SLOPE_RANGE[0] < slope < CLOCK_SLOPE_RANGE[1]:
        slope = 1.0
    resid = (u - u[0]) - slope * (t - t[0])
    offset = float(u[0] + np.percentile(resid, 2.0) - slope * t[0])
    return float(slope), offset


def _setpoint_times(raw: _Raw, lpn_t: NDArray[np.float64], slope: float, offset: float) -> NDArray[np.float64]:
    """Boot-clock time of each setpoint.

    pf-offboard stamps a setpoint with the boot time of the telemetry sample it answers
    (``time_boot_ms``) and sends it at once: when (nearly) all setpoints carry such stamps, they are
    used — exact, and immune to wall-clock jitter (a lockstep simulator's wall clock does not run
    evenly). Otherwise (another sender), the UNIX stamps go through the fitted clock line.

    A stamp counts when it is within ``STAMP_TOLERANCE_S`` of the boot time of the latest
    LOCAL_POSITION_NED logged before the setpoint: the log's order, not its UNIX stamps, decides
    (comparing against the fitted clock line fails whenever the boot clock does not run at the
    line's rate, e.g. a lockstep simulator running several times faster than real time). In a
    stamped log the few unstamped setpoints (e.g. take-off setpoints sent before any telemetry)
    take that latest telemetry time, so every setpoint stays on the one clock and in sending order.
    """
    boot = np.asarray(raw.sp_boot, dtype=float)
    unix_mapped = (np.asarray(raw.sp_unix) - offset) / slope
    if len(boot) == 0:
        return unix_mapped
    received = np.asarray(raw.sp_lpn_boot, dtype=float)
    stamped = (boot > 0.0) & np.isfinite(received) & (np.abs(boot - received) <= STAMP_TOLERANCE_S)
    if np.mean(stamped) < 0.9:
        return unix_mapped
    times = np.where(stamped, boot, received)  # −inf: sent before any telemetry, never flying
    # sent in this order: a setpoint never takes effect before the one sent ahead of it
    return np.maximum.accumulate(times)


def _hover_thrust(
    raw: _Raw, path: Path, override: float | None, autopilot: int | None
) -> tuple[float | None, str]:
    if override is not None:
        return override, "--hover-thrust"
    from pf_offboard.logs.flightlog import FlightLogPaths

    cfg = FlightLogPaths.beside(path).config_yaml
    if cfg.is_file():
        try:
            import yaml

            data = yaml.safe_load(cfg.read_text(encoding="utf-8"))
            value = data.get("flight", {}).get("hover_thrust") if isinstance(data, dict) else None
        except (OSError, yaml.YAMLError, AttributeError):
            value = None
        if isinstance(value, (int, float)) and not isinstance(value, bool) and 0.0 < value < 1.0:
            return float(value), f"config {cfg.name}"
    for name in HOVER_THRUST_PARAMS:
        if name in raw.params and 0.0 < raw.params[name] < 1.0:
            return raw.params[name], f"{name} in the log"
    return None, ""


def _hold_index(times: NDArray[np.float64], at: NDArray[np.float64]) -> NDArray[np.int64]:
    """Index of the last ``times`` entry <= each ``at`` (−1 before the first)."""
    return np.searchsorted(times, at, side="right") - 1


def load_log(
    path: str | Path,
    hover_thrust: float | None = None,
    grid_dt_s: float | None = None,
    velocity_correction_s: float | None = None,
    truth: bool = False,
) -> LogData:
    """Read one ``.tlog`` / ``.tlog.gz`` or PX4 ``.ulg`` into active segments (see the module docstring;
    ``truth``: a ULog's simulator ground truth instead of the estimate).

    ``hover_thrust``: the normalised hover thrust the app used for attitude / rates setpoints
    (default: the log's sibling config ``flight.hover_thrust``, else the autopilot's parameter
    recorded in the log). ``grid_dt_s``: resampling step (default: the telemetry period, at most
    10 ms). ``velocity_correction_s``: fit the velocity made position-consistent with this time
    constant (module docstring; default None: as reported). Raises :class:`InputError` naming the file for anything unusable.
    """
    p = Path(path)
    name = str(p)
    if not p.exists():
        raise InputError(name, "no such file")
    if p.is_dir():
        raise InputError(name, "is a directory, not a .tlog")
    ulog = p.suffix.lower() == ".ulg"
    raw = _read_raw_ulog(p, truth) if ulog else _read_raw(p)
    if len(raw.lpn_t) < 20:
        raise InputError(name, f"only {len(raw.lpn_t)} LOCAL_POSITION_NED samples: no measured velocity to fit")
    kinds = [k for k in raw.sp_kind if k in SETPOINT_KINDS]
    if not kinds:
        if ulog:
            raise InputError(name, "no offboard flight in this ULog (never armed in OFFBOARD with acceleration, attitude or rate setpoints)")
        raise InputError(name, "no acceleration or attitude setpoints from the app (component 191) in the log: "
                         "identify fits flights flown by pf-offboard (its .tlog) or a PX4 ULog (.ulg) of an offboard flight")  # fmt: skip
    # the kind that flew: an app may stream other setpoints while the autopilot is not yet armed in
    # its mode, more of them than it flies (an ArduCopter `fly` log: 40 s of level attitude targets
    # before arming in GUIDED, 21 s of flown body rates)
    hb_unix = np.asarray(raw.hb_unix)
    hb_idx = _hold_index(hb_unix, np.asarray(raw.sp_unix))
    hb_active = np.asarray(raw.hb_active, dtype=bool)
    flying = np.array([i >= 0 and bool(hb_active[i]) for i in hb_idx], dtype=bool) if len(hb_unix) else np.ones(len(raw.sp_kind), dtype=bool)
    flown = [k for k, f in zip(raw.sp_kind, flying) if f and k in SETPOINT_KINDS]
    kind = max(SETPOINT_KINDS, key=(flown if flown else kinds).count)
    slope, offset = _clock_map(raw)
    hover, hover_src = (None, "")
    if kind != "acceleration":
        hover, hover_src = _hover_thrust(raw, p, hover_thrust, raw.autopilot)
        if hover is None:
            raise InputError(name, f"{kind} setpoints need the hover thrust the app used: none in the log or its config; pass --hover-thrust")
    lpn_t = np.asarray(raw.lpn_t)
    period = float((lpn_t[-1] - lpn_t[0]) / (len(lpn_t) - 1))
    dt = grid_dt_s if grid_dt_s is not None else min(max(period, 0.002), 0.01)
    # setpoints on the boot clock, and whether each one was flying
    sp_t = _setpoint_times(raw, lpn_t, slope, offset)
    sp_active = flying & np.array([k == kind for k in raw.sp_kind], dtype=bool)
    grid = np.arange(lpn_t[0], lpn_t[-1], dt)
    # the grid sample k stands for the interval [t_k, t_k+1): it takes the setpoint that arrived by
    # its middle (a setpoint answering the telemetry of t_k is sent a moment after t_k)
    idx = _hold_index(sp_t, grid + 0.5 * dt)
    valid = idx >= 0
    safe = np.where(valid, idx, 0)
    valid &= sp_active[safe] & (grid - sp_t[safe] <= MAX_SETPOINT_AGE_S)
    valid &= _within_telemetry(lpn_t, grid)  # no interpolation across a telemetry gap
    v_ned = np.asarray(raw.lpn_v_ned)
    if velocity_correction_s is not None:
        v_ned = position_consistent_velocity(lpn_t, np.asarray(raw.lpn_p_ned), v_ned, velocity_correction_s)
    velocity = np.column_stack([np.interp(grid, lpn_t, v_ned[:, k]) for k in range(3)])
    velocity_enu = np.array([frames.ned_to_enu(v) for v in velocity])
    accel_enu, rates_sp, rates = _setpoint_accel(raw, kind, hover, safe, grid)
    valid &= np.all(np.isfinite(accel_enu), axis=1)
    up = _thrust_axis_up(raw, grid)
    segments = []
    for start, stop in _runs(valid):
        if (stop - start) * dt < MIN_SEGMENT_S:
            continue
        sl = slice(start, stop)
        segments.append(Segment(
            source=name, kind=kind, time_s=grid[sl], dt_s=dt, accel_sp_enu_m_s2=accel_enu[sl],
            velocity_enu_m_s=velocity_enu[sl],
            rates_sp_frd_rad_s=None if rates_sp is None else rates_sp[sl],
            rates_frd_rad_s=None if rates is None else rates[sl],
            thrust_axis_up=None if up is None or not np.all(np.isfinite(up[sl])) else up[sl],
        ))  # fmt: skip
    if not segments:
        raise InputError(name, f"no stretch of at least {MIN_SEGMENT_S:g} s where {kind} setpoints were flying (armed, in OFFBOARD/GUIDED)")
    return LogData(name, kind, tuple(segments), hover, hover_src, slope, velocity_correction_s)


def _tilts_from_gravity(raw: _Raw) -> bool:
    """Whether the logged autopilot tilted from g alone for acceleration setpoints: its
    ``accel_tilt_param`` as logged, else the profile's default (PX4's and ArduPilot's: yes)."""
    from pf_offboard.app.params import param_value_decode
    from pf_offboard.app.profiles import ARDUPILOT, PX4

    profile = PX4 if raw.autopilot == _MAV_AUTOPILOT_PX4 else ARDUPILOT
    name = profile.accel_tilt_param
    if name is None or name not in raw.params:
        return profile.tilts_from_gravity(None)
    return profile.tilts_from_gravity(param_value_decode(raw.params[name], raw.param_types.get(name, 9), profile.params_bytewise))


def _setpoint_accel(
    raw: _Raw, kind: str, hover: float | None, sp_idx: NDArray[np.int64], grid: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """Acceleration setpoint (ENU) on the grid; for rates logs also the rate setpoints and rates."""
    n = len(grid)
    g_enu = np.array([0.0, 0.0, GRAVITY_M_S2])
    if kind == "acceleration":
        a_ned = np.asarray(raw.sp_accel_ned, dtype=float)
        per_sp = np.array([frames.ned_to_enu(a) if np.all(np.isfinite(a)) else (math.nan,) * 3 for a in a_ned])
        if _tilts_from_gravity(raw):
            # what the autopilot flies for the setpoint sent (a_xy scaled by (g + a_up) / g), whether
            # or not the app had divided that out: the fit sees the acceleration asked of the vehicle
            per_sp = np.array([flown_when_tilting_from_gravity(a) for a in per_sp])
        return per_sp[sp_idx], None, None
    assert hover is not None
    thrust = np.asarray(raw.sp_thrust, dtype=float) / hover * THRUST_NORM_G_M_S2  # m/s^2
    if kind == "attitude":
        z_body = np.array([_body_z_enu(q) for q in raw.sp_q_ned_frd])
        per_sp = z_body * thrust[:, None] - g_enu
        return per_sp[sp_idx], None, None
    # rates: the thrust acts along the measured body z
    if len(raw.att_t) < 20:
        return np.full((n, 3), math.nan), None, None
    att_t = np.asarray(raw.att_t)
    k = np.clip(_hold_index(att_t, grid), 0, len(att_t) - 1)
    z_meas = np.array([_body_z_enu(raw.att_q_ned_frd[i]) for i in k])
    z_meas[np.abs(grid - att_t[k]) > MAX_SETPOINT_AGE_S] = math.nan
    accel = z_meas * thrust[sp_idx][:, None] - g_enu
    rates_sp = np.asarray(raw.sp_rates_frd, dtype=float)[sp_idx]
    att_r = np.asarray(raw.att_rates_frd, dtype=float)
    rates = np.column_stack([np.interp(grid, att_t, att_r[:, c]) for c in range(3)])
    return accel, rates_sp, rates


def _thrust_axis_up(raw: _Raw, grid: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """cos(measured tilt) on the grid, linearly interpolated (the end values held); NaN outside
    the attitude telemetry (:func:`_within_telemetry`); None without attitude telemetry."""
    if len(raw.att_t) < 20:
        return None
    att_t = np.asarray(raw.att_t)
    keep = np.concatenate(([True], np.diff(att_t) > 0.0))  # drop duplicated / reordered samples
    att_t = att_t[keep]
    if len(att_t) < 20:
        return None
    up = np.array([_body_z_enu(q)[2] for q, k in zip(raw.att_q_ned_frd, keep) if k])
    return np.where(_within_telemetry(att_t, grid), np.interp(grid, att_t, up), math.nan)


def _within_telemetry(times: NDArray[np.float64], grid: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Per grid time: it lies between two telemetry samples (increasing ``times``) at most 5 of
    the telemetry's mean periods (at least 0.1 s) apart, or at most that far beyond the ends."""
    gap = max(5.0 * float((times[-1] - times[0]) / (len(times) - 1)), 0.1)
    j = np.clip(np.searchsorted(times, grid), 1, len(times) - 1)
    return (times[j] - times[j - 1] <= gap) & (grid >= times[0] - gap) & (grid <= times[-1] + gap)


def _body_z_enu(q_ned_frd: Sequence[float]) -> NDArray[np.float64]:
    """Thrust direction (body +z FLU, i.e. up through the rotors) in world ENU."""
    try:
        q = frames.quat_ned_frd_to_enu_flu(q_ned_frd)
    except ValueError:
        return np.full(3, math.nan)
    w, x, y, z = q
    return np.array([2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)])


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """[start, stop) index pairs of the True runs of ``mask``."""
    m = np.concatenate(([False], mask, [False])).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))
