"""Flight summary from a step log: how fast and how well the vehicle got onto the path.

Definitions (all over *active* steps, i.e. while the follower's setpoints were streamed):

- activation: vehicle time of the first active step;
- convergence time: time from activation to the first step after which every later active
  step has ``cross_track_m <= cross_track_tol_m`` and ``|eta2 - eta2_ref| <= speed_tol_m_s``
  (None when the flight never settles);
- cross-track RMS / max: over active steps from convergence on;
- speed error RMS: of ``eta2 - eta2_ref`` over the same steps;
- whole flight: cross-track RMS / max and speed error RMS / mean over *every* active step from
  activation on (always given when there are active steps, also when the convergence rule
  never holds, e.g. on a real vehicle whose GPS noise keeps it beyond 5 cm);
- saturation time: per limit, the summed duration of active steps whose flag is set (each
  step counts for the interval to the next step);
- mode changes: (time, from, to) whenever the ``mode`` column changes, and logged events.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pf_offboard.logs.steplog import StepRecord

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
    # over every active step (from activation on); None without active steps
    whole_cross_track_rms_m: float | None = None
    whole_cross_track_max_m: float | None = None
    whole_speed_error_rms_m_s: float | None = None
    whole_speed_error_mean_m_s: float | None = None

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
            "whole_cross_track_rms_m": self.whole_cross_track_rms_m,
            "whole_cross_track_max_m": self.whole_cross_track_max_m,
            "whole_speed_error_rms_m_s": self.whole_speed_error_rms_m_s,
            "whole_speed_error_mean_m_s": self.whole_speed_error_mean_m_s,
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
            f"whole flight        cross-track RMS {f(self.whole_cross_track_rms_m, 'm', '.4f')}, max {f(self.whole_cross_track_max_m, 'm', '.4f')}; "
            f"speed error RMS {f(self.whole_speed_error_rms_m_s, 'm/s', '.4f')}, mean {f(self.whole_speed_error_mean_m_s, 'm/s', '+.4f')} "
            "(all active steps)",
            "saturation          " + ", ".join(f"{k.removeprefix('sat_')} {v:.2f} s" for k, v in self.saturation_s.items()),
        ]
        for t, a, b in self.mode_changes:
            out.append(f"mode change         t={t:.3f} s: {a or '-'} -> {b}")
        for t, e in self.events:
            out.append(f"event               t={t:.3f} s: {e}")
        return out


# Events kept for the summary: a flight that logs an event on every step (e.g. a hold sent instead
# of a non-finite command) must not grow the summary without bound. The count of the rest is kept.
MAX_EVENTS = 200


class SummaryAccumulator:
    """The :class:`FlightSummary` of a stream of step records, in constant memory.

    ``add(record)`` per step, ``result()`` at any time; the same definitions as :func:`summarize`
    (which is this, over a sequence). Convergence is "the first active step after the last bad
    one": the sums over the steps from convergence on restart at every bad active step, so only
    running sums are kept, never the steps.
    """

    def __init__(self, cross_track_tol_m: float = 0.05, speed_tol_m_s: float = 0.1) -> None:
        self.cross_track_tol_m = cross_track_tol_m
        self.speed_tol_m_s = speed_tol_m_s
        self.steps = 0
        self.active_steps = 0
        self._t_first = self._t_last = math.nan
        self._prev: StepRecord | None = None  # its saturation lasts until this step
        self._saturation = {k: 0.0 for k in SAT_FLAGS}
        self._modes: list[tuple[float, str, str]] = []
        self._mode = ""
        self._events: list[tuple[float, str]] = []
        self.events_dropped = 0
        self._t_act: float | None = None
        # the window from convergence on: start time, count, sum of squares, max
        self._conv_t: float | None = None
        self._n = 0
        self._ct2 = 0.0
        self._ct_max = -math.inf
        self._err2 = 0.0
        # the whole flight (every finite active step): count, sums of squares, max, sum
        self._w_nc = self._w_ne = 0
        self._w_ct2 = self._w_err2 = self._w_err = 0.0
        self._w_ct_max = -math.inf

    def add(self, r: StepRecord) -> None:
        t = r.time_s
        prev = self._prev
        if prev is not None and prev.active:
            dt = t - prev.time_s
            for k in SAT_FLAGS:
                if getattr(prev, k):
                    self._saturation[k] += dt
        if self.steps == 0:
            self._t_first = t
        self._t_last = t
        self.steps += 1
        self._prev = r
        if r.mode != self._mode:
            self._modes.append((t, self._mode, r.mode))
            self._mode = r.mode
        if r.event:
            if len(self._events) < MAX_EVENTS:
                self._events.append((t, r.event))
            else:
                self.events_dropped += 1
        if not r.active:
            return
        self.active_steps += 1
        if self._t_act is None:
            self._t_act = t
        ct = r.cross_track_m
        err = r.eta2_m_s - r.speed_ref_m_s
        if math.isfinite(ct):
            self._w_nc += 1
            self._w_ct2 += ct * ct
            self._w_ct_max = max(self._w_ct_max, ct)
        if math.isfinite(err):
            self._w_ne += 1
            self._w_err2 += err * err
            self._w_err += err
        good = ct <= self.cross_track_tol_m and abs(err) <= self.speed_tol_m_s  # False for NaN
        if not good:
            self._conv_t, self._n, self._ct2, self._ct_max, self._err2 = None, 0, 0.0, -math.inf, 0.0
            return
        if self._conv_t is None:
            self._conv_t = t
        self._n += 1
        self._ct2 += ct * ct
        self._ct_max = max(self._ct_max, ct)
        self._err2 += err * err

    def result(self) -> FlightSummary:
        if self.steps == 0:
            return FlightSummary(0.0, 0, 0, None, None, None, None, None, {k: 0.0 for k in SAT_FLAGS}, (), ())
        events = tuple(self._events)
        if self.events_dropped:
            events += ((self._t_last, f"... {self.events_dropped} more events (see the step log)"),)
        duration = float(self._t_last - self._t_first)
        saturation = dict(self._saturation)
        if self._t_act is None:
            return FlightSummary(duration, self.steps, 0, None, None, None, None, None, saturation, tuple(self._modes), events)
        if self._conv_t is None:
            conv = rms = mx = srms = None
        else:
            conv = self._conv_t - self._t_act
            rms = math.sqrt(self._ct2 / self._n)
            mx = self._ct_max
            srms = math.sqrt(self._err2 / self._n)
        return FlightSummary(
            duration_s=duration,
            steps=self.steps,
            active_steps=self.active_steps,
            activation_time_s=self._t_act,
            convergence_time_s=conv,
            cross_track_rms_m=rms,
            cross_track_max_m=mx,
            speed_error_rms_m_s=srms,
            saturation_s=saturation,
            mode_changes=tuple(self._modes),
            events=events,
            whole_cross_track_rms_m=math.sqrt(self._w_ct2 / self._w_nc) if self._w_nc else None,
            whole_cross_track_max_m=self._w_ct_max if self._w_nc else None,
            whole_speed_error_rms_m_s=math.sqrt(self._w_err2 / self._w_ne) if self._w_ne else None,
            whole_speed_error_mean_m_s=self._w_err / self._w_ne if self._w_ne else None,
        )


def summarize(
    records: Iterable[StepRecord], cross_track_tol_m: float = 0.05, speed_tol_m_s: float = 0.1
) -> FlightSummary:
    """Summarise a flight's step log (see the module docstring for the definitions)."""
    acc = SummaryAccumulator(cross_track_tol_m, speed_tol_m_s)
    for r in records:
        acc.add(r)
    return acc.result()


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
