"""Flight summary from a step log: how fast and how well the vehicle got onto the path.

Definitions (all over *active* steps, i.e. while the follower's setpoints were streamed):

- activation: vehicle time of the first active step;
- convergence time: time from activation to the first step after which every later active
  step has ``cross_track_m <= cross_track_tol_m`` and ``|eta2 - eta2_ref| <= speed_tol_m_s``
  (None when the flight never settles);
- cross-track RMS / max: over active steps from convergence on;
- speed error RMS: of ``eta2 - eta2_ref`` over the same steps;
- saturation time: per limit, the summed duration of active steps whose flag is set (each
  step counts for the interval to the next step);
- mode changes: (time, from, to) whenever the ``mode`` column changes, and logged events.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pf_offboard.logs.steplog import StepRecord, column

SAT_FLAGS = ("sat_tangential", "sat_transversal", "sat_tilt", "sat_thrust", "sat_approach_speed")


@dataclass(frozen=True)
class FlightSummary:
    duration_s: float
    steps: int
    active_steps: int
    activation_time_s: float | None  # vehicle time
    convergence_time_s: float | None  # seconds after activation
    cross_track_rms_m: float | None
    cross_track_max_m: float | None
    speed_error_rms_m_s: float | None
    saturation_s: dict[str, float]
    mode_changes: tuple[tuple[float, str, str], ...]
    events: tuple[tuple[float, str], ...]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: every field by name (units in the names; None where undefined)."""
        return {
            "duration_s": self.duration_s,
            "steps": self.steps,
            "active_steps": self.active_steps,
            "activation_time_s": self.activation_time_s,
            "convergence_time_s": self.convergence_time_s,
            "cross_track_rms_m": self.cross_track_rms_m,
            "cross_track_max_m": self.cross_track_max_m,
            "speed_error_rms_m_s": self.speed_error_rms_m_s,
            "saturation_s": dict(self.saturation_s),
            "mode_changes": [{"time_s": t, "from": a, "to": b} for t, a, b in self.mode_changes],
            "events": [{"time_s": t, "event": e} for t, e in self.events],
        }

    def lines(self) -> list[str]:
        """Human-readable summary, one fact per line."""

        def f(x: float | None, unit: str, fmt: str = ".3f") -> str:
            return "n/a" if x is None else f"{x:{fmt}} {unit}"

        out = [
            f"duration            {self.duration_s:.3f} s, {self.steps} steps ({self.active_steps} active)",
            f"activation          {f(self.activation_time_s, 's (vehicle time)')}",
            f"convergence time    {f(self.convergence_time_s, 's after activation')}",
            f"cross-track RMS     {f(self.cross_track_rms_m, 'm', '.4f')} (after convergence)",
            f"cross-track max     {f(self.cross_track_max_m, 'm', '.4f')} (after convergence)",
            f"speed error RMS     {f(self.speed_error_rms_m_s, 'm/s', '.4f')} (after convergence)",
            "saturation          " + ", ".join(f"{k.removeprefix('sat_')} {v:.2f} s" for k, v in self.saturation_s.items()),
        ]
        for t, a, b in self.mode_changes:
            out.append(f"mode change         t={t:.3f} s: {a or '-'} -> {b}")
        for t, e in self.events:
            out.append(f"event               t={t:.3f} s: {e}")
        return out


def summarize(
    records: Sequence[StepRecord], cross_track_tol_m: float = 0.05, speed_tol_m_s: float = 0.1
) -> FlightSummary:
    """Summarise a flight's step log (see the module docstring for the definitions)."""
    n = len(records)
    if n == 0:
        return FlightSummary(0.0, 0, 0, None, None, None, None, None, {k: 0.0 for k in SAT_FLAGS}, (), ())
    t = column(records, "time_s")
    active = np.array([r.active for r in records], dtype=bool)
    dt = np.diff(t, append=t[-1])  # each step lasts until the next one
    saturation = {k: float(np.sum(dt[active & np.array([getattr(r, k) for r in records], dtype=bool)])) for k in SAT_FLAGS}
    modes: list[tuple[float, str, str]] = []
    prev = ""
    for r in records:
        if r.mode != prev:
            modes.append((r.time_s, prev, r.mode))
            prev = r.mode
    events = tuple((r.time_s, r.event) for r in records if r.event)
    idx = np.flatnonzero(active)
    if idx.size == 0:
        return FlightSummary(float(t[-1] - t[0]), n, 0, None, None, None, None, None, saturation, tuple(modes), events)
    ct = column(records, "cross_track_m")[idx]
    err = (column(records, "eta2_m_s") - column(records, "speed_ref_m_s"))[idx]
    good = (ct <= cross_track_tol_m) & (np.abs(err) <= speed_tol_m_s)
    good &= np.isfinite(ct) & np.isfinite(err)
    # first index from which all later active steps are good
    bad = np.flatnonzero(~good)
    first = 0 if bad.size == 0 else int(bad[-1]) + 1
    t_act = float(t[idx[0]])
    if first >= idx.size:
        conv = rms = mx = srms = None
    else:
        conv = float(t[idx[first]]) - t_act
        rms = float(math.sqrt(np.mean(ct[first:] ** 2)))
        mx = float(np.max(ct[first:]))
        srms = float(math.sqrt(np.mean(err[first:] ** 2)))
    return FlightSummary(
        duration_s=float(t[-1] - t[0]),
        steps=n,
        active_steps=int(idx.size),
        activation_time_s=t_act,
        convergence_time_s=conv,
        cross_track_rms_m=rms,
        cross_track_max_m=mx,
        speed_error_rms_m_s=srms,
        saturation_s=saturation,
        mode_changes=tuple(modes),
        events=events,
    )


SUMMARY_JSON = "summary.json"
SUMMARY_SCHEMA = 1


def flight_report(summary: FlightSummary | None, exit_code: int, reason: str, log_dir: str | Path | None,
                  config: Any = None, command: str = "fly") -> dict[str, Any]:  # fmt: skip
    """The end-of-flight report as one JSON-ready mapping: how the flight ended, the summary, the
    logs, and the path's geodetic origin when the path came from a planning tool."""
    geodetic = getattr(getattr(config, "path", None), "geodetic", None)
    origin = getattr(geodetic, "origin", None)
    report: dict[str, Any] = {
        "schema": SUMMARY_SCHEMA,
        "command": command,
        "exit_code": exit_code,
        "reason": reason,
        "log_dir": str(Path(log_dir).resolve()) if log_dir is not None else None,  # absolute: machines read it from anywhere
        "config": getattr(config, "source", None),
        "summary": summary.to_dict() if summary is not None else None,
    }
    if geodetic is not None:
        report["path_file"] = {
            "file": geodetic.file,
            "altitude_reference": geodetic.altitude_reference,
            "origin": None if origin is None else {"lat_deg": origin.lat_deg, "lon_deg": origin.lon_deg, "alt_amsl_m": origin.alt_amsl_m},
            "home_alt_amsl_m": geodetic.home_alt_amsl_m,
        }
    return report


def write_report(report: dict[str, Any], log_dir: str | Path) -> Path:
    """``LOG_DIR/summary.json`` (non-finite numbers as null)."""
    out = Path(log_dir) / SUMMARY_JSON
    out.write_text(report_json(report) + "\n", encoding="utf-8")
    return out


def report_json(report: dict[str, Any]) -> str:
    """Strict JSON (NaN / inf become null)."""

    def clean(v: Any) -> Any:
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        return v

    return json.dumps(clean(report), indent=2, allow_nan=False)
