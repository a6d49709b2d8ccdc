"""Shared set-up of the app's integration flights: configs, running `fly` against sitl-mock, metrics."""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from pf_offboard.app.fly import FlyOutcome, add_arguments, fly

REPO = Path(__file__).resolve().parents[2]
PAPER = REPO / "configs" / "paper.yaml"
RATE_HZ = 100.0  # setpoint rate == lockstep step (10 ms): one fresh state sample per setpoint (the default: 50)
def write_config(tmp: Path, speed_m_s: float = -1.5, gains: dict | None = None, **flight: object) -> Path:
    data = yaml.safe_load(PAPER.read_text())
    data["speed_m_s"] = speed_m_s
    if gains is not None:
        data["gains"] = gains
    data["flight"] = {"setpoint_rate_hz": RATE_HZ, "attitude_time_constant_s": 0.05, **flight}
    path = tmp / "flight.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def fly_args(*flags: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return parser.parse_args(list(flags))


def run_fly(port: int, config: Path, log_dir: Path, *flags: str) -> FlyOutcome:
    return fly(fly_args("--connect", f"udpout:127.0.0.1:{port}", "--config", str(config), "--log-dir", str(log_dir),
                        "--heartbeat-timeout", "5", "--quiet", *flags))  # fmt: skip


@dataclass(frozen=True)
class LapMetrics:
    initial_cross_track_m: float
    convergence_s: float  # after activation (the summary's: within 10 cm for 1 s)
    settled_s: float  # after activation: cross-track <= 5 cm and |speed error| <= 0.1 m/s from then on
    cross_track_rms_m: float  # over one lap after convergence
    cross_track_max_m: float
    speed_rms_m_s: float
    settled_cross_track_rms_m: float  # the same lap without its first 2 s (the approach's tail)


def lap_metrics(outcome: FlyOutcome, lap_s: float) -> LapMetrics:
    """Over one lap from where the flight settled (cross-track <= 5 cm and |eta2 - eta2_ref| <=
    0.1 m/s from then on, a stricter rule than the summary's convergence): cross-track RMS / max
    and speed error RMS."""
    from pf_offboard.logs.summary import summarize

    recs = [r for r in outcome.records if r.active]
    summary = summarize(recs)
    assert summary.convergence_time_s is not None, "never converged"
    t = np.array([r.time_s for r in recs])
    e = np.array([r.cross_track_m for r in recs])
    speed_error = np.array([r.eta2_m_s - r.speed_ref_m_s for r in recs])
    bad = np.flatnonzero(~((e <= 0.05) & (np.abs(speed_error) <= 0.1)))
    assert bad.size == 0 or bad[-1] + 1 < len(t), "never settled"
    t0 = t[0] if bad.size == 0 else t[bad[-1] + 1]
    window = (t >= t0) & (t <= t0 + lap_s)
    assert t[-1] >= t0 + lap_s - 0.05, f"less than a lap after settling ({t[-1] - t0:.2f} s < {lap_s:.2f} s)"
    return LapMetrics(
        initial_cross_track_m=float(e[0]),
        convergence_s=float(summary.convergence_time_s),
        settled_s=float(t0 - t[0]),
        cross_track_rms_m=float(np.sqrt(np.mean(e[window] ** 2))),
        cross_track_max_m=float(np.max(e[window])),
        speed_rms_m_s=float(np.sqrt(np.mean(speed_error[window] ** 2))),
        settled_cross_track_rms_m=float(np.sqrt(np.mean(e[window & (t >= t0 + 2.0)] ** 2))),
    )


def transversal_norm(outcome: FlyOutcome) -> tuple[np.ndarray, np.ndarray]:
    recs = [r for r in outcome.records if r.active]
    t = np.array([r.time_s for r in recs])
    return t, np.array([math.hypot(r.xi1_m, r.phi1_m) for r in recs])
