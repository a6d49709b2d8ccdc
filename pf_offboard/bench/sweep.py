"""Benchmark of ``pf-offboard sweep``: the batch engine against the scalar one.

- 1000 thrown starts (``--quick``: 100) of the sweep's defaults (configs/px4-sih.yaml on the
  px4-sih preset, <= 5 m / 4 m/s off the path, 15 s each) on the batch engine, 2 local worker
  processes: wall time, flights per second, success rate and convergence percentiles;
- the scalar engine on the first 20 of the same starts (``--quick``: 4), serially: its CPU time per
  flight, the 1000-flight time on 2 workers *extrapolated* from it (ideal parallel speed-up), the
  ratio; the two engines' rows of that sample must be identical (checked, not timed);
- the same on the ArduPilot profile with the arducopter preset (the mock's GUIDED handling per
  flight over the batched dynamics): batch time, the scalar sample, the ratio, rows identical;
- a 20 x 20 gain grid (``--quick``: 4 x 4), 10 flights each (``--quick``: 4), on the batch engine:
  wall time and the best candidate with its region-of-attraction figure (success rate);
- Dask in local mode (2 single-threaded worker processes) on 200 of the starts (``--quick``: 50),
  when the ``cluster`` extra is installed: wall time with and without the cluster's start-up.

The figures depend on the machine's load: the 1-minute load average is reported with them, and
the batch figures also as ``*_on_idle_cores`` = CPU seconds (this process and its workers) / workers,
what the same work needs on otherwise idle cores.
"""

from __future__ import annotations

import dataclasses
import os
import time
from pathlib import Path
from typing import Any

WORKERS = 2
CONFIG = Path(__file__).resolve().parents[1] / "configs" / "px4-sih.yaml"  # package data


def _cpu() -> float:
    """CPU seconds of this process and of its finished children (the worker processes)."""
    import resource

    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def run(quick: bool = False, workers: int = WORKERS) -> dict[str, Any]:
    from pf_offboard.sweep import engine, gains, plan, report
    from pf_offboard.sweep.runner import execute, rows_equal

    flights = 100 if quick else 1000
    sample_n = 4 if quick else 20
    out: dict[str, Any] = {"flights": flights, "workers": workers, "cpu_count": os.cpu_count(),
                           "load_average_1min_at_start": os.getloadavg()[0]}  # fmt: skip
    spec = plan.SweepSpec(flights=flights)
    out["flight_s"] = spec.settings.duration_s
    t0 = time.perf_counter()
    tasks = plan.tasks(CONFIG, spec)
    out["plan_s"] = time.perf_counter() - t0

    c0, t0 = _cpu(), time.perf_counter()
    rows = execute(tasks, workers=workers, engine="batch")
    out["batch_wall_s"] = time.perf_counter() - t0
    out["batch_flights_per_s"] = flights / out["batch_wall_s"]
    out["batch_cpu_s"] = _cpu() - c0  # this process and its worker processes
    out["batch_wall_s_on_idle_cores"] = out["batch_cpu_s"] / workers  # what the CPU time needs on free cores
    stats = report.summarize(rows, str(CONFIG), dataclasses.asdict(spec.settings))
    out["batch_success_rate"] = stats["success_rate"]
    for key in ("p50", "p90", "p99"):
        out[f"batch_caught_{key}_s"] = stats["caught_time"][f"{key}_s"]  # after activation, caught flights

    sample = tasks[:sample_n]
    c0, t0 = time.process_time(), time.perf_counter()
    scalar_rows = execute(sample, workers=1, engine="scalar")
    out["scalar_sample_flights"] = sample_n
    out["scalar_cpu_s_per_flight"] = (time.process_time() - c0) / sample_n
    out["scalar_wall_s_per_flight"] = (time.perf_counter() - t0) / sample_n
    out["scalar_wall_s_extrapolated"] = out["scalar_wall_s_per_flight"] * flights / workers
    out["scalar_extrapolated_note"] = f"from {sample_n} serial flights, x {flights} / {workers} workers (ideal speed-up)"
    out["speedup_batch_over_scalar"] = out["scalar_wall_s_extrapolated"] / out["batch_wall_s"]
    out["sample_rows_identical"] = rows_equal(rows[:sample_n], scalar_rows)

    out["ardupilot"] = _ardupilot(quick, workers)

    points, per = (4, 4) if quick else (20, 10)
    from pf_offboard.config import load_config

    bw = load_config(CONFIG).gains.transversal_bandwidth_hz
    cands = tuple(gains.candidates("grid", (max(0.5 * bw, gains.BANDWIDTH_HZ[0]), 1.5 * bw), (0.6, 1.2), points, 0))
    grid = plan.SweepSpec(flights=per, gains=cands)
    c0, t0 = _cpu(), time.perf_counter()
    grid_tasks = plan.tasks(CONFIG, grid)
    grid_rows = execute(grid_tasks, workers=workers, engine="batch")
    out["gain_grid"] = f"{points} x {points} x {per} flights"
    out["gain_grid_wall_s"] = time.perf_counter() - t0
    out["gain_grid_wall_s_on_idle_cores"] = (_cpu() - c0) / workers
    best = gains.rank(grid_rows, cands)[0]
    out["gain_grid_best"] = (f"{best['bandwidth_hz']:.3g} Hz / damping {best['damping']:.3g}: {100 * best['success_rate']:.0f} % "
                             f"converged (region of attraction), p90 {best['caught_p90_s']:.2f} s")  # fmt: skip

    if engine.available():
        import logging

        import distributed

        few = tasks[: (50 if quick else 200)]
        t0 = time.perf_counter()
        with distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                                      silence_logs=logging.ERROR) as cluster, distributed.Client(cluster) as client:  # fmt: skip
            started = time.perf_counter()
            dask_rows = execute(few, client=client, engine="batch")
            done = time.perf_counter()
        out["dask_local_flights"] = len(few)
        out["dask_local_startup_s"] = started - t0
        out["dask_local_wall_s"] = done - started
        out["dask_rows_identical"] = rows_equal(dask_rows, rows[: len(few)])
    else:
        out["dask_local"] = "not installed (pip install 'pf-offboard[cluster]')"
    out["load_average_1min_at_end"] = os.getloadavg()[0]
    return out


def _ardupilot(quick: bool, workers: int) -> dict[str, Any]:
    """The 1000 starts (``--quick``: 100) on the ArduPilot profile and the arducopter preset, attitude
    output (acceleration targets are jerk-limited on ArduPilot: the defaults do not fly them)."""
    from pf_offboard.sweep import plan, report
    from pf_offboard.sweep.runner import FlightSettings, execute, rows_equal

    flights = 100 if quick else 1000
    sample_n = 4 if quick else 20
    settings = dataclasses.replace(FlightSettings(), vehicle="arducopter", autopilot="ardupilot", output_mode="attitude")
    spec = plan.SweepSpec(flights=flights, settings=settings)
    tasks = plan.tasks(CONFIG, spec)
    out: dict[str, Any] = {"flights": flights, "vehicle": "arducopter", "autopilot": "ardupilot",
                           "output_mode": settings.output_mode, "load_average_1min_at_start": os.getloadavg()[0]}  # fmt: skip
    c0, t0 = _cpu(), time.perf_counter()
    rows = execute(tasks, workers=workers, engine="batch")
    out["batch_wall_s"] = time.perf_counter() - t0
    out["batch_cpu_s"] = _cpu() - c0
    out["batch_wall_s_on_idle_cores"] = out["batch_cpu_s"] / workers
    stats = report.summarize(rows, str(CONFIG), dataclasses.asdict(settings))
    out["batch_success_rate"] = stats["success_rate"]
    for key in ("p50", "p90", "p99"):
        out[f"batch_caught_{key}_s"] = stats["caught_time"][f"{key}_s"]
    c0, t0 = time.process_time(), time.perf_counter()
    scalar_rows = execute(tasks[:sample_n], workers=1, engine="scalar")
    out["scalar_sample_flights"] = sample_n
    out["scalar_cpu_s_per_flight"] = (time.process_time() - c0) / sample_n
    out["scalar_wall_s_extrapolated"] = (time.perf_counter() - t0) / sample_n * flights / workers
    out["speedup_batch_over_scalar"] = out["scalar_wall_s_extrapolated"] / out["batch_wall_s"]
    out["sample_rows_identical"] = rows_equal(rows[:sample_n], scalar_rows)
    out["load_average_1min_at_end"] = os.getloadavg()[0]
    return out
