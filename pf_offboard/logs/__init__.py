"""Flight logs: MAVLink ``.tlog`` (all traffic in and out) and the per-step controller CSV.

``replay`` and ``plot`` (the CLI sub-commands) live in :mod:`pf_offboard.logs.replay` and
:mod:`pf_offboard.logs.plot`; they are not imported here so ``import pf_offboard.logs`` stays
light (no matplotlib).
"""

from pf_offboard.logs.flightlog import FlightLog, FlightLogPaths
from pf_offboard.logs.steplog import COLUMNS, StepLogWriter, StepRecord, read_steplog
from pf_offboard.logs.tlog import OWN_COMPONENT_ID, LogError, TlogEntry, TlogWriter, iter_tlog, read_tlog

__all__ = [
    "COLUMNS",
    "FlightLog",
    "FlightLogPaths",
    "OWN_COMPONENT_ID",
    "LogError",
    "StepLogWriter",
    "StepRecord",
    "TlogEntry",
    "TlogWriter",
    "iter_tlog",
    "read_steplog",
    "read_tlog",
]
