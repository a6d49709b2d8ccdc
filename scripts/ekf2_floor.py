"""Where a PX4 SIH flight's error sits, by frequency: the estimate's cross-track and speed error,
EKF2's own error (estimate - SIH truth, frame offset removed) and the part locked to the lap.

    python scripts/ekf2_floor.py RUN_DIR...      # flight directories of scripts/real_sitl_campaign.py

Per flight, from activation + 8 s (the campaign's window), RMS in the bands 0-0.5, 0.5-1, 1-2 and
2+ Hz (FFT of the signal resampled at 50 Hz; the bands' squares add up to the whole):
  ct      the estimate's cross-track vector (position minus the path's closest point)
  speed   the speed error along the path (position's derivative +-0.1 s, minus the reference)
  ekf_x   EKF2's error across the path; ekf_v: the derivative (+-0.1 s) of its error along the path
          (what a vehicle flying the truth perfectly would read as its speed error)
  inc     the speed error's part that is the app's velocity (flight.velocity_correction_s)
          disagreeing with the position's derivative (one for one in the speed error)
and, on a closed path, the lap-locked part of ct / speed (their mean over laps by path parameter,
in 100 bins) and the share of steps with a saturation flag.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

from pf_offboard import frames
from pf_offboard.config import load_config
from pf_offboard.logs import measures
from pf_offboard.logs.steplog import read_steplog
from pf_offboard.logs.truth import find_ulog, read_ulog_truth

BANDS_HZ = ((0.0, 0.5), (0.5, 1.0), (1.0, 2.0), (2.0, math.inf))
RATE_HZ = 50.0


def bands(t: np.ndarray, x: np.ndarray) -> list[float]:
    """RMS of ``x`` (N,) or (N, k) per band (the squares add up to the mean square)."""
    ok = np.isfinite(x).all(axis=1) if x.ndim == 2 else np.isfinite(x)
    t, x = t[ok], x[ok]
    tu = np.arange(t[0], t[-1], 1.0 / RATE_HZ)
    xs = x.reshape(len(t), -1)
    out = np.zeros(len(BANDS_HZ))
    for k in range(xs.shape[1]):
        spec = np.fft.rfft(np.interp(tu, t, xs[:, k]))
        f = np.fft.rfftfreq(len(tu), 1.0 / RATE_HZ)
        power = np.abs(spec) ** 2 / len(tu) ** 2
        power[1:] *= 2.0  # one-sided
        if len(tu) % 2 == 0:
            power[-1] /= 2.0
        for b, (lo, hi) in enumerate(BANDS_HZ):
            out[b] += power[(f >= lo) & (f < hi)].sum()
    return [float(math.sqrt(v)) for v in out]


def lap_locked(lam: np.ndarray, x: np.ndarray, lam_max: float) -> tuple[float, float]:
    """(RMS of the per-bin mean over laps, RMS of the rest) of ``x`` by path parameter."""
    ok = np.isfinite(x)
    lam, x = lam[ok], x[ok]
    b = np.clip((np.mod(lam, lam_max) / lam_max * 100).astype(int), 0, 99)
    mean = np.array([x[b == i].mean() if (b == i).any() else 0.0 for i in range(100)])
    locked = mean[b]
    return float(np.sqrt(np.mean(locked**2))), float(np.sqrt(np.mean((x - locked) ** 2)))


def analyse(run: Path, settle_s: float = 8.0) -> dict[str, object]:
    spec = json.loads((run / "result.json").read_text())["spec"]
    config = run / f"{Path(spec['config']).stem}-fast.yaml"
    path = load_config(config if config.exists() else Path(spec["config"])).path.spline()
    recs = read_steplog(run / "log" / "flight.csv")
    tangent = measures.path_tangent(path)
    t = np.array([r.time_s for r in recs])
    p = np.array([r.position_enu_m for r in recs], dtype=float)
    lam = np.array([r.lam for r in recs])
    act = np.array([r.active for r in recs])
    tang = np.array([tangent(float(x)) for x in lam])
    speed = measures.position_speed_along_path(t, p, tang) - np.array([r.speed_ref_m_s for r in recs])
    closest = np.array([path.eval_floats(path.wrap(float(x)))[0:3] for x in lam], dtype=float)
    if not act.any():
        raise ValueError("never activated")
    t_act = t[act][0]
    w = act & (t >= t_act + settle_s)
    if not path.closed:  # as the campaign: up to the open path's end or where the reference slows for it
        slowing = measures.final_slowdown([r.speed_ref_m_s for r in recs], act & (t > t_act + settle_s))
        end = act & ((lam >= path.lam_max - 1e-6) | slowing)
        if end.any():
            w &= t < t[end][0]
    out: dict[str, object] = {"name": f"{run.parent.name}/{run.name}", "ct": bands(t[w], (p - closest)[w]), "speed": bands(t[w], speed[w])}
    v = np.array([r.velocity_enu_m_s for r in recs], dtype=float)
    inc = speed + np.array([r.speed_ref_m_s for r in recs]) - np.einsum("ij,ij->i", v, tang)
    out["inc"] = bands(t[w], inc[w])
    out["sat"] = float(np.mean([r.sat_tangential or r.sat_transversal or r.sat_tilt or r.sat_thrust for r, k in zip(recs, w) if k]))
    if path.closed:
        out["ct_lap"] = lap_locked(lam[w], np.array([r.cross_track_m for r, k in zip(recs, w) if k]), path.lam_max)
        out["speed_lap"] = lap_locked(lam[w], speed[w], path.lam_max)
    ulog = find_ulog(run / "sitl")
    if ulog is not None:
        tt, ned = read_ulog_truth(ulog)
        truth = np.array([frames.ned_to_enu(x) for x in ned], dtype=float)
        tru = np.column_stack([np.interp(t, tt, truth[:, k]) for k in range(3)])
        inside = (t >= tt[0]) & (t <= tt[-1])
        e = p - tru
        e -= e[w & inside].mean(axis=0)
        along = np.einsum("ij,ij->i", e, tang)
        out["ekf_x"] = bands(t[w & inside], (e - along[:, None] * tang)[w & inside])
        dv = measures.position_speed_along_path(t, e, tang)  # derivative of e, along the tangent
        out["ekf_v"] = bands(t[w & inside], dv[w & inside])
    return out


def fmt(name: str, b: list[float] | None, unit: str) -> str:
    if b is None:
        return f"{name} -"
    return f"{name} {100 * math.sqrt(sum(x * x for x in b)):4.1f} [" + " ".join(f"{100 * x:4.1f}" for x in b) + f"] {unit}"


def main(argv: list[str]) -> int:
    print("bands: 0-0.5 | 0.5-1 | 1-2 | 2+ Hz; lap: (lap-locked, rest) RMS")
    for arg in argv:
        for run in sorted({r.parent for r in Path(arg).glob("**/result.json")} if not (Path(arg) / "result.json").exists() else [Path(arg)]):
            if not (run / "log" / "flight.csv").exists():
                continue
            try:
                a = analyse(run)
            except Exception as exc:  # noqa: BLE001 - a report
                print(f"{run.name}: {type(exc).__name__}: {exc}")
                continue
            lap = ""
            if "ct_lap" in a:
                cl, sl = a["ct_lap"], a["speed_lap"]  # type: ignore[misc]
                lap = f" | lap ct {100 * cl[0]:.1f}/{100 * cl[1]:.1f} cm, speed {100 * sl[0]:.1f}/{100 * sl[1]:.1f} cm/s"
            print(f"{a['name']}: {fmt('ct', a['ct'], 'cm')} | {fmt('speed', a['speed'], 'cm/s')} | {fmt('inc', a['inc'], 'cm/s')} | "  # type: ignore[arg-type]
                  f"{fmt('ekf_x', a.get('ekf_x'), 'cm')} | {fmt('ekf_v', a.get('ekf_v'), 'cm/s')} | sat {100 * a['sat']:.0f}%{lap}")  # type: ignore[arg-type, operator]
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
