"""Flight summary from a step log: how fast and how well the vehicle got onto the path.

The measures are :mod:`pf_offboard.logs.measures`' (one definition for every command), over
*active* steps (while the follower's setpoints were streamed):

- activation: vehicle time of the first active step;
- convergence time: from activation to the first time the cross-track error stays <= 10 cm for
  1 s (None when it never does);
- two named windows, each with cross-track RMS / max, the speed along the path from the
  *position's* derivative (±0.1 s, on the path's tangent: mean, error RMS and mean), and the
  estimator's velocity figure (η2 − η2_ref, RMS and mean) beside it: "from activation + 8 s" (what
  the docs quote; None in a shorter flight) and "whole flight" (every active step);
- saturation time: per limit, the summed duration of active steps whose flag is set (each
  step counts for the interval to the next step);
- mode changes: (time, from, to) whenever the ``mode`` column changes, and logged events;
- on a closed path, the time of each whole lap from activation and, beside it, the point-mass
  lower bound of a lap at the vehicle's limits (:class:`pf_offboard.logs.measures.LapTimer`;
  :meth:`pf_offboard.control.PathFollower.lap_time_bound_s`);
- the inner-loop model identified in flight (``compensation.identify_online``): the last
  ``identified: ...`` event of the step log (:func:`identified_event`), None when none was adopted.

Without the path (``tangent=None``) the position-derived speed is not available (n/a).
"""

from __future__ import annotations

import json
import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pf_offboard.logs.measures import (
    CONVERGED_DEFINITION,
    DERIVATIVE_HALF_WINDOW_S,
    SETTLE_S,
    WINDOW_SETTLED,
    WINDOW_WHOLE,
    Convergence,
    LapTimer,
    Tangent,
    WindowFigures,
    WindowSums,
    settled_window,
)
from pf_offboard.logs.steplog import StepRecord

IDENTIFIED_PREFIX = "identified: "
_IDENTIFIED_KEYS = ("lag_s", "delay_s", "drag_1_s")
_FITTED_KEYS = ("gain_xy", "gain_z", "drag_z_1_s")  # a joint model's, when not the defaults


def identified_event(lag_s: float, delay_s: float, drag_1_s: float, gain_xy: float = 1.0, gain_z: float = 1.0,
                     drag_z_1_s: float = 0.0) -> str:  # fmt: skip
    """The step log's event for an adopted inner-loop model (floats as ``repr``: read back exactly;
    the gains and vertical drag only when fitted, not 1 and 0)."""
    text = IDENTIFIED_PREFIX + " ".join(f"{k}={float(v)!r}" for k, v in zip(_IDENTIFIED_KEYS, (lag_s, delay_s, drag_1_s)))
    for key, value, default in (("gain_xy", gain_xy, 1.0), ("gain_z", gain_z, 1.0), ("drag_z_1_s", drag_z_1_s, 0.0)):
        if value != default:
            text += f" {key}={float(value)!r}"
    return text


ROLLED_BACK_PREFIX = "rolled_back: "


def rolled_back_event(lag_s: float, delay_s: float, drag_1_s: float, gain_xy: float, cross_track_rms_m: float,
                      reference_cross_track_rms_m: float, speed_error_rms_m_s: float,
                      reference_speed_error_rms_m_s: float) -> str:  # fmt: skip
    """The step log's event for an adoption the rollback guard undid (the rejected model, and the
    errors' low-passed RMS that fired it against their reference); the model flown before it is
    flown again (the summary's ``identified_model`` goes back to it)."""
    values = (lag_s, delay_s, drag_1_s, gain_xy, cross_track_rms_m, reference_cross_track_rms_m, speed_error_rms_m_s,
              reference_speed_error_rms_m_s)  # fmt: skip
    keys = ("lag_s", "delay_s", "drag_1_s", "gain_xy", "cross_track_rms_m", "reference_cross_track_rms_m",
            "speed_error_rms_m_s", "reference_speed_error_rms_m_s")  # fmt: skip
    return ROLLED_BACK_PREFIX + " ".join(f"{k}={float(v):.4g}" for k, v in zip(keys, values))


def parse_identified(event: str) -> dict[str, float] | None:
    """The model an ``identified: ...`` event names (None when the event is another one)."""
    if not event.startswith(IDENTIFIED_PREFIX):
        return None
    try:
        values = dict(item.split("=", 1) for item in event[len(IDENTIFIED_PREFIX):].split())
        model = {k: float(values[k]) for k in _IDENTIFIED_KEYS}
        for key in _FITTED_KEYS:
            if key in values:
                model[key] = float(values[key])
        return model
    except (KeyError, ValueError):
        return None


SAT_FLAGS = ("sat_tangential", "sat_transversal", "sat_tilt", "sat_thrust", "sat_approach_speed")


@dataclass(frozen=True)
class FlightSummary:
    duration_s: float
    steps: int
    active_steps: int
    activation_time_s: float | None  # vehicle time
    convergence_time_s: float | None  # seconds after activation (measures.CONVERGED_DEFINITION)
    settled: WindowFigures | None  # from activation + 8 s
    whole: WindowFigures | None  # every active step
    saturation_s: dict[str, float]
    mode_changes: tuple[tuple[float, str, str], ...]
    events: tuple[tuple[float, str], ...]
    # closed path: each whole lap's time from activation (s; the first includes the approach), and
    # the point-mass lower bound of one lap at the vehicle's limits (s; None when not given)
    lap_times_s: tuple[float, ...] = ()
    lap_time_bound_s: float | None = None
    # the inner-loop model adopted in flight, the last one (lag_s, delay_s, drag_1_s, adopted_at_s:
    # vehicle time); None when the flight kept the model it was given
    identified_model: dict[str, float] | None = None

    # shorthands (window in the name)
    @property
    def settled_cross_track_rms_m(self) -> float | None:
        return None if self.settled is None else self.settled.cross_track_rms_m

    @property
    def settled_speed_error_rms_m_s(self) -> float | None:
        return None if self.settled is None else self.settled.speed_error_rms_m_s

    @property
    def whole_cross_track_rms_m(self) -> float | None:
        return None if self.whole is None else self.whole.cross_track_rms_m

    @property
    def whole_cross_track_max_m(self) -> float | None:
        return None if self.whole is None else self.whole.cross_track_max_m

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: every field by name (units and windows in the names; None where undefined)."""
        return {
            "duration_s": self.duration_s,
            "steps": self.steps,
            "active_steps": self.active_steps,
            "activation_time_s": self.activation_time_s,
            "convergence_time_s": self.convergence_time_s,
            "convergence_definition": CONVERGED_DEFINITION,
            "from_activation_plus_8s": None if self.settled is None else self.settled.to_dict(),
            "whole_flight": None if self.whole is None else self.whole.to_dict(),
            "saturation_s": dict(self.saturation_s),
            "mode_changes": [{"time_s": t, "from": a, "to": b} for t, a, b in self.mode_changes],
            "events": [{"time_s": t, "event": e} for t, e in self.events],
            "lap_times_s": list(self.lap_times_s),
            "lap_time_bound_s": self.lap_time_bound_s,
            "identified_model": None if self.identified_model is None else dict(self.identified_model),
        }

    def lines(self) -> list[str]:
        """Human-readable summary, one fact per line; each figure names its window."""

        def f(x: float | None, unit: str, fmt: str = ".3f") -> str:
            return "n/a" if x is None else f"{x:{fmt}} {unit}"

        out = [
            f"duration            {self.duration_s:.3f} s, {self.steps} steps ({self.active_steps} active)",
            f"activation          {f(self.activation_time_s, 's (vehicle time)')}",
            f"converged           {f(self.convergence_time_s, 's after activation', '.2f')} ({CONVERGED_DEFINITION})",
            (self.settled.line() if self.settled is not None else f"{WINDOW_SETTLED}: n/a (the flight followed for less than 8 s)"),
            (self.whole.line() if self.whole is not None else f"{WINDOW_WHOLE}: n/a (no active step)"),
            "saturation          " + ", ".join(f"{k.removeprefix('sat_')} {v:.2f} s" for k, v in self.saturation_s.items()),
        ]
        if self.lap_times_s or self.lap_time_bound_s is not None:
            laps = ", ".join(f"{x:.2f}" for x in self.lap_times_s) or "none completed"
            bound = "" if self.lap_time_bound_s is None else f"; point-mass bound at the vehicle's limits {self.lap_time_bound_s:.2f} s"
            out.append(f"lap times           {laps} s (from activation; the first includes the approach){bound}")
        m = self.identified_model
        if m is None:
            out.append("identified model    none adopted (the configured or typical inner-loop model was flown)")
        else:
            gain = f", gain {m['gain_xy']:.3f}" if "gain_xy" in m else ""
            if "gain_z" in m or "drag_z_1_s" in m:
                gain += f"; vertical gain {m.get('gain_z', 1.0):.3f}, drag {m.get('drag_z_1_s', 0.0):.3f} 1/s"
            out.append(f"identified model    lag {m['lag_s']:.3f} s, dead time {m['delay_s']:.3f} s, drag {m['drag_1_s']:.3f} 1/s{gain} "
                       f"(adopted at t={m['adopted_at_s']:.3f} s)")  # fmt: skip
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
    (which is this, over a sequence) and :func:`pf_offboard.logs.measures.tracking`. The position's
    central difference needs the steps up to 0.1 s after each: a step is counted once a step 0.1 s
    later has arrived (a short delay line of recent steps), the last 0.1 s at ``result()``.
    """

    def __init__(self, tangent: Tangent | None = None, settle_s: float = SETTLE_S) -> None:
        self.tangent = tangent
        self.settle_s = settle_s
        self._laps: LapTimer | None = None
        self.lap_time_bound_s: float | None = None
        self.steps = 0
        self.active_steps = 0
        self._t_first = self._t_last = math.nan
        self._prev: StepRecord | None = None  # its saturation lasts until this step
        self._saturation = {k: 0.0 for k in SAT_FLAGS}
        self._modes: list[tuple[float, str, str]] = []
        self._mode = ""
        self._events: list[tuple[float, str]] = []
        self.events_dropped = 0
        self._identified: dict[str, float] | None = None
        self._adoptions: list[dict[str, float]] = []  # in order; a rollback removes the last
        self._t_act: float | None = None
        self._conv = Convergence()
        self._settled = WindowSums(settled_window(settle_s), settle_s)
        self._whole = WindowSums(WINDOW_WHOLE, 0.0)
        # recent steps [time, position, active record or None, counted]: the ones waiting for their
        # +0.1 s neighbour and those still needed as a -0.1 s neighbour
        self._recent: deque[list[Any]] = deque()
    def time_laps(self, length_m: float, bound_s: float | None = None) -> None:
        """A closed path of ``length_m``: time its laps (and report ``bound_s`` beside them)."""
        self._laps = LapTimer(length_m)
        self.lap_time_bound_s = bound_s if bound_s is not None and math.isfinite(bound_s) else None

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
            for part in r.event.split(";"):
                model = parse_identified(part)
                if model is not None:
                    self._adoptions.append({**model, "adopted_at_s": t})
                elif part.startswith(ROLLED_BACK_PREFIX) and self._adoptions:
                    self._adoptions.pop()
                else:
                    continue
                self._identified = self._adoptions[-1] if self._adoptions else None
            if len(self._events) < MAX_EVENTS:
                self._events.append((t, r.event))
            else:
                self.events_dropped += 1
        if r.active:
            self.active_steps += 1
            if self._t_act is None:
                self._t_act = t
            self._conv.add(t, r.cross_track_m)
            if self._laps is not None:
                self._laps.add(t, r.eta1_m, r.speed_ref_m_s)
        pos = np.asarray(r.position_enu_m, dtype=float)
        if not (math.isfinite(t) and (not self._recent or t > self._recent[-1][0])):
            # not newer than the last step: no derivative through it; counted without one
            if r.active:
                self._count(r, math.nan, self._settled, self._whole)
            return
        self._recent.append([t, pos, r if r.active else None, False])
        self._drain(final=False, settled=self._settled, whole=self._whole)

    def _count(self, r: StepRecord, speed: float, settled: WindowSums, whole: WindowSums) -> None:
        assert self._t_act is not None
        args = (r.time_s, r.cross_track_m, speed, r.eta2_m_s, r.speed_ref_m_s)
        whole.add(*args)
        if r.time_s >= self._t_act + self.settle_s:
            settled.add(*args)

    def _speed(self, i: int) -> float:
        """Position-derived speed along the path of ``_recent[i]`` (NaN without both neighbours)."""
        h = DERIVATIVE_HALF_WINDOW_S
        t, _, r, _ = self._recent[i]
        if self.tangent is None or r is None or not math.isfinite(r.lam):
            return math.nan
        recent = self._recent
        if t - h < recent[0][0] or t + h > recent[-1][0]:
            return math.nan
        return float(np.dot((self._at(t + h, i, 1) - self._at(t - h, i, -1)) / (2.0 * h), self.tangent(r.lam)))

    def _at(self, t: float, i: int, step: int) -> np.ndarray:
        """The position at time ``t`` (linear between the recent steps around it), searching from
        step ``i`` forward (``step`` 1, ``t`` after it) or back (-1, ``t`` before it)."""
        recent = self._recent
        j = i
        if step > 0:
            while j + 1 < len(recent) - 1 and recent[j + 1][0] < t:
                j += 1
            a, b = recent[j], recent[j + 1]
        else:
            while j - 1 > 0 and recent[j - 1][0] > t:
                j -= 1
            a, b = recent[j - 1], recent[j]
        w = (t - a[0]) / (b[0] - a[0])
        return np.asarray(a[1]) + w * (np.asarray(b[1]) - np.asarray(a[1]))

    def _drain(self, final: bool, settled: WindowSums, whole: WindowSums) -> None:
        """Count the active steps whose +0.1 s neighbour has arrived (all of them if ``final``, into
        ``settled`` / ``whole`` only); then forget what no later step needs."""
        h = DERIVATIVE_HALF_WINDOW_S
        t_last = self._recent[-1][0]
        first_pending: float | None = None
        for i, entry in enumerate(self._recent):
            t, _, r, counted = entry
            if r is None or counted:
                continue
            if not final and t + h > t_last:
                first_pending = t
                break
            self._count(r, self._speed(i), settled, whole)
            if not final:
                entry[3] = True
        if final:
            return
        keep_from = (first_pending if first_pending is not None else t_last) - h
        while len(self._recent) > 1 and self._recent[1][0] <= keep_from:
            self._recent.popleft()

    def result(self) -> FlightSummary:
        if self.steps == 0:
            return FlightSummary(0.0, 0, 0, None, None, None, None, {k: 0.0 for k in SAT_FLAGS}, (), ())
        events = tuple(self._events)
        if self.events_dropped:
            events += ((self._t_last, f"... {self.events_dropped} more events (see the step log)"),)
        duration = float(self._t_last - self._t_first)
        saturation = dict(self._saturation)
        if self._t_act is None:
            return FlightSummary(duration, self.steps, 0, None, None, None, None, saturation, tuple(self._modes), events,
                                 identified_model=self._identified)  # fmt: skip
        settled, whole = self._settled.copy(), self._whole.copy()
        self._drain(final=True, settled=settled, whole=whole)  # the last 0.1 s: no derivative
        conv = self._conv.time_s
        return FlightSummary(
            duration_s=duration,
            steps=self.steps,
            active_steps=self.active_steps,
            activation_time_s=self._t_act,
            convergence_time_s=None if conv is None else conv - self._t_act,
            settled=settled.result(),
            whole=whole.result(),
            saturation_s=saturation,
            mode_changes=tuple(self._modes),
            events=events,
            lap_times_s=tuple(self._laps.laps_s) if self._laps is not None else (),
            lap_time_bound_s=self.lap_time_bound_s,
            identified_model=self._identified,
        )


def summarize(records: Iterable[StepRecord], tangent: Tangent | None = None, settle_s: float = SETTLE_S,
              follower: Any = None) -> FlightSummary:  # fmt: skip
    """Summarise a flight's step log (see the module docstring for the definitions); ``tangent``:
    the path's (:func:`pf_offboard.logs.measures.path_tangent`) for the position-derived speed;
    ``follower``: its path's laps are timed (closed path) beside its lap-time bound."""
    acc = SummaryAccumulator(tangent, settle_s)
    time_laps_of(acc, follower)
    for r in records:
        acc.add(r)
    return acc.result()


def time_laps_of(acc: SummaryAccumulator, follower: Any) -> None:
    """Time the laps of ``follower``'s path if it is closed, beside its point-mass bound (a
    follower without :meth:`~pf_offboard.control.PathFollower.lap_time_bound_s`: no bound)."""
    path = getattr(follower, "path", None)
    if path is None or not bool(getattr(path, "closed", False)):
        return
    bound = getattr(follower, "lap_time_bound_s", None)
    acc.time_laps(float(path.length_m), float(bound()) if callable(bound) else None)


SUMMARY_JSON = "summary.json"
SUMMARY_SCHEMA = 1


def flight_report(summary: FlightSummary | None, exit_code: int, reason: str, log_dir: str | Path | None,
                  config: Any = None, command: str = "fly", tilt_limit_deg: float | None = None) -> dict[str, Any]:  # fmt: skip
    """The end-of-flight report as one JSON-ready mapping: how the flight ended, the summary, the
    logs, the tilt limit flown (``tilt_limit_deg``: min(limits.max_tilt_deg, the autopilot's)), and
    the path's geodetic origin when the path came from a planning tool."""
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
    if tilt_limit_deg is not None:
        report["tilt_limit_deg"] = tilt_limit_deg
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
