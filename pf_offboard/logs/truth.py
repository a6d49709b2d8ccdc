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
