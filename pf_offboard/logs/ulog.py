"""PX4 flight logs (ULog, ``.ulg``) through pyulog: what ``identify`` and ``plot`` need from them.

PX4 writes a ULog of every armed flight (``log/`` beside its rootfs in SITL, the SD card on a
vehicle). This reader takes the estimate (``vehicle_local_position``), the attitude, the mode
(``vehicle_status``: OFFBOARD and armed), the offboard setpoints PX4 received
(``trajectory_setpoint`` acceleration, ``vehicle_attitude_setpoint``, ``vehicle_rates_setpoint``)
and, when the simulator logged it (SIH), the ground truth (``vehicle_local_position_groundtruth``).
Times are PX4's boot clock (s); frames as PX4 logs them (NED, body FRD); conversion to ENU is the
caller's, through :mod:`pf_offboard.frames`.

Every problem is one :class:`~pf_offboard.errors.InputError` naming the file and the reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pf_offboard.errors import InputError
from pf_offboard.logs.tlog import check_log_file

NAV_STATE_OFFBOARD = 14
ARMING_STATE_ARMED = 2
SUFFIXES = (".ulg",)


@dataclass(frozen=True)
class Track:
    """Positions and velocities (NED, m and m/s) on PX4's boot clock (s)."""

    time_s: NDArray[np.float64]
    position_ned_m: NDArray[np.float64]  # (N, 3)
    velocity_ned_m_s: NDArray[np.float64]  # (N, 3)


@dataclass(frozen=True)
class Setpoints:
    """One kind of offboard setpoint as PX4 logged it (boot clock, s)."""

    kind: str  # acceleration | attitude | rates
    time_s: NDArray[np.float64]
    accel_ned_m_s2: NDArray[np.float64] | None = None  # (N, 3), acceleration
    q_ned_frd: NDArray[np.float64] | None = None  # (N, 4) w, x, y, z, attitude
    rates_frd_rad_s: NDArray[np.float64] | None = None  # (N, 3), rates
    thrust: NDArray[np.float64] | None = None  # (N,) normalised collective thrust 0..1, attitude / rates


@dataclass(frozen=True)
class ULogFlight:
    """What a ULog holds for path following and identification."""

    source: str
    estimate: Track
    truth: Track | None  # SIH's ground truth, when logged
    attitude_time_s: NDArray[np.float64]
    attitude_q_ned_frd: NDArray[np.float64]  # (N, 4)
    rates_time_s: NDArray[np.float64]
    rates_frd_rad_s: NDArray[np.float64]  # (N, 3)
    status_time_s: NDArray[np.float64]
    offboard_armed: NDArray[np.bool_]  # per status sample: armed in OFFBOARD
    setpoints: Setpoints | None  # the kind flown in OFFBOARD; None: never in OFFBOARD
    parameters: dict[str, float]
    origin_lat_lon_alt: tuple[float, float, float] | None  # the local frame's reference (EKF origin)

    def offboard_intervals(self) -> list[tuple[float, float]]:
        """[start, end) boot-clock intervals armed in OFFBOARD."""
        out: list[tuple[float, float]] = []
        start = None
        for t, on in zip(self.status_time_s.tolist(), self.offboard_armed.tolist()):
            if on and start is None:
                start = t
            elif not on and start is not None:
                out.append((start, t))
                start = None
        if start is not None:
            out.append((start, float(self.estimate.time_s[-1])))
        return out


def _columns(data: dict[str, NDArray], name: str, n: int) -> NDArray[np.float64]:
    return np.column_stack([np.asarray(data[f"{name}[{i}]"], dtype=float) for i in range(n)])


def read_ulog(path: str | Path) -> ULogFlight:
    """Read a ``.ulg`` (InputError naming the file when it is missing or not a usable ULog)."""
    p = Path(path)
    name = str(p)
    if p.is_dir():
        raise InputError(name, "is a directory, not a ULog")
    check_log_file(p)  # missing, a FIFO (would block the header read), a device or a huge file
    try:
        from pyulog import ULog
    except ImportError:  # pragma: no cover - a dependency
        raise InputError(name, "reading ULogs needs pyulog (pip install pyulog)") from None
    try:
        with open(p, "rb") as fh:
            if fh.read(7) != b"ULog\x01\x12\x35":
                raise InputError(name, "not a PX4 ULog (no ULog header): PX4 writes .ulg files; pass a .tlog for other logs")
        log = ULog(name)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - pyulog raises many kinds on a damaged file
        raise InputError(name, f"unreadable ULog ({type(exc).__name__}: {exc})") from None
    topics = {}
    for d in log.data_list:
        if d.multi_id == 0:
            topics[d.name] = d.data

    def need(topic: str) -> dict[str, NDArray]:
        if topic not in topics or len(topics[topic]["timestamp"]) == 0:
            raise InputError(name, f"no {topic} in the ULog (logged by every PX4 multicopter flight; is the logger's profile trimmed?)")
        return topics[topic]

    def track(topic: str) -> Track:
        d = topics[topic]
        t = np.asarray(d["timestamp"], dtype=float) * 1e-6
        pos = np.column_stack([np.asarray(d[k], dtype=float) for k in ("x", "y", "z")])
        vel = np.column_stack([np.asarray(d[k], dtype=float) for k in ("vx", "vy", "vz")])
        keep = np.all(np.isfinite(pos), axis=1) & np.all(np.isfinite(vel), axis=1)
        return Track(t[keep], pos[keep], vel[keep])

    need("vehicle_local_position")
    estimate = track("vehicle_local_position")
    truth = track("vehicle_local_position_groundtruth") if "vehicle_local_position_groundtruth" in topics else None
    att = need("vehicle_attitude")
    status = need("vehicle_status")
    rates = topics.get("vehicle_angular_velocity")
    st_t = np.asarray(status["timestamp"], dtype=float) * 1e-6
    active = (np.asarray(status["nav_state"]) == NAV_STATE_OFFBOARD) & (np.asarray(status["arming_state"]) == ARMING_STATE_ARMED)
    lp = topics["vehicle_local_position"]
    origin = None
    if "ref_lat" in lp and len(lp["ref_lat"]) and np.isfinite(lp["ref_lat"][-1]) and lp["ref_lat"][-1] != 0.0:
        origin = (float(lp["ref_lat"][-1]), float(lp["ref_lon"][-1]), float(lp["ref_alt"][-1]))
    return ULogFlight(
        source=name,
        estimate=estimate,
        truth=truth if truth is not None and len(truth.time_s) else None,
        attitude_time_s=np.asarray(att["timestamp"], dtype=float) * 1e-6,
        attitude_q_ned_frd=_columns(att, "q", 4),
        rates_time_s=np.asarray(rates["timestamp"], dtype=float) * 1e-6 if rates is not None else np.zeros(0),
        rates_frd_rad_s=_columns(rates, "xyz", 3) if rates is not None else np.zeros((0, 3)),
        status_time_s=st_t,
        offboard_armed=active,
        setpoints=_offboard_setpoints(topics, st_t, active),
        parameters={k: float(v) for k, v in log.initial_parameters.items()},
        origin_lat_lon_alt=origin,
    )


def _offboard_setpoints(topics: dict[str, dict[str, NDArray]], st_t: NDArray[np.float64], active: NDArray[np.bool_]) -> Setpoints | None:
    """The setpoint kind the offboard flight sent: PX4's control-mode flags in OFFBOARD say which
    loops the offboard input drove (acceleration: the position controller's; attitude / rates)."""
    if not np.any(active):
        return None
    kind = "acceleration"
    mode = topics.get("vehicle_control_mode")
    if mode is not None and len(mode["timestamp"]):
        mt = np.asarray(mode["timestamp"], dtype=float) * 1e-6
        k = np.clip(np.searchsorted(st_t, mt, side="right") - 1, 0, len(st_t) - 1)
        on = active[k] & (np.asarray(mode["flag_control_offboard_enabled"]) == 1)
        if np.any(on):
            # the position controller runs for acceleration setpoints (its acceleration flag), not for
            # attitude or rate setpoints
            acc = (np.asarray(mode["flag_control_acceleration_enabled"])[on] == 1) | (np.asarray(mode["flag_control_velocity_enabled"])[on] == 1)
            att = np.asarray(mode["flag_control_attitude_enabled"])[on] == 1
            kind = "acceleration" if np.mean(acc) > 0.5 else "attitude" if np.mean(att) > 0.5 else "rates"
    if kind == "acceleration":
        d = topics.get("trajectory_setpoint")
        if d is None:
            return None
        t = np.asarray(d["timestamp"], dtype=float) * 1e-6
        acc = _columns(d, "acceleration", 3)
        pos = _columns(d, "position", 3)
        keep = np.all(np.isfinite(acc), axis=1) & np.all(np.isnan(pos), axis=1)  # acceleration-only setpoints
        return Setpoints("acceleration", t[keep], accel_ned_m_s2=acc[keep])
    if kind == "attitude":
        d = topics.get("vehicle_attitude_setpoint")
        if d is None:
            return None
        return Setpoints("attitude", np.asarray(d["timestamp"], dtype=float) * 1e-6, q_ned_frd=_columns(d, "q_d", 4),
                         thrust=-np.asarray(d["thrust_body[2]"], dtype=float))  # fmt: skip
    d = topics.get("vehicle_rates_setpoint")
    if d is None:
        return None
    return Setpoints("rates", np.asarray(d["timestamp"], dtype=float) * 1e-6,
                     rates_frd_rad_s=np.column_stack([np.asarray(d[k], dtype=float) for k in ("roll", "pitch", "yaw")]),
                     thrust=-np.asarray(d["thrust_body[2]"], dtype=float))  # fmt: skip
