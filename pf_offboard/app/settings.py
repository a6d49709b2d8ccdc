"""The app's typed settings, built once from a config (and the user's choices) at the edge:
``flight:`` with overrides (:class:`FlightSettings`), the safety fence of a path, where logs go."""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pf_offboard.app.hover import HOVER_THRUST_RANGE, plausible_hover_thrust
from pf_offboard.config import VELOCITY_CORRECTION_AUTO
from pf_offboard.errors import InputError


@dataclass(frozen=True)
class FlightSettings:
    """The ``flight:`` section of a config with the command-line overrides applied."""

    output_mode: str
    setpoint_rate_hz: float
    state_timeout_s: float
    hover_thrust: float | None
    end_action: str
    attitude_time_constant_s: float
    velocity_correction_s: float | str | None  # pf_offboard.app.estimator; None: off; "auto": the autopilot's

    def velocity_correction_for(self, profile: Any) -> float | None:
        """The velocity correction's time constant (s; None: off) flown with this autopilot
        (``profile``, pf_offboard.app.profiles): the configured one, or the autopilot's when
        the config leaves it ``auto``."""
        if self.velocity_correction_s == VELOCITY_CORRECTION_AUTO:
            return profile.velocity_correction_s  # type: ignore[no-any-return]
        return self.velocity_correction_s  # type: ignore[return-value]


def flight_settings_for(config: Any, output: str | None = None, end_action: str | None = None) -> FlightSettings:
    """``config.flight`` with an output mode / end action given by the user (None: the config's)."""
    flight = getattr(config, "flight", None)

    def get(name: str, default: Any) -> Any:
        value = getattr(flight, name, None) if flight is not None else None
        return default if value is None else value

    s = FlightSettings(
        output_mode=output or get("output_mode", "acceleration"),
        setpoint_rate_hz=float(get("setpoint_rate_hz", 50.0)),
        state_timeout_s=float(get("state_timeout_s", 0.5)),
        hover_thrust=get("hover_thrust", None),
        end_action=end_action or get("end_action", "hold"),
        attitude_time_constant_s=_attitude_time_constant(config, get("attitude_time_constant_s", None)),
        velocity_correction_s=get("velocity_correction_s", None),
    )
    if s.output_mode not in ("acceleration", "attitude", "rates"):
        raise InputError("flight.output_mode", f"must be acceleration, attitude or rates, got {s.output_mode!r}")
    if not (math.isfinite(s.setpoint_rate_hz) and 2.0 < s.setpoint_rate_hz <= 1000.0):
        raise InputError("flight.setpoint_rate_hz", f"must be in (2, 1000] Hz (PX4 needs > 2 Hz), got {s.setpoint_rate_hz}")
    if not (math.isfinite(s.state_timeout_s) and 0.0 < s.state_timeout_s <= 5.0):
        raise InputError("flight.state_timeout_s", f"must be in (0, 5] s, got {s.state_timeout_s}")
    if s.hover_thrust is not None and not plausible_hover_thrust(float(s.hover_thrust)):
        lo, hi = HOVER_THRUST_RANGE
        raise InputError("flight.hover_thrust", f"must be in [{lo:g}, {hi:g}] (normalised) or omitted, got {s.hover_thrust}")
    if s.end_action not in ("hold", "land"):
        raise InputError("flight.end_action", f"must be hold or land, got {s.end_action!r}")
    if not (math.isfinite(s.attitude_time_constant_s) and 0.01 <= s.attitude_time_constant_s <= 2.0):
        raise InputError("flight.attitude_time_constant_s", f"must be in [0.01, 2] s, got {s.attitude_time_constant_s}")
    return s


def _attitude_time_constant(config: Any, configured: Any) -> float:
    """Rates mode's τ (s): ``flight.attitude_time_constant_s`` if set, else derived from the
    identified rate loop (``vehicle.rate_time_constant_s``: 4x it), else the default 0.25 s."""
    from pf_offboard.control.attitude import AttitudeRateLaw

    if configured is not None:
        return float(configured)
    rate_tc = getattr(getattr(config, "vehicle", None), "rate_time_constant_s", 0.0) or 0.0
    return AttitudeRateLaw.for_rate_loop(float(rate_tc)).time_constant_s


def envelope_fence(config: Any) -> Any:
    """The safety fence for this config's path (pf_offboard.safety); InputError (exit 2) if the
    path itself leaves it or dips below the floor: such a flight is refused before any traffic."""
    from pf_offboard.safety import SafetyConfig, check_path, fence_for_path

    safety = getattr(config, "safety", None) or SafetyConfig()
    p = config.path
    path = p.spline()
    n = max(2, math.ceil(path.lam_max / 0.05) + 1)  # every 5 cm or finer
    points = [path.eval_floats(path.lam_max * i / (n - 1))[:3] for i in range(n)]
    fence = fence_for_path(safety, points)
    if safety.enabled:
        why = check_path(fence, points)
        if why:
            raise InputError("safety", why)
    return fence


def rate_bound(config: Any) -> float | None:
    """safety.max_body_rate_rad_s when the envelope is on (the encoder bounds rates-mode setpoints)."""
    safety = getattr(config, "safety", None)
    return safety.max_body_rate_rad_s if safety is not None and safety.enabled else None


def default_log_dir(prefix: str = "") -> Path:
    """``flights/<prefix><UTC time>``, created here and never shared: a run started in the same
    second as another (or a directory left from one) gets ``-2``, ``-3`` ... (the directory is made
    with an exclusive mkdir, so two concurrent runs can never write the same one)."""
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    base = Path("flights")
    base.mkdir(parents=True, exist_ok=True)
    for n in range(1, 10_000):
        candidate = base / (f"{prefix}{stamp}" + (f"-{n}" if n > 1 else ""))
        try:
            candidate.mkdir()
        except FileExistsError:
            continue
        return candidate
    raise OSError(f"no free log directory name under {base} for {prefix}{stamp}")
