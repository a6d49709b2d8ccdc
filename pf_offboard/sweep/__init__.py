"""``pf-offboard sweep``: many in-process ``sim`` flights from seeded random thrown starts.

See :mod:`pf_offboard.sweep.starts` (the draws), :mod:`pf_offboard.sweep.runner` (one flight as a
task, the local executors), :mod:`pf_offboard.sweep.engine` (Dask, the optional ``cluster``
extra), :mod:`pf_offboard.sweep.gains` (gain sweeps), :mod:`pf_offboard.sweep.report` (the table,
statistics and the region-of-attraction plot) and :mod:`pf_offboard.sweep.cli` (the command).
"""

from pf_offboard.sweep.plan import SweepResult, SweepSpec, run, tasks
from pf_offboard.sweep.runner import FlightSettings, FlightTask, execute, run_flight
from pf_offboard.sweep.starts import Start, StartRanges, sample_start

__all__ = [
    "FlightSettings", "FlightTask", "Start", "StartRanges", "SweepResult", "SweepSpec", "execute", "run", "run_flight",
    "sample_start", "tasks",
]
