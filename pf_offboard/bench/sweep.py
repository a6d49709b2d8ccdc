"""Benchmark of ``pf-offboard sweep``: the same flights serially, on a local process pool, and on
Dask in local mode (a LocalCluster of single-threaded worker processes); and the cost of writing
each flight's logs.

The flights are the sweep's defaults (configs/px4-sih.yaml on the px4-sih preset, thrown starts
<= 5 m / 4 m/s off the path, 15 s each). Figures: wall time of each executor and its speed-up over
the serial run; the Dask figures without and with the LocalCluster's start-up; CPU seconds per
flight with and without logs. Every executor must give the same rows (checked, not timed).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from pathlib import Path
from typing import Any

WORKERS = 2
CONFIG = Path(__file__).resolve().parents[1] / "configs" / "px4-sih.yaml"  # package data


def run(quick: bool = False, workers: int = WORKERS) -> dict[str, Any]:
    from pf_offboard.sweep import engine, plan
    from pf_offboard.sweep.runner import execute, rows_equal, run_flight

    flights = 8 if quick else 40
    tasks = plan.tasks(CONFIG, plan.SweepSpec(flights=flights))
    out: dict[str, Any] = {"flights": flights, "workers": workers, "flight_s": tasks[0].settings.duration_s}

    t0 = time.perf_counter()
    serial = execute(tasks, workers=1)
    out["serial_wall_s"] = time.perf_counter() - t0
    out["serial_flights_per_s"] = flights / out["serial_wall_s"]

    t0 = time.perf_counter()
    pooled = execute(tasks, workers=workers)
    out["pool_wall_s"] = time.perf_counter() - t0
    out["pool_speedup"] = out["serial_wall_s"] / out["pool_wall_s"]
    out["pool_rows_identical"] = rows_equal(pooled, serial)

    if engine.available():
        import logging

        import distributed

        t0 = time.perf_counter()
        with distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                                      silence_logs=logging.ERROR) as cluster, distributed.Client(cluster) as client:  # fmt: skip
            started = time.perf_counter()
            dask_rows = execute(tasks, client=client)
            done = time.perf_counter()
        out["dask_local_startup_s"] = started - t0
        out["dask_local_wall_s"] = done - started
        out["dask_local_speedup"] = out["serial_wall_s"] / out["dask_local_wall_s"]
        out["dask_local_speedup_with_startup"] = out["serial_wall_s"] / (done - t0)
        out["dask_rows_identical"] = rows_equal(dask_rows, serial)
    else:
        out["dask_local"] = "not installed (pip install 'pf-offboard[cluster]')"

    sample = tasks[: max(2, flights // 5)]
    with tempfile.TemporaryDirectory(prefix="pf-bench-sweep-") as tmp:
        for label, logs in (("no_logs", None), ("logs", tmp)):
            c0 = time.process_time()
            for task in sample:
                run_flight(dataclasses.replace(task, logs_dir=logs))
            out[f"{label}_cpu_s_per_flight"] = (time.process_time() - c0) / len(sample)
    out["logs_cost_percent"] = 100.0 * (out["logs_cpu_s_per_flight"] / out["no_logs_cpu_s_per_flight"] - 1.0)
    return out
