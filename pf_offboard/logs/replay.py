"""``pf-offboard replay``: re-run the controller on a recorded flight and compare setpoints.

The recorded telemetry (inbound frames of the ``.tlog``) is fed, in logged order, through a fresh
:class:`pf_offboard.app.pipeline.Pipeline` built from ``--config``. Where the flight logged a
controller step (a row of the step-log CSV beside the ``.tlog``), the pipeline is stepped and its
setpoint — packed to MAVLink and decoded again, so float32 exactly as on the wire — is compared
field by field with the setpoint frame that flew; the step record (float64, from the CSV) is
compared too. The largest differences are printed with the field and vehicle time; exit 1 when
any exceeds the tolerance (default 1e-9), 0 otherwise, 2 for unreadable input.

Float32 allowance: a setpoint field is a float32 rounding of a float64 result, so a 1e-16 change
in the float64 value (another libm, another numpy) can move it by one float32 step (~1e-7 near
1). One such step is allowed on setpoint float fields; beyond it the tolerance applies. The step
log is compared in float64 with no allowance, so the 1e-9 check of the controller stays exact.

How steps are found: the bridge sends each step's setpoint immediately after the state sample
that triggered it, stamped with that sample's ``time_boot_ms``; rows of the step log carry the
same time (``time_s``). Other setpoints in the ``.tlog`` (take-off position, hold, keep-alive
repeats) are skipped. Inbound messages from systems other than the vehicle's are ignored, as
the link does in flight.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pf_offboard.errors import InputError
from pf_offboard.logs.flightlog import FlightLogPaths
from pf_offboard.logs.steplog import StepRecord, read_steplog
from pf_offboard.logs.measures import path_tangent
from pf_offboard.logs.summary import FlightSummary, summarize
from pf_offboard.logs.tlog import TlogEntry, read_tlog

SETPOINT_TYPES = frozenset({"SET_POSITION_TARGET_LOCAL_NED", "SET_ATTITUDE_TARGET"})
# Step-log fields decided by the bridge, not the controller: passed through, not compared.
_BRIDGE_FIELDS = frozenset({"mode", "active", "event"})
_MAV_AUTOPILOT_INVALID = 8
DEFAULT_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Difference:
    """One compared value: where (field, vehicle time) and by how much."""

    field: str
    time_s: float
    recorded: float
    recomputed: float
    allowance: float = 0.0  # float32 fields: one rounding step of the encoding is not a difference

    @property
    def excess(self) -> float:
        """How far beyond the encoding allowance the difference goes (what the tolerance bounds)."""
        return max(0.0, self.abs_diff - self.allowance)

    @property
    def abs_diff(self) -> float:
        if math.isnan(self.recorded) and math.isnan(self.recomputed):
            return 0.0
        if math.isnan(self.recorded) or math.isnan(self.recomputed):
            return math.inf
        if self.recorded == self.recomputed:  # equal infinities
            return 0.0
        return abs(self.recorded - self.recomputed)

    def describe(self) -> str:
        return (
            f"{self.field} at t={self.time_s:.3f} s: recorded {self.recorded!r}, recomputed {self.recomputed!r} "
            f"(|diff| {self.abs_diff:.3g})"
        )


@dataclass(frozen=True)
class ReplayReport:
    """What a replay found. ``problems`` are structural (a step without a setpoint, wrong type ...)."""

    tolerance: float
    steps: int
    setpoint_max: Difference | None  # largest setpoint-field difference
    record_max: Difference | None  # largest step-record difference
    problems: tuple[str, ...]
    summary: FlightSummary
    profile: str
    output_mode: str

    @property
    def ok(self) -> bool:
        worst = max((d.excess for d in (self.setpoint_max, self.record_max) if d is not None), default=0.0)
        return not self.problems and worst <= self.tolerance and self.steps > 0

    def lines(self) -> list[str]:
        out = [f"replayed {self.steps} controller steps ({self.profile}, {self.output_mode} setpoints), tolerance {self.tolerance:g}"]
        for label, d in (("setpoint", self.setpoint_max), ("step log", self.record_max)):
            if d is None:
                text = "nothing compared"
            elif d.abs_diff == 0.0:
                text = "0 (every compared value identical)"
            elif d.excess == 0.0:
                text = d.describe() + ", within one float32 rounding step"
            else:
                text = d.describe()
            out.append(f"largest {label} difference: {text}")
        out.extend(f"problem: {p}" for p in self.problems[:10])
        if len(self.problems) > 10:
            out.append(f"... and {len(self.problems) - 10} more problems")
        out.append("MATCH: the controller reproduces the flight" if self.ok else "DIFFERENT: recomputed setpoints differ from the flight")
        return out


def _worse(a: Difference | None, b: Difference) -> Difference:
    if a is None:
        return b
    return b if (b.excess, b.abs_diff) > (a.excess, a.abs_diff) else a


def _f32_step(value: float) -> float:
    """Spacing of float32 numbers at ``value``: what re-rounding a float64 result may change."""
    if not math.isfinite(value):
        return 0.0
    return float(np.spacing(np.float32(abs(value))))


def _scalar_items(prefix: str, value: Any) -> list[tuple[str, float, bool]]:
    """(name, value, is_float) for a scalar or each element of an array field."""
    if isinstance(value, (list, tuple)):
        return [(f"{prefix}[{i}]", float(v), isinstance(v, float)) for i, v in enumerate(value)]
    if isinstance(value, (bytes, str)):
        return []
    return [(prefix, float(value), isinstance(value, float))]


def compare_messages(recorded: Any, recomputed: Any, time_s: float) -> tuple[Difference | None, str | None]:
    """Largest field difference between two decoded messages (or a problem when types differ)."""
    if recorded.get_type() != recomputed.get_type():
        return None, f"t={time_s:.3f} s: flew {recorded.get_type()}, recomputed {recomputed.get_type()}"
    worst: Difference | None = None
    for name in recorded.get_fieldnames():
        a = _scalar_items(name, getattr(recorded, name))
        b = _scalar_items(name, getattr(recomputed, name))
        for (field, va, is_float), (_, vb, _) in zip(a, b):
            allowance = _f32_step(va) if is_float else 0.0
            worst = _worse(worst, Difference(f"{recorded.get_type()}.{field}", time_s, va, vb, allowance))
    return worst, None


def compare_records(recorded: StepRecord, recomputed: StepRecord) -> Difference | None:
    """Largest difference over the controller's fields of two step records (float64)."""
    worst: Difference | None = None
    for f in dataclasses.fields(StepRecord):
        if f.name in _BRIDGE_FIELDS:
            continue
        for (field, va, _), (_, vb, _) in zip(
            _scalar_items(f.name, getattr(recorded, f.name)), _scalar_items(f.name, getattr(recomputed, f.name))
        ):
            worst = _worse(worst, Difference(field, recorded.time_s, va, vb))
    return worst


def _ms(time_s: float) -> int:
    return int(round(time_s * 1000.0)) & 0xFFFFFFFF


@dataclass(frozen=True)
class ReplayOptions:
    """How to rebuild the flight's pipeline; None = from the log / config like ``fly`` does."""

    autopilot: str | None = None  # px4 | ardupilot; default from the recorded HEARTBEAT
    output_mode: str | None = None  # default: config flight.output_mode
    state_source: str | None = None  # local_position | odometry; default: what the flight asked for
    hover_thrust: float | None = None  # default: config, else the PARAM_VALUE in the log
    # acceleration setpoints encoded for an autopilot tilting from g alone (Profile.accel_tilt_from_gravity);
    # default: the logged PARAM_VALUE, else the profile's default
    tilt_from_gravity: bool | None = None
    tolerance: float = DEFAULT_TOLERANCE


def _first_step_setpoint(entries: Sequence[TlogEntry], records: Sequence[StepRecord]) -> Any:
    times = {_ms(r.time_s) for r in records}
    for e in entries:
        if e.direction == "out" and e.message.get_type() in SETPOINT_TYPES and e.message.time_boot_ms in times:
            return e.message
    return None


def _output_mode_of(msg: Any) -> str:
    if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
        return "acceleration"
    return "rates" if int(msg.type_mask) & 128 else "attitude"


_MSG_ID_LOCAL_POSITION_NED = 32
_MSG_ID_ODOMETRY = 331
_CMD_SET_MESSAGE_INTERVAL = 511


def _state_source_of(entries: Sequence[TlogEntry]) -> str:
    """The state telemetry the flight asked for (SET_MESSAGE_INTERVAL), local position if unsure."""
    for e in entries:
        m = e.message
        if e.direction == "out" and m.get_type() == "COMMAND_LONG" and m.command == _CMD_SET_MESSAGE_INTERVAL and m.param2 > 0:
            if int(m.param1) == _MSG_ID_ODOMETRY:
                return "odometry"
            if int(m.param1) == _MSG_ID_LOCAL_POSITION_NED:
                return "local_position"
    return "local_position"


def _param_from_log(entries: Sequence[TlogEntry], param: str, profile: Any) -> float | None:
    """The last value the vehicle reported for ``param`` (PARAM_VALUE), or None."""
    from pf_offboard.app.params import param_value_decode

    value = None
    for e in entries:
        if e.direction == "in" and e.message.get_type() == "PARAM_VALUE":
            pid = e.message.param_id
            pid = pid.decode(errors="replace") if isinstance(pid, bytes) else pid
            if pid.rstrip("\x00") == param:
                value = float(param_value_decode(e.message.param_value, e.message.param_type, profile.params_bytewise))
    return value


def _tilt_from_gravity(entries: Sequence[TlogEntry], profile: Any, options: ReplayOptions) -> bool:
    """How the flight's acceleration setpoints were encoded: ``--tilt-from-gravity`` if given, else
    the autopilot's reported ``accel_tilt_param`` as fly read it, else the profile's default (as fly
    assumes without an answer)."""
    if options.tilt_from_gravity is not None:
        return options.tilt_from_gravity
    name = profile.accel_tilt_param
    return profile.tilts_from_gravity(None if name is None else _param_from_log(entries, name, profile))


def _thrust_angle_boost(entries: Sequence[TlogEntry], profile: Any, output_mode: str) -> bool:
    """Whether fly encoded the thrust for an autopilot boosting it by 1 / cos(tilt): its reported
    ``thrust_angle_boost_param`` (attitude / rates). A log without it: no (logs from before fly
    read it; fly itself assumes the autopilot's default 1 only when the parameter goes unanswered)."""
    name = profile.thrust_angle_boost_param
    if name is None or output_mode == "acceleration":
        return False
    value = _param_from_log(entries, name, profile)
    return False if value is None else value != 0.0


def _tilt_limit_from_log(entries: Sequence[TlogEntry], profile: Any, output_mode: str) -> float | None:
    """The autopilot's acceleration tilt limit as fly read it (the logged PARAM_VALUEs of
    ``accel_tilt_limit_params``), or None (another output mode, or a log without them)."""
    if output_mode != "acceleration" or not profile.accel_tilt_limit_params:
        return None
    reported = {}
    for name, _ in profile.accel_tilt_limit_params:
        value = _param_from_log(entries, name, profile)
        if value is not None:
            reported[name] = value
    try:
        return profile.accel_tilt_limit_deg(reported)
    except ValueError as exc:
        raise InputError("LOG", f"logged {exc}") from None


def build_pipeline(
    config: Any,
    entries: Sequence[TlogEntry],
    records: Sequence[StepRecord],
    options: ReplayOptions,
    follower: Any | None = None,
) -> tuple[Any, Any, str, int]:
    """A fresh pipeline configured like the flight's: (pipeline, profile, output_mode, target sysid)."""
    from pf_offboard.app.encoders import Encoder
    from pf_offboard.app.estimator import Estimator
    from pf_offboard.app.settings import flight_settings_for
    from pf_offboard.app.pipeline import Pipeline
    from pf_offboard.app.profiles import select_profile
    from pf_offboard.control import controller_from_config

    first = _first_step_setpoint(entries, records)
    if first is None:
        raise InputError("LOG", "no controller setpoint in the .tlog matches the step log (nothing to replay)")
    target_system, target_component = int(first.target_system), int(first.target_component)
    heartbeat_autopilot = _MAV_AUTOPILOT_INVALID
    for e in entries:
        m = e.message
        if e.direction == "in" and m.get_type() == "HEARTBEAT" and m.get_srcSystem() == target_system and m.autopilot != _MAV_AUTOPILOT_INVALID:
            heartbeat_autopilot = int(m.autopilot)
            break
    profile = select_profile(options.autopilot, heartbeat_autopilot)
    settings = flight_settings_for(config, output=options.output_mode)
    output_mode = options.output_mode or settings.output_mode
    flown_mode = _output_mode_of(first)
    if options.output_mode is None and flown_mode != output_mode:
        output_mode = flown_mode  # the flight overrode the config with --output
    hover = options.hover_thrust if options.hover_thrust is not None else settings.hover_thrust
    if hover is None:
        hover = _param_from_log(entries, profile.hover_thrust_param, profile)
    if hover is None and output_mode != "acceleration":
        raise InputError("--hover-thrust", f"the log has no {profile.hover_thrust_param} value and the config none; pass --hover-thrust")
    if hover is not None and not (math.isfinite(hover) and 0.0 < hover < 1.0):
        raise InputError("LOG", f"logged {profile.hover_thrust_param} = {hover!r} is not a normalised hover thrust in (0, 1)")
    encoder = Encoder(
        output_mode, profile, target_system, target_component,
        hover_thrust=float(hover) if hover is not None else 0.5,
        time_constant_s=settings.attitude_time_constant_s,
        max_body_rate_rad_s=config.safety.max_body_rate_rad_s if config.safety.enabled else None,  # as fly bounds them
        tilt_from_gravity=_tilt_from_gravity(entries, profile, options),
        thrust_angle_boost=_thrust_angle_boost(entries, profile, output_mode),
    )  # fmt: skip
    if follower is None:
        follower = controller_from_config(config)
    tilt = _tilt_limit_from_log(entries, profile, output_mode)
    if tilt is not None and hasattr(follower, "cap_tilt"):
        follower.cap_tilt(tilt)  # as fly: min(limits.max_tilt_deg, the autopilot's)
    source = options.state_source or _state_source_of(entries)
    return Pipeline(follower, encoder, Estimator(source, settings.velocity_correction_for(profile))), profile, output_mode, target_system


def replay_flight(
    tlog_path: str | Path,
    config: Any,
    steps_csv: str | Path | None = None,
    options: ReplayOptions = ReplayOptions(),
    follower: Any | None = None,
) -> ReplayReport:
    """Replay one flight (see the module docstring). ``config`` is a loaded Config."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    entries = read_tlog(tlog_path)
    csv_path = Path(steps_csv) if steps_csv is not None else FlightLogPaths.beside(tlog_path).steps_csv
    if not csv_path.exists():
        raise InputError("--steps", f"no step log {csv_path} (replay needs it to know which setpoints came from controller steps)")
    records = read_steplog(csv_path)
    if not records:
        raise InputError(str(csv_path), "step log has no rows: the flight never stepped the controller")
    pipeline, profile, output_mode, target_system = build_pipeline(config, entries, records, options, follower)
    codec = mavlink.MAVLink(None, srcSystem=target_system, srcComponent=191)
    parser = mavlink.MAVLink(None)

    setpoint_max: Difference | None = None
    record_max: Difference | None = None
    problems: list[str] = []
    j = 0  # next step record to match
    steps = 0
    for e in entries:
        msg = e.message
        if e.direction == "in":
            if msg.get_srcSystem() == target_system:
                pipeline.on_message(msg)
            continue
        if msg.get_type() not in SETPOINT_TYPES or j >= len(records) or msg.time_boot_ms != _ms(records[j].time_s):
            continue  # not a controller step: take-off, hold, keep-alive repeat, command ...
        rec = records[j]
        j += 1
        step = pipeline.step(rec.mode, rec.active, "")
        if step is None:
            problems.append(f"t={rec.time_s:.3f} s: no fresh state sample before the recorded step (telemetry missing from the log?)")
            continue
        steps += 1
        recomputed = parser.decode(bytearray(step.setpoint.pack(codec)))
        worst, problem = compare_messages(msg, recomputed, rec.time_s)
        if problem:
            problems.append(problem)
        if worst is not None:
            setpoint_max = _worse(setpoint_max, worst)
        d = compare_records(rec, step.record)
        if d is not None:
            record_max = _worse(record_max, d)
    if j < len(records):
        problems.append(
            f"{len(records) - j} of {len(records)} step-log rows (from t={records[j].time_s:.3f} s) have no matching setpoint in the .tlog"
        )
    return ReplayReport(
        tolerance=options.tolerance,
        steps=steps,
        setpoint_max=setpoint_max,
        record_max=record_max,
        problems=tuple(problems),
        summary=summarize(records, path_tangent(pipeline.follower.path), follower=pipeline.follower),
        profile=profile.name,
        output_mode=output_mode,
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", metavar="LOG.tlog", help="telemetry log of the flight (its .csv step log beside it)")
    parser.add_argument("--config", help="config YAML the flight used (default: the .yaml beside the log)")
    parser.add_argument("--steps", metavar="CSV", help="step log (default: LOG.csv)")
    parser.add_argument("--tolerance", type=float, default=DEFAULT_TOLERANCE, help="largest allowed difference (default 1e-9)")
    parser.add_argument("--autopilot", choices=("px4", "ardupilot"), help="default: from the logged HEARTBEAT")
    parser.add_argument("--output", choices=("acceleration", "attitude", "rates"), help="default: as flown")
    parser.add_argument("--state-source", choices=("local_position", "odometry"),
                        help="state telemetry the flight followed (default: the stream it requested)")  # fmt: skip
    parser.add_argument("--hover-thrust", type=float, help="normalised hover thrust (default: config, else logged parameter)")
    parser.add_argument("--tilt-from-gravity", choices=("yes", "no"),
                        help="acceleration output: were setpoints encoded for an autopilot that tilts from g alone (PX4 MPC_ACC_DECOUPLE 1)? "
                             "default: the logged parameter, else the autopilot's default (yes); 'no' for flights of pf-offboard before 2026-11-24")  # fmt: skip
    parser.add_argument("--json", action="store_true", help="print the report and flight summary as JSON")
    parser.add_argument("--truth", metavar="FLIGHT.ulg",
                        help="PX4 SIH's ULog of the same flight: the flight against the simulator's ground truth "
                             "(vehicle_local_position_groundtruth), the frames' constant offset apart from the estimate's error")  # fmt: skip


def run(args: argparse.Namespace) -> int:
    from pf_offboard.config import load_config

    if not (math.isfinite(args.tolerance) and args.tolerance >= 0.0):
        raise InputError("--tolerance", f"must be a finite number >= 0, got {args.tolerance}")
    if args.hover_thrust is not None and not (math.isfinite(args.hover_thrust) and 0.05 <= args.hover_thrust <= 0.95):
        raise InputError("--hover-thrust", f"must be in [0.05, 0.95] (normalised), got {args.hover_thrust}")
    if Path(args.log).is_dir():
        raise InputError("LOG", f"{args.log} is a directory; give its .tlog (e.g. {Path(args.log) / 'flight.tlog'})")
    if not Path(args.log).exists():
        raise InputError(str(args.log), "no such file")
    if Path(args.log).suffix.lower() == ".ulg":
        raise InputError(str(args.log), "is a PX4 ULog: replay re-runs the controller on the telemetry pf-offboard received, "
                         "which only its own .tlog holds; plot and identify read ULogs")  # fmt: skip
    if args.config:
        from pf_offboard.shipped import resolve_config

        args.config = str(resolve_config(args.config))
    config_path = Path(args.config) if args.config else FlightLogPaths.beside(args.log).config_yaml
    if not config_path.exists():
        raise InputError("--config", f"no such file: {config_path}" + ("" if args.config else " (pass --config)"))
    config = load_config(config_path).require_local("or replay with the flight.yaml beside the log: it holds the local way-points flown")
    options = ReplayOptions(
        autopilot=args.autopilot,
        output_mode=args.output,
        state_source=args.state_source,
        hover_thrust=args.hover_thrust,
        tilt_from_gravity=None if args.tilt_from_gravity is None else args.tilt_from_gravity == "yes",
        tolerance=args.tolerance,
    )
    truth_report = None
    if args.truth:
        from pf_offboard.logs.truth import read_ulog_truth

        truth_t, truth_ned = read_ulog_truth(args.truth)  # an unreadable ULog is bad input, before the replay
    report = replay_flight(args.log, config, args.steps, options)
    if args.truth:
        from pf_offboard.logs.steplog import read_steplog
        from pf_offboard.logs.truth import judge_truth

        steps_csv = Path(args.steps) if args.steps else FlightLogPaths.beside(args.log).steps_csv
        truth_report = judge_truth(read_steplog(steps_csv), truth_t, truth_ned, config.path.spline())
    if args.json:
        from pf_offboard.logs.summary import flight_report, report_json

        doc = flight_report(report.summary, 0 if report.ok else 1, "replay " + ("matches" if report.ok else "differs"),
                            Path(args.log).parent, config, "replay")  # fmt: skip
        doc["replay_lines"] = report.lines()
        if truth_report is not None:
            doc["ground_truth"] = truth_report.to_dict()
        print(report_json(doc))
        return 0 if report.ok else 1
    for line in report.lines():
        print(line)
    print("flight summary:")
    for line in report.summary.lines():
        print("  " + line)
    if truth_report is not None:
        for line in truth_report.lines():
            print(line)
    return 0 if report.ok else 1
