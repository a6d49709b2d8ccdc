"""Benchmark of the pure core: cost of ``PathFollower.update()`` on the paper path.

The follower flies configs/paper.yaml in closed loop on the ideal double integrator (semi-implicit
Euler at 100 Hz), starting 2 m off the path at rest, so the timed calls cover the approach
(limits active, blended laws) as well as steady path following. Each call is timed with
``perf_counter_ns``; figures are per call, in microseconds.
"""

from __future__ import annotations

import gc
import statistics
import time
from pathlib import Path as FsPath
from typing import Any

import numpy as np

PAPER_YAML = FsPath(__file__).resolve().parents[1] / "configs" / "paper.yaml"  # package data
START_ENU_M = (0.0, -1.5, 4.0)  # 2 m above the paper's PF1 start (0, -1.5, 2), at rest


def _follower() -> Any:
    from pf_offboard import PathFollower
    from pf_offboard.config import parse_config

    if PAPER_YAML.exists():
        from pf_offboard.config import load_config

        return PathFollower.from_config(load_config(PAPER_YAML))
    # installed without the repository's configs/: the same path, inline
    data = {
        "path": {
            "closed": True,
            "waypoints": [
                [0.0, -1.5, 2.0],
                [-1.6, -0.1, 1.8],
                [-0.7, 0.6, 3.6],
                [0.95, 1.3, 2.35],
                [-0.65, 2.0, 1.9],
                [-0.7, 0.6, 3.6],
                [0.5, -1.2, 2.35],
            ],
        },
        "speed_m_s": -1.5,
    }
    return PathFollower.from_config(parse_config(data, source="<bench>"))


def run(quick: bool = False) -> dict[str, Any]:
    """Median / p99 / mean cost of one ``update()`` (µs) over a closed-loop flight: the paper's
    law (configs/paper.yaml), and with the inner-loop compensation (configs/px4-sih.yaml)."""
    out = _run(_follower(), quick, timed=False)
    px4 = PAPER_YAML.parent / "px4-sih.yaml"
    if px4.exists():
        from pf_offboard import PathFollower

        from pf_offboard.config import load_config

        comp = _run(PathFollower.from_config(load_config(px4)), quick, timed=True)
        out.update({f"compensated_{k}": v for k, v in comp.items() if k.startswith("update_m")})
    return out


def _run(follower: Any, quick: bool, timed: bool) -> dict[str, Any]:
    dt = 0.01
    steps = 2_000 if quick else 20_000  # 20 s or 200 s of flight at 100 Hz
    y = np.array(START_ENU_M, dtype=float)
    v = np.zeros(3)
    t_s = 0.0
    kw = {"time_s": t_s} if timed else {}
    follower.update(y, v, **kw)  # first call: global projection (initialisation), not timed
    samples = []
    cross = []
    clock = time.perf_counter_ns
    gc_was_enabled = gc.isenabled()
    gc.disable()  # the control loop allocates little; keep collector pauses out of the figures
    try:
        for _ in range(steps):
            t_s += dt
            if timed:
                kw["time_s"] = t_s
            t0 = clock()
            cmd = follower.update(y, v, **kw)
            samples.append(clock() - t0)
            v = v + dt * cmd.acceleration
            y = y + dt * v
            cross.append(cmd.cross_track_m)
    finally:
        if gc_was_enabled:
            gc.enable()
    samples.sort()
    n = len(samples)
    return {
        "update_calls": n,
        "update_median_us": samples[n // 2] / 1e3,
        "update_p99_us": samples[min(n - 1, int(0.99 * n))] / 1e3,
        "update_mean_us": statistics.fmean(samples) / 1e3,
        "update_max_us": samples[-1] / 1e3,
        "final_cross_track_m": float(cross[-1]),
    }
