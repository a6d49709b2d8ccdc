"""Flight logs written by others, read leniently for ``plot``: PX4 ULogs (``.ulg``) and the
telemetry logs of QGroundControl / MAVProxy (``.tlog`` without pf-offboard's step CSV beside it).

pf-offboard's own logs are read strictly (:mod:`pf_offboard.logs.tlog`: a corrupt record is an
error, because replay must reproduce every setpoint). A ground station's tlog is read the way
pymavlink reads any tlog: records it cannot decode are skipped and counted. From either kind of
log the track (position and velocity, ENU) and whether the vehicle was armed in OFFBOARD / GUIDED
are taken; the path coordinates are then computed against the config's path, as the controller
would have (:meth:`pf_offboard.control.PathFollower.transverse_state`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pf_offboard import frames
from pf_offboard.errors import InputError
from pf_offboard.logs.tlog import check_log_file

PLOT_RATE_HZ = 50.0  # tracks are resampled to this for the figures
_ARMED = 128
_PX4_OFFBOARD_MAIN = 6
_ARDUPILOT_GUIDED = (4, 20)
_MAV_AUTOPILOT_PX4 = 12
_MAV_AUTOPILOT_INVALID = 8


@dataclass(frozen=True)
class ForeignTrack:
    """A vehicle's track from someone else's log (ENU, boot clock s)."""

    name: str
    time_s: NDArray[np.float64]
    position_enu_m: NDArray[np.float64]  # (N, 3)
    velocity_enu_m_s: NDArray[np.float64]  # (N, 3), the position's derivative
    active: NDArray[np.bool_]  # armed in OFFBOARD / GUIDED
    note: str = ""  # e.g. how many records were skipped


def _resample(t: NDArray[np.float64], x: NDArray[np.float64], grid: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.column_stack([np.interp(grid, t, x[:, k]) for k in range(x.shape[1])])


def _active_at(grid: NDArray[np.float64], times: NDArray[np.float64], flags: NDArray[np.bool_]) -> NDArray[np.bool_]:
    if len(times) == 0:
        return np.zeros(len(grid), dtype=bool)
    k = np.searchsorted(times, grid, side="right") - 1
    return np.where(k >= 0, flags[np.clip(k, 0, len(flags) - 1)], False)


def _track(name: str, t: NDArray[np.float64], p_ned: NDArray[np.float64], v_ned: NDArray[np.float64],
           st_t: NDArray[np.float64], st_on: NDArray[np.bool_], note: str = "") -> ForeignTrack:  # fmt: skip
    order = np.argsort(t, kind="stable")
    t, p_ned, v_ned = t[order], p_ned[order], v_ned[order]
    keep = np.concatenate(([True], np.diff(t) > 0.0))
    t, p_ned, v_ned = t[keep], p_ned[keep], v_ned[keep]
    if len(t) < 2:
        raise InputError(name, "fewer than 2 position samples: no track to plot")
    grid = np.arange(t[0], t[-1], 1.0 / PLOT_RATE_HZ)
    p = np.array([frames.ned_to_enu(x) for x in _resample(t, p_ned, grid)])
    # what the vehicle did: the velocity as the position's derivative (an estimator's reported
    # velocity can disagree with its own position: EKF2 on PX4 SIH by 10-40 cm/s), over 0.1 s
    step = max(1, round(0.05 * PLOT_RATE_HZ))
    v = np.empty_like(p)
    for k in range(3):
        ahead = np.concatenate((p[step:, k], np.repeat(p[-1:, k], step)))
        behind = np.concatenate((np.repeat(p[:1, k], step), p[:-step, k]))
        v[:, k] = (ahead - behind) / (2.0 * step / PLOT_RATE_HZ)
    del v_ned
    return ForeignTrack(name, grid, p, v, _active_at(grid, st_t, st_on), note)


def read_ulog_tracks(path: str | Path) -> list[ForeignTrack]:
    """The estimate's track of a PX4 ULog and, when SIH logged it, the ground truth's."""
    from pf_offboard.logs.ulog import read_ulog

    f = read_ulog(path)
    stem = Path(path).stem
    out = [_track(stem, f.estimate.time_s, f.estimate.position_ned_m, f.estimate.velocity_ned_m_s, f.status_time_s, f.offboard_armed)]
    if f.truth is not None:
        out.append(_track(f"{stem}-truth", f.truth.time_s, f.truth.position_ned_m, f.truth.velocity_ned_m_s,
                          f.status_time_s, f.offboard_armed))  # fmt: skip
    return out


def read_foreign_tlog(path: str | Path) -> ForeignTrack:
    """A ground station's tlog (QGroundControl, MAVProxy), leniently: undecodable records are
    skipped and counted; LOCAL_POSITION_NED gives the track, the autopilot's HEARTBEAT the mode."""
    from pymavlink import mavutil

    p = Path(path)
    name = str(p)
    check_log_file(p)
    try:
        conn = mavutil.mavlink_connection(name, dialect="common", robust_parsing=True)
    except Exception as exc:  # noqa: BLE001 - pymavlink raises many kinds on a bad file
        raise InputError(name, f"not readable as a tlog ({type(exc).__name__}: {exc})") from None
    t: list[float] = []
    pos: list[tuple[float, float, float]] = []
    vel: list[tuple[float, float, float]] = []
    st_t: list[float] = []
    st_on: list[bool] = []
    bad = 0
    last_boot = -math.inf
    while True:
        try:
            # every record decoded (no type filter: pymavlink then skips unwanted ones undecoded,
            # and a damaged one among them would go uncounted)
            msg: Any = conn.recv_match()
        except Exception:  # noqa: BLE001 - a damaged record: skip it
            bad += 1
            continue
        if msg is None:
            break
        kind = msg.get_type()
        if kind == "BAD_DATA":
            bad += 1
        elif kind == "LOCAL_POSITION_NED":
            vals = (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz)
            if all(map(math.isfinite, vals)):
                last_boot = msg.time_boot_ms * 1e-3
                t.append(last_boot)
                pos.append(vals[:3])
                vel.append(vals[3:])
        elif kind == "HEARTBEAT" and msg.autopilot != _MAV_AUTOPILOT_INVALID and math.isfinite(last_boot):
            armed = bool(msg.base_mode & _ARMED)
            mode_ok = ((msg.custom_mode >> 16) & 0xFF == _PX4_OFFBOARD_MAIN) if msg.autopilot == _MAV_AUTOPILOT_PX4 \
                else msg.custom_mode in _ARDUPILOT_GUIDED  # fmt: skip
            st_t.append(last_boot)
            st_on.append(armed and mode_ok)
    if not t:
        raise InputError(name, "no LOCAL_POSITION_NED in this tlog: nothing to plot (is it a MAVLink telemetry log? "
                         f"{bad} undecodable records skipped)")  # fmt: skip
    note = f"{bad} undecodable records skipped" if bad else ""
    return _track(Path(name).stem, np.asarray(t), np.asarray(pos), np.asarray(vel), np.asarray(st_t), np.asarray(st_on, dtype=bool), note)


def step_records(track: ForeignTrack, follower: Any) -> list[Any]:
    """StepRecords of a track against ``follower``'s path: the path coordinates the controller would
    have computed; no commands (NaN)."""
    from pf_offboard.logs.steplog import StepRecord

    nan3 = (math.nan,) * 3
    out = []
    for t, p, v, on in zip(track.time_s, track.position_enu_m, track.velocity_enu_m_s, track.active):
        st = follower.transverse_state(p, v)
        out.append(StepRecord(
            time_s=float(t), mode="following" if on else "other", active=bool(on), position_enu_m=p, velocity_enu_m_s=v,
            lam=math.nan, eta1_m=st.eta1, eta2_m_s=st.eta2, xi1_m=st.xi1, xi2_m_s=st.xi2, phi1_m=st.phi1, phi2_m_s=st.phi2,
            cross_track_m=math.hypot(st.xi1, st.phi1), speed_ref_m_s=follower.reference_speed(st.eta1),
            accel_cmd_enu_m_s2=nan3, thrust_cmd_m_s2=math.nan, q_cmd_enu_flu=(math.nan,) * 4, rates_cmd_flu_rad_s=nan3,
            yaw_cmd_rad=math.nan, yaw_rate_cmd_rad_s=math.nan, sat_tangential=False, sat_transversal=False, sat_tilt=False,
            sat_thrust=False, sat_approach_speed=False,
        ))  # fmt: skip
    return out


def iter_tlog_lenient(path: str | Path, own_component_ids: tuple[int, ...] = (191,)) -> Any:
    """A tlog read the way pymavlink reads any tlog (records it cannot decode are skipped), as
    :class:`~pf_offboard.logs.tlog.TlogEntry` s: for logs that pf-offboard did not write (a
    MAVProxy log of the companion's link, a ground station's). ``direction`` is "out" for
    messages from ``own_component_ids`` (pf-offboard's 191, MAVSDK / MAVROS companions' 191 too)."""
    from pymavlink import mavutil

    from pf_offboard.logs.tlog import TlogEntry

    p = Path(path)
    check_log_file(p)
    try:
        conn = mavutil.mavlink_connection(str(p), dialect="common", robust_parsing=True)
    except Exception as exc:  # noqa: BLE001 - pymavlink raises many kinds on a bad file
        raise InputError(str(p), f"not readable as a tlog ({type(exc).__name__}: {exc})") from None
    count = 0
    while True:
        try:
            msg = conn.recv_msg()
        except Exception:  # noqa: BLE001 - a damaged record: skip it
            continue
        if msg is None:
            if count == 0:
                raise InputError(str(p), "not a .tlog: no MAVLink message could be read from it")
            return
        if msg.get_type() == "BAD_DATA":
            continue
        count += 1
        out = msg.get_srcComponent() in own_component_ids
        yield TlogEntry(time_unix_s=float(getattr(msg, "_timestamp", 0.0)), message=msg, direction="out" if out else "in",
                        offset=-1, frame=bytes(msg.get_msgbuf()))  # fmt: skip
