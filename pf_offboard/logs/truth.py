"""Judge a SITL flight against the simulator's ground truth, not only the autopilot's estimate.

``pf-offboard fly`` steers the autopilot's estimate (LOCAL_POSITION_NED) onto the path, and its
summary measures the cross-track error in that estimate. A simulator knows where the vehicle
really was: PX4 SITL streams it as HIL_STATE_QUATERNION on request (SIH and Gazebo builds). With
that stream in the flight's ``.tlog`` this script prints

- how far the estimate was from the truth (after removing the constant offset between the EKF's
  origin and the truth's first sample), RMS and peak-to-peak per NED axis;
- the cross-track error of the estimate and of the truth, from activation + ``--skip`` seconds.

The truth is interpolated at the estimate's arrival times (both stamped by the ``.tlog`` on
receipt), so a transport delay between the two streams is not an estimator error.

Usage (scripts/sitl_truth.py), on a PX4 SITL (instance 0) after it started and before ``fly``::

    px4-mavlink stream -u 14580 -s HIL_STATE_QUATERNION -r 50   # from the PX4 rootfs
    pf-offboard fly --connect udpin:127.0.0.1:14540 --config px4-sih --log-dir run ...
    python scripts/sitl_truth.py run --config px4-sih

Frames: the estimate is NED in the log; the path and the cross-track figures are world ENU.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pf_offboard import frames
from pf_offboard.config import load_config
from pf_offboard.errors import InputError
from pf_offboard.geo import GeoPoint, geodetic_to_enu
from pf_offboard.logs.steplog import read_steplog
from pf_offboard.logs.tlog import iter_tlog
from pf_offboard.path import Path as SplinePath
from pf_offboard.path import Projector

AUTOPILOT_SYSTEM_ID = 1


@dataclass(frozen=True)
class TruthReport:
    """Estimate vs truth over the judged window. Distances in metres."""

    samples: int
    estimate_error_rms_ned_m: tuple[float, float, float]  # estimate − truth, constant offset removed
    estimate_error_p2p_ned_m: tuple[float, float, float]
    cross_track_rms_estimate_m: float  # what fly's summary measures
    cross_track_rms_truth_m: float  # where the vehicle really was (truth + the constant offset)


@dataclass(frozen=True)
class _Series:
    time_unix_s: NDArray[np.float64]
    ned_m: NDArray[np.float64]  # (N, 3)
    boot_s: NDArray[np.float64] | None = None  # LOCAL_POSITION_NED only


def read_series(tlog: Path) -> tuple[_Series, _Series]:
    """(estimate LOCAL_POSITION_NED, truth HIL_STATE_QUATERNION as NED about its first sample)."""
    est_t, est_p, est_b, tru_t, tru_llh = [], [], [], [], []
    for entry in iter_tlog(tlog):
        m = entry.message
        if entry.direction != "in" or m.get_srcSystem() != AUTOPILOT_SYSTEM_ID:
            continue
        kind = m.get_type()
        if kind == "LOCAL_POSITION_NED":
            est_t.append(entry.time_unix_s)
            est_p.append((m.x, m.y, m.z))
            est_b.append(m.time_boot_ms * 1e-3)
        elif kind == "HIL_STATE_QUATERNION":
            tru_t.append(entry.time_unix_s)
            tru_llh.append((m.lat * 1e-7, m.lon * 1e-7, m.alt * 1e-3))
    if len(tru_t) < 2:
        raise InputError(str(tlog), "no HIL_STATE_QUATERNION in the log: stream it from the simulator first (see --help)")
    if len(est_t) < 2:
        raise InputError(str(tlog), "no LOCAL_POSITION_NED from the autopilot in the log")
    llh = np.array(tru_llh)
    origin = GeoPoint(float(llh[0, 0]), float(llh[0, 1]), float(llh[0, 2]))
    tru_ned = np.array([frames.enu_to_ned(p) for p in geodetic_to_enu(llh, origin)])
    return (
        _Series(np.array(est_t), np.array(est_p), np.array(est_b)),
        _Series(np.array(tru_t), tru_ned),
    )


def _cross_track(path: SplinePath, points_ned: NDArray[np.float64]) -> NDArray[np.float64]:
    proj = Projector(path)
    out = np.empty(len(points_ned))
    for i, p in enumerate(points_ned):
        enu = np.asarray(frames.ned_to_enu(p), dtype=float)
        lam = proj.update(enu)
        out[i] = float(np.linalg.norm(enu - np.asarray(path.eval_floats(lam)[0:3])))
    return out


def judge(log_dir: Path, config: str, skip_s: float = 8.0) -> TruthReport:
    """Compare estimate and truth from activation + ``skip_s`` (vehicle time) to the end of following."""
    tlogs, csvs = sorted(log_dir.glob("*.tlog")), sorted(log_dir.glob("*.csv"))
    if not tlogs or not csvs:
        raise InputError(str(log_dir), "needs the flight's .tlog and .csv")
    est, tru = read_series(tlogs[0])
    active = [r for r in read_steplog(csvs[0]) if r.mode == "following"]
    if not active:
        raise InputError(str(csvs[0]), "no step in mode 'following'")
    t0, t1 = active[0].time_s + skip_s, active[-1].time_s
    assert est.boot_s is not None
    sel = (est.boot_s >= t0) & (est.boot_s <= t1) & (est.time_unix_s >= tru.time_unix_s[0]) & (est.time_unix_s <= tru.time_unix_s[-1])
    if sel.sum() < 2:
        raise InputError(str(log_dir), f"no estimate sample with truth from activation + {skip_s} s on")
    truth_at = np.column_stack([np.interp(est.time_unix_s[sel], tru.time_unix_s, tru.ned_m[:, k]) for k in range(3)])
    diff = est.ned_m[sel] - truth_at
    offset = diff.mean(axis=0)  # EKF origin vs the truth's first sample: not an error
    err = diff - offset
    cfg = load_config(config)
    path = cfg.path.spline()
    ct_est = _cross_track(path, est.ned_m[sel])
    ct_tru = _cross_track(path, truth_at + offset)
    rms = np.sqrt((err**2).mean(axis=0))
    p2p = err.max(axis=0) - err.min(axis=0)
    return TruthReport(
        samples=int(sel.sum()),
        estimate_error_rms_ned_m=(float(rms[0]), float(rms[1]), float(rms[2])),
        estimate_error_p2p_ned_m=(float(p2p[0]), float(p2p[1]), float(p2p[2])),
        cross_track_rms_estimate_m=float(math.sqrt(np.mean(ct_est**2))),
        cross_track_rms_truth_m=float(math.sqrt(np.mean(ct_tru**2))),
    )


def describe(r: TruthReport, skip_s: float) -> str:
    """The report as three lines, centimetres."""
    cm = lambda v: ", ".join(f"{100 * x:.1f}" for x in v)  # noqa: E731
    return (
        f"{r.samples} samples from activation + {skip_s:g} s\n"
        f"estimate - truth (N, E, D)   RMS {cm(r.estimate_error_rms_ned_m)} cm; peak-to-peak {cm(r.estimate_error_p2p_ned_m)} cm\n"
        f"cross-track RMS              estimate {100 * r.cross_track_rms_estimate_m:.1f} cm; truth {100 * r.cross_track_rms_truth_m:.1f} cm"
    )


# --------------------------------------------------------------------------- PX4 ULog ground truth
@dataclass(frozen=True)
class UlogTruthReport:
    """A flight against PX4 SIH's ground truth (``vehicle_local_position_groundtruth`` in its ULog).

    Over one window of the step log (``window``). ``frame_offset_ned_m``: the constant offset
    between the estimate's frame (EKF2's origin) and the truth's, the mean of estimate − truth;
    not an error of the flight. ``estimate_error_*``: estimate − truth − that offset (EKF2's own
    error, the floor no controller steering the estimate can get under). ``truth``: the flight
    measured from the truth moved by the offset (where the vehicle really was relative to the path
    the estimate was steered onto); ``truth_raw_cross_track_rms_m``: the truth as it is, offset
    included (what a tape measure would say if both frames had one origin)."""

    window: str
    samples: int
    frame_offset_ned_m: tuple[float, float, float]
    estimate_error_rms_ned_m: tuple[float, float, float]
    estimate_error_p2p_ned_m: tuple[float, float, float]
    estimate_error_rms_horizontal_m: float
    truth: Any  # measures.WindowFigures: the truth + offset against the path
    truth_raw_cross_track_rms_m: float

    def to_dict(self) -> dict[str, Any]:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d["truth"] = None if self.truth is None else self.truth.to_dict()
        return d

    def lines(self) -> list[str]:
        cm = lambda v: ", ".join(f"{100 * x:.1f}" for x in v)  # noqa: E731
        out = [
            f"ground truth ({self.window}, {self.samples} samples):",
            f"  frame offset (estimate - truth, N E D)   {cm(self.frame_offset_ned_m)} cm (constant: the frames' origins, not an error)",
            f"  estimate error (offset removed, N E D)   RMS {cm(self.estimate_error_rms_ned_m)} cm "
            f"(horizontal {100 * self.estimate_error_rms_horizontal_m:.1f}); peak-to-peak {cm(self.estimate_error_p2p_ned_m)} cm",
        ]
        if self.truth is not None:
            out.append("  truth + offset: " + self.truth.line())
        out.append(f"  truth as logged (offset included): cross-track RMS {100 * self.truth_raw_cross_track_rms_m:.1f} cm")
        return out


def read_ulog_truth(ulog_file: str | Path) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(time since boot s, NED position m (N, 3)) of ``vehicle_local_position_groundtruth``."""
    try:
        from pyulog import ULog
    except ImportError as exc:  # a dependency: only a broken install lacks it
        raise InputError(str(ulog_file), "reading a ULog needs pyulog (pip install pyulog)") from exc
    try:
        ulog = ULog(str(ulog_file), ["vehicle_local_position_groundtruth"])
    except Exception as exc:  # pyulog raises plain exceptions on a bad file  # noqa: BLE001
        raise InputError(str(ulog_file), f"not a readable ULog ({type(exc).__name__}: {exc})") from exc
    sets = [d for d in ulog.data_list if d.name == "vehicle_local_position_groundtruth"]
    if not sets or len(sets[0].data["timestamp"]) < 2:
        raise InputError(str(ulog_file), "no vehicle_local_position_groundtruth in the ULog (PX4 logs it in SITL builds and with SYS_HITL)")
    d = sets[0].data
    t = np.asarray(d["timestamp"], dtype=float) * 1e-6
    ned = np.column_stack([np.asarray(d[k], dtype=float) for k in ("x", "y", "z")])
    ok = np.isfinite(ned).all(axis=1)
    return t[ok], ned[ok]


def judge_truth(records: Any, truth_time_s: NDArray[np.float64], truth_ned_m: NDArray[np.float64], path: SplinePath,
                settle_s: float = 8.0) -> UlogTruthReport:  # fmt: skip
    """The flight of ``records`` (step log, vehicle time = the autopilot's boot clock, as the
    ULog's) against the truth, from activation + ``settle_s`` to the last active step."""
    from pf_offboard.logs import measures

    recs = list(records)
    active = [r for r in recs if r.active]
    if not active:
        raise InputError("step log", "no active step")
    t_act = active[0].time_s
    t = np.array([r.time_s for r in recs])
    inside = (t >= truth_time_s[0]) & (t <= truth_time_s[-1])
    sel = inside & (t >= t_act + settle_s) & (t <= active[-1].time_s) & np.array([r.active for r in recs])
    if sel.sum() < 2:
        raise InputError("ULog", f"no ground truth over the flight from activation + {settle_s:g} s (another flight's log?)")
    est_ned = np.array([frames.enu_to_ned(r.position_enu_m) for r in recs], dtype=float)
    tru_at = np.column_stack([np.interp(t, truth_time_s, truth_ned_m[:, k]) for k in range(3)])
    diff = est_ned[sel] - tru_at[sel]
    offset = diff.mean(axis=0)
    err = diff - offset
    rms = np.sqrt((err**2).mean(axis=0))
    p2p = err.max(axis=0) - err.min(axis=0)
    # the truth moved by the offset, as a flight: projected, cross-track, speed from its derivative.
    # Each truth point is projected on the branch its estimate was projected on in flight (the step
    # log's lam, a warm start): a search carried from truth sample to truth sample could lock onto a
    # helix's neighbouring turn, and a fresh global search near a figure-eight's crossing can land
    # on the other branch, whose tangent turns the speed along the path into nonsense.
    moved = tru_at + offset
    lam = np.full(len(t), math.nan)
    ct = np.full(len(t), math.nan)
    ct_raw = []
    proj = Projector(path, jump_m=5.0)

    def near(i: int, point_ned: NDArray[np.float64]) -> tuple[float, float]:
        proj.reset()
        estimate = np.asarray(frames.ned_to_enu(est_ned[i]), dtype=float)
        enu = np.asarray(frames.ned_to_enu(point_ned), dtype=float)
        if math.isfinite(recs[i].lam):
            proj.seed(recs[i].lam, enu, estimate)
        else:  # no projection logged (before activation): found afresh from the estimate
            proj.update(estimate)
        lam_i = proj.update(enu)
        return lam_i, float(np.linalg.norm(enu - np.asarray(path.eval_floats(lam_i)[0:3])))

    for i in np.flatnonzero(inside):
        lam[i], ct[i] = near(i, moved[i])
        if sel[i]:
            ct_raw.append(near(i, tru_at[i])[1])
    moved_enu = np.array([frames.ned_to_enu(p) for p in moved], dtype=float)
    window_active = inside & np.array([r.active for r in recs])
    track = measures.tracking(t[inside], moved_enu[inside], lam[inside], ct[inside], np.full(int(inside.sum()), math.nan),
                              [r.speed_ref_m_s for r, k in zip(recs, inside) if k], window_active[inside],
                              measures.path_tangent(path), settle_s=t_act + settle_s - t[inside][window_active[inside]][0])  # fmt: skip
    return UlogTruthReport(
        window=measures.settled_window(settle_s),
        samples=int(sel.sum()),
        frame_offset_ned_m=(float(offset[0]), float(offset[1]), float(offset[2])),
        estimate_error_rms_ned_m=(float(rms[0]), float(rms[1]), float(rms[2])),
        estimate_error_p2p_ned_m=(float(p2p[0]), float(p2p[1]), float(p2p[2])),
        estimate_error_rms_horizontal_m=float(math.hypot(rms[0], rms[1])),
        truth=None if track is None else track.settled,
        truth_raw_cross_track_rms_m=float(math.sqrt(np.mean(np.square(ct_raw)))),
    )


def find_ulog(directory: str | Path) -> Path | None:
    """The newest ``.ulg`` under ``directory`` (PX4 writes them under its rootfs ``log/``)."""
    found = sorted(Path(directory).rglob("*.ulg"), key=lambda p: p.stat().st_mtime)
    return found[-1] if found else None
