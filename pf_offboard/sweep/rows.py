"""A sweep flight's outcome columns from what it produced: one function shared by the scalar
engine (:mod:`pf_offboard.sweep.runner`) and the batch engine (:mod:`pf_offboard.sim.batch.flight`),
so the same numbers give the same row. Imports neither engine."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pf_offboard.sweep.runner import FlightSettings


def finish_row(row: dict[str, Any], s: FlightSettings, reason: str, crashed: bool, sim_time_s: float, ct_max: float | None,
               act: float | None, conv: float | None, first: float | None, last: float | None, max_out_m: float,
               max_after_m: float, rms_after_m: float) -> dict[str, Any]:  # fmt: skip
    """The row's outcome columns from what a flight produced (shared by both engines: the same
    numbers give the same row)."""
    ground = crashed or reason.startswith("on the ground")
    if ground:
        success = False
    elif act is None or conv is None:
        if first is not None and last is not None:
            success, reason = False, (f"{reason}; within {s.tube_m:g} m at {first:.2f} s, then beyond {s.stay_m:g} m "
                                      f"(max {max_out_m:.2f} m, last at {last:.2f} s) and not back by the end")  # fmt: skip
        else:
            success, reason = False, f"{reason}; never within {s.tube_m:g} m of the path"
    elif sim_time_s - conv < s.settle_s - 1e-9:
        success, reason = False, f"{reason}; caught only {sim_time_s - conv:.2f} s before the end"
    else:
        success = True
    row.update(outcome(success, crashed, ground, reason, act, None if conv is None or act is None else conv - act,
                        ct_max, max_after_m if conv is not None else math.nan, rms_after_m, sim_time_s))  # fmt: skip
    row["first_in_tube_time_s"] = first - act if (first is not None and act is not None) else math.nan
    return row


def outcome(success: bool, crashed: bool, ground: bool, reason: str, activation: float | None, conv: float | None,
             ct_max: float | None, ct_max_after: float, ct_rms_after: float, sim_time_s: float) -> dict[str, Any]:  # fmt: skip
    nan = math.nan
    return {
        "success": success,
        "crashed": crashed,
        "ground_contact": ground,
        "activation_time_s": nan if activation is None else activation,
        "caught_time_s": nan if conv is None else conv,  # after activation; NaN if not converged
        "cross_track_max_m": nan if ct_max is None else ct_max,  # over every active step
        "cross_track_max_after_m": ct_max_after,  # from convergence on (NaN if not converged)
        "cross_track_rms_after_m": ct_rms_after,
        "sim_time_s": sim_time_s,
        "reason": reason,
    }
