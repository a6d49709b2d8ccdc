"""In-process ``sim`` flights judged from the mock's truth (not from what the estimator says).

:func:`fly_truth` flies one :class:`pf_offboard.sim.SimFlight` and records the simulated vehicle's
true position at every control step; :func:`truth_metrics` measures it against the path: the
cross-track distance (closest point), and the speed along the path's tangent taken from the true
position's central difference over +-``DIFF_S`` (the speed a user sees in the position log).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path as FsPath
from typing import Any

import numpy as np

from pf_offboard import frames
from pf_offboard.path import Path, Projector
from pf_offboard.sim import SimSpec
from pf_offboard.sim.flight import SimFlight

DIFF_S = 0.1  # half-width of the central difference (s)


@dataclass(frozen=True)
class TruthMetrics:
    cross_track_rms_m: float
    cross_track_max_m: float
    speed_error_rms_m_s: float
    speed_error_mean_m_s: float
    mean_speed_m_s: float  # |speed along the path| averaged over the window
    lap_time_s: float  # window duration / laps flown in it (nan on an open path)
    tangential_saturated_share: float  # of the window's steps
    window_s: float
    crashed: bool
    estimate_cross_track_rms_m: float = math.nan  # the controller's view: the estimate's distance to the path
    estimate_error_rms_m: float = math.nan  # |estimate - truth|, RMS


@dataclass
class TruthFlight:
    time_s: np.ndarray  # (N,) s, control steps while following
    position_enu_m: np.ndarray  # (N, 3) the true position
    estimate_enu_m: np.ndarray  # (N, 3) the position the controller was given
    speed_ref_m_s: np.ndarray  # (N,) eta2_ref the controller tracked
    tangential_saturated: np.ndarray  # (N,) bool
    activation_s: float
    crashed: bool
    path: Path


def fly_truth(config: str | FsPath, spec: SimSpec, out_dir: str | FsPath,
              patch: Callable[[SimFlight], None] | None = None) -> TruthFlight:  # fmt: skip
    """Fly without logs; the true position at each following step (after the controller's step)."""
    flight = SimFlight(config, spec, out_dir, write_logs=False)
    if patch is not None:
        patch(flight)
    rows: list[tuple[float, float, float, float, float, bool]] = []
    est: list[tuple[float, float, float]] = []
    orig_add = flight.summary.add

    def add(record: Any) -> None:
        orig_add(record)
        if record.mode == "following":
            p = frames.ned_to_enu(flight.autopilot.truth.position_ned_m)
            rows.append((flight.autopilot.time_s, float(p[0]), float(p[1]), float(p[2]), record.speed_ref_m_s,
                         bool(record.sat_tangential)))  # fmt: skip
            e = flight.pipeline.estimator.latest.position_enu_m
            est.append((float(e[0]), float(e[1]), float(e[2])))

    flight.summary.add = add  # type: ignore[method-assign]
    flight.run()
    a = np.array([r[:5] for r in rows]) if rows else np.zeros((0, 5))
    return TruthFlight(a[:, 0], a[:, 1:4], np.array(est).reshape(-1, 3), a[:, 4], np.array([r[5] for r in rows], dtype=bool),
                       float(a[0, 0]) if len(a) else math.nan, bool(flight.autopilot.truth.crashed), flight.path)  # fmt: skip


def truth_metrics(f: TruthFlight, settle_s: float = 8.0, end_s: float | None = None) -> TruthMetrics:
    """Measured over [activation + settle_s, end_s or the end] (the central difference needs DIFF_S each side)."""
    t = f.time_s
    if len(t) < 10:
        return TruthMetrics(*(math.inf,) * 8, crashed=True)  # type: ignore[arg-type]
    proj = Projector(f.path)
    lam = np.array([proj.update(p) for p in f.position_enu_m])
    pts = [f.path.eval(float(x)) for x in lam]
    sig = np.array([p.sigma for p in pts])
    tan = np.array([p.tangent for p in pts]) if hasattr(pts[0], "tangent") else None
    if tan is None:
        d1 = np.array([f.path.eval_floats(float(x))[3:6] for x in lam])
        tan = d1 / np.linalg.norm(d1, axis=1, keepdims=True)
    ct = np.linalg.norm(f.position_enu_m - sig, axis=1)
    # speed from the true position's central difference, projected on the tangent
    dt = float(np.median(np.diff(t)))
    k = max(1, int(round(DIFF_S / dt)))
    v = np.full_like(f.position_enu_m, np.nan)
    v[k:-k] = (f.position_enu_m[2 * k:] - f.position_enu_m[:-2 * k]) / (t[2 * k:] - t[:-2 * k])[:, None]
    v_t = np.einsum("ij,ij->i", v, tan)
    t_end = t[-1] - DIFF_S if end_s is None else min(end_s, t[-1] - DIFF_S)
    win = (t >= f.activation_s + settle_s) & (t <= t_end) & np.isfinite(v_t)
    if not f.path.closed:  # an open path: while the reference is the nominal one (not the stop at its end)
        nominal = np.max(np.abs(f.speed_ref_m_s))
        win &= np.abs(f.speed_ref_m_s) >= nominal - 1e-9
    e = v_t[win] - f.speed_ref_m_s[win]
    duration = float(t[win][-1] - t[win][0]) if win.any() else 0.0
    eta1 = np.array([f.path.arclength(float(x)) for x in lam[win]])
    lap = math.nan
    if f.path.closed and win.sum() > 2:
        ds = np.diff(eta1)
        L = f.path.length_m
        ds = (ds + L / 2) % L - L / 2
        travelled = abs(float(ds.sum()))
        lap = duration * L / travelled if travelled > 0 else math.inf
    return TruthMetrics(
        cross_track_rms_m=float(np.sqrt(np.mean(ct[win] ** 2))),
        cross_track_max_m=float(ct[win].max()),
        speed_error_rms_m_s=float(np.sqrt(np.mean(e**2))),
        speed_error_mean_m_s=float(np.mean(e)),
        mean_speed_m_s=float(np.mean(np.abs(v_t[win]))),
        lap_time_s=lap,
        tangential_saturated_share=float(np.mean(f.tangential_saturated[win])),
        window_s=duration,
        crashed=f.crashed,
        estimate_cross_track_rms_m=_estimate_cross_track_rms(f, win),
        estimate_error_rms_m=float(np.sqrt(np.mean(np.sum((f.estimate_enu_m[win] - f.position_enu_m[win]) ** 2, axis=1)))),
    )


def _estimate_cross_track_rms(f: TruthFlight, win: np.ndarray) -> float:
    proj = Projector(f.path)
    pts = f.estimate_enu_m[win]
    d = [float(np.linalg.norm(p - f.path.eval(float(proj.update(p))).sigma)) for p in pts]
    return float(np.sqrt(np.mean(np.square(d))))


def fly_sampled(config: str | FsPath, spec: SimSpec, out_dir: str | FsPath,
                sample: Callable[[SimFlight, Any], tuple[float, ...]]) -> tuple[np.ndarray, SimFlight]:  # fmt: skip
    """:func:`fly_truth` recording ``sample(flight, record)`` at every following step: (the
    samples as rows, the flight)."""
    rows: list[tuple[float, ...]] = []
    flights: list[SimFlight] = []

    def patch(flight: SimFlight) -> None:
        flights.append(flight)
        orig = flight.summary.add

        def add(record: Any) -> None:
            orig(record)
            if record.mode == "following":
                rows.append(sample(flight, record))

        flight.summary.add = add  # type: ignore[method-assign]

    fly_truth(config, spec, out_dir, patch=patch)
    return np.array(rows), flights[0]


def above_hz(time_s: np.ndarray, signal: np.ndarray, hz: float = 2.5) -> float:
    """RMS of ``signal``'s content above ``hz`` (its spectrum over the samples' median step)."""
    spectrum = np.fft.rfft(signal - signal.mean())
    freq = np.fft.rfftfreq(len(signal), float(np.median(np.diff(time_s))))
    return float(np.sqrt(2.0 * np.sum(np.abs(spectrum[freq > hz]) ** 2)) / len(signal))
