"""Present an :class:`~pf_offboard.identify.fit.Identification`: text report, JSON, ``vehicle:`` YAML.

Pure formatting plus :func:`merge_vehicle_section` (reads a config, returns the merged text).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pf_offboard.errors import InputError
from pf_offboard.identify.fit import AxisFit, Identification, model_fields
from pf_offboard.identify.logdata import LogData


def report_lines(ident: Identification, logs: Sequence[LogData]) -> list[str]:
    """Human-readable report: inputs, per-axis fit with quality, notes."""
    lines = []
    for log in logs:
        hover = f", hover thrust {log.hover_thrust:g} ({log.hover_thrust_source})" if log.hover_thrust is not None else ""
        vc = log.velocity_correction_s
        velocity = f"velocity made position-consistent ({vc:g} s)" if vc is not None else "velocity as reported"
        lines.append(f"{log.source}: {log.kind} setpoints, {len(log.segments)} active stretch(es), {log.duration_s:.1f} s{hover}; {velocity}")
    lines.append(f"fitted on {ident.duration_s:.1f} s of active flight (model: dv/dt = gain * delay(lag(a_sp)) - drag * v + c, world frame)")
    share = ident.z.measured_tilt_share
    if share > 0.0:
        lines.append(f"z input: thrust magnitude through the lag, along the measured tilt (u_z = lag(|a_sp + g|) * cos(tilt) - g) on {100 * share:.0f} % of samples; the rest a_sp,z")
    else:
        lines.append("z input: the vertical setpoint a_sp,z (no attitude telemetry in the log: the tilt's lag may read as vertical lag)")
    lines.append("axis  lag s   delay s  rise63 s  gain    drag 1/s  bias m/s^2          R^2    NRMSE  samples  excitation m/s^2")
    for f in (ident.xy, ident.z):
        lines.append(_axis_line(f))
    if ident.rate is not None:
        r = ident.rate
        lines.append(f"body rates (roll/pitch): lag {r.lag_s:.3f} s, delay {r.delay_s:.3f} s -> time constant {r.time_constant_s:.3f} s (R^2 {r.r2:.3f}, {r.samples} samples)")
    kinds = {log.kind for log in logs}
    if "rates" in kinds:
        lines.append("note: rates-mode log: the acceleration setpoint uses the measured attitude, so the xy lag/delay describe the thrust path only, not the attitude loop")
    lines.extend(f"note: {n}" for n in ident.notes)
    return lines


def _axis_line(f: AxisFit) -> str:
    bias = ", ".join(f"{b:+.3f}" for b in f.bias_m_s2)
    return (
        f"{f.group:<5} {f.lag_s:6.3f}  {f.delay_s:7.3f}  {f.rise_63_s:8.3f}  {f.gain:6.3f}  {f.drag_1_s:8.3f}  "
        f"{bias:<18}  {f.r2:5.3f}  {f.nrmse:5.3f}  {f.samples:7d}  {f.excitation_m_s2:6.2f}"
    )


def vehicle_yaml(ident: Identification, keep: dict[str, Any] | None = None) -> str:
    """The ``vehicle:`` config section (VehicleModel's field names), as YAML text; ``keep``: values
    of an existing section for the fields this fit did not determine (rate_time_constant_s)."""
    fields = {**(keep or {}), **model_fields(ident)}
    # null: the field's default (accel_delay_z_s: the horizontal delay), replacing a kept value
    body = "".join(f"  {k}: {'null' if v is None else format(v, 'g')}\n" for k, v in fields.items())
    return "vehicle:  # identified by pf-offboard identify\n" + body


def as_json(ident: Identification, logs: Sequence[LogData]) -> str:
    """Machine-readable result: inputs, per-group fits, rate loop, the vehicle section, notes."""

    def axis(f: AxisFit) -> dict[str, Any]:
        return {
            "lag_s": f.lag_s, "delay_s": f.delay_s, "rise_63_s": f.rise_63_s, "gain": f.gain,
            "drag_1_s": f.drag_1_s, "bias_m_s2": list(f.bias_m_s2), "r2": f.r2, "nrmse": f.nrmse,
            "samples": f.samples, "excitation_m_s2": f.excitation_m_s2, "measured_tilt_share": f.measured_tilt_share,
        }  # fmt: skip

    out = {
        "logs": [
            {"path": log.source, "setpoints": log.kind, "active_s": log.duration_s, "segments": len(log.segments),
             "hover_thrust": log.hover_thrust, "hover_thrust_source": log.hover_thrust_source,
             "velocity_correction_s": log.velocity_correction_s}
            for log in logs
        ],  # fmt: skip
        "duration_s": ident.duration_s,
        "xy": axis(ident.xy),
        "z": axis(ident.z),
        "rate": None if ident.rate is None else {"lag_s": ident.rate.lag_s, "delay_s": ident.rate.delay_s,
                                                 "time_constant_s": ident.rate.time_constant_s, "r2": ident.rate.r2},  # fmt: skip
        "vehicle": model_fields(ident),
        "notes": list(ident.notes),
    }
    return json.dumps(out, indent=2)


def merge_vehicle_section(config_text: str, ident: Identification, source: str) -> str:
    """``config_text`` with its ``vehicle:`` section replaced (or added) by the identified one.

    Text-level so the rest of the file (comments, order) is kept: the old section is the
    top-level ``vehicle:`` line and its indented / blank / comment lines that follow.
    """
    import yaml

    try:
        data = yaml.safe_load(config_text)
    except yaml.YAMLError as exc:
        raise InputError(source, f"not valid YAML: {exc}") from None
    if data is not None and not isinstance(data, dict):
        raise InputError(source, "not a config (a mapping of sections)")
    old = data.get("vehicle") if isinstance(data, dict) else None
    keep = {k: v for k, v in old.items() if k == "rate_time_constant_s"} if isinstance(old, dict) else {}
    lines = config_text.splitlines(keepends=True)
    out: list[str] = []
    skipping = False
    for line in lines:
        if line.startswith("vehicle:"):
            skipping = True
            continue
        if skipping:
            if line.strip() == "" or line.startswith((" ", "\t", "#")):
                continue
            skipping = False
        out.append(line)
    text = "".join(out)
    if text and not text.endswith("\n"):
        text += "\n"
    return text + vehicle_yaml(ident, keep)


def write_config(path: Path, ident: Identification, base: Path | None) -> None:
    """Write ``path``: ``base`` (default: ``path`` itself if it exists) with the new ``vehicle:``.

    The result must load as a config when the base was one (checked before writing).
    """
    src = base if base is not None else (path if path.exists() else None)
    text = ""
    if src is not None:
        try:
            text = src.read_text(encoding="utf-8")
        except OSError as exc:
            raise InputError(str(src), f"cannot read: {exc.strerror or exc}") from None
    merged = merge_vehicle_section(text, ident, str(src or path))
    import yaml

    data = yaml.safe_load(merged)
    if isinstance(data, dict) and "path" in data:
        from pf_offboard.config import parse_config

        parse_config(data, source=str(path))  # a full config must still be valid
    try:
        path.write_text(merged, encoding="utf-8")
    except OSError as exc:
        raise InputError("--write-config", f"cannot write {path}: {exc.strerror or exc}") from None
