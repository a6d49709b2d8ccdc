"""YAML configuration: path, speed, gains, yaw, limits, flight. Loaded into frozen dataclasses.

Every problem raises one :class:`~pf_offboard.errors.ConfigError` naming the dotted field
(``path.waypoints[3]``, ``gains.transversal.bandwidth_hz``) and the reason. Unknown keys are errors
(a typo must not silently fly with a default). Only ``path`` is required; every other field has a
safe default (docs/controller.md lists them). Way-points and yaw given in ``ned`` are converted
to the core's ENU frame with :mod:`pf_offboard.frames`.
"""

from __future__ import annotations

import math
import os
import reprlib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

from pf_offboard.control.profile import SpeedProfileSpec
from pf_offboard.control.types import (
    ANY_STATE_NEEDS_NO_COMPENSATION,
    DEFAULT_SPEED_M_S,
    FEEDFORWARD_MODES,
    GRAVITY_M_S2,
    MIN_THRUST_FLOOR_M_S2,
    Compensation,
    Gains,
    Limits,
    YAW_MODES,
    VehicleModel,
    YawSpec,
)
from pf_offboard.errors import ConfigError, InputError
from pf_offboard.frames import ned_to_enu, yaw_ned_to_enu, yaw_rate_ned_to_enu
from pf_offboard.safety.envelope import ACTIONS as SAFETY_ACTIONS
from pf_offboard.safety.envelope import SHAPES as FENCE_SHAPES
from pf_offboard.safety.envelope import SafetyConfig
from pf_offboard.geo import GeoPoint

MAX_SPEED_M_S = 20.0
OUTPUT_MODES = ("acceleration", "attitude", "rates")
END_ACTIONS = ("hold", "land")
FRAMES = ("enu", "ned")
MOVING_FRAMES = ("auto", "frenet", "rmf")
# path_following: the paper's time-invariant controller (PathFollower); trajectory_tracking: the
# baseline that tracks the same spline timed at constant speed (TrajectoryTracker)
CONTROLLERS = ("path_following", "trajectory_tracking")


@dataclass(frozen=True)
class GeodeticSource:
    """A path given in latitude / longitude / altitude (``path.file``), before or after its
    conversion to the local frame.

    ``file``: the way-point file as resolved (relative to the config's directory);
    ``waypoints_lat_lon_alt``: (lat_deg, lon_deg, alt_m) as in the file, ``altitude_reference``
    (``relative_home`` | ``amsl``) saying what alt_m is measured from; ``names``: item / line of
    each way-point in the file; ``origin``: the local frame's origin (WGS-84, AMSL) when known
    (``path.origin`` in the config, or read from the vehicle at connect time); ``skipped``: file
    items that are not way-points (take-off, speed changes, ...).
    """

    file: str
    file_format: str
    altitude_reference: str
    waypoints_lat_lon_alt: tuple[tuple[float, float, float], ...]
    names: tuple[str, ...]
    origin: GeoPoint | None = None
    home_alt_amsl_m: float | None = None  # relative_home: home's altitude (default: the origin's)
    skipped: tuple[str, ...] = ()
    takeoff_alt_m: float | None = None  # the file's take-off altitude above home (a plan's take-off item)


@dataclass(frozen=True)
class PathConfig:
    """``frame``: frame the way-points were written in; ``waypoints_enu_m`` are always ENU (m).

    A path from a planning tool (``geodetic`` set) has no local way-points until its origin is
    known: ``waypoints_enu_m`` is then empty and :func:`with_origin` fills it in."""

    waypoints_enu_m: tuple[tuple[float, float, float], ...]
    closed: bool = False
    frame: str = "enu"
    moving_frame: str = "auto"
    geodetic: GeodeticSource | None = None

    def spline(self) -> Any:
        """The :class:`pf_offboard.path.Path` through these way-points (world ENU)."""
        from pf_offboard.path import Path

        return Path.from_waypoints(self.waypoints_enu_m, closed=self.closed, frame=self.moving_frame)


@dataclass(frozen=True)
class FlightConfig:
    """How the app flies (consumed by pf_offboard.app; see docs there)."""

    output_mode: str = "acceleration"  # acceleration | attitude | rates
    setpoint_rate_hz: float = 50.0  # >= 20 (PX4 offboard needs > 2 Hz; control needs more)
    state_timeout_s: float = 0.5  # no fresh state for this long: stop path following (failsafe)
    hover_thrust: float | None = None  # normalised hover thrust 0.05..0.95; None: from the autopilot
    takeoff_altitude_m: float = 2.0
    throw_activation_height_m: float | None = None  # None: no throw activation
    end_action: str = "hold"  # at the end of an open path: hold | land
    # rates mode: attitude error feedback time constant (s); None: derived from
    # vehicle.rate_time_constant_s (4x it), or 0.25 s when that is unknown (see control/attitude.py)
    attitude_time_constant_s: float | None = None
    # time constant (s) of the correction that makes the velocity estimate agree with the position
    # estimate's derivative (pf_offboard.app.estimator); None (null): the velocity as reported;
    # "auto": the autopilot's (pf_offboard.app.profiles.Profile.velocity_correction_s: PX4 0.1 s,
    # ArduPilot 0.3 s). 0.1 s on PX4: the law then damps with the velocity of the position it
    # steers up to ~1.6 Hz; on the real PX4 SIH, default config, 1.5 m/s, it cut the speed error's
    # part that is the velocity's disagreement with the position's derivative from ~4 to ~2.4 cm/s
    # RMS and the cross-track by ~1 cm against 0.3 s (docs/design-decisions.md, The estimate);
    # 0.3 s: 3.5-4.2 cm with the earlier gains (0.5 s: 3.9-5.3; 1 s: 5.0-7.5; off: 10.9-17.7)
    velocity_correction_s: float | str | None = "auto"  # auto: the autopilot's (PX4 0.1, ArduPilot 0.3); null: the velocity as reported


# flight.velocity_correction_s's range (s); `identify --velocity-correction` takes the same
VELOCITY_CORRECTION_RANGE_S = (0.05, 60.0)
VELOCITY_CORRECTION_AUTO = "auto"  # flight.velocity_correction_s: the autopilot's


# The ``compensation:`` section is the core's Compensation: one set of defaults for the config
# and for PathFollower(path, speed).
CompensationConfig = Compensation


@dataclass(frozen=True)
class Config:
    path: PathConfig
    speed_m_s: float = DEFAULT_SPEED_M_S
    gains: Gains = field(default_factory=Gains)
    yaw: YawSpec = field(default_factory=YawSpec)
    limits: Limits = field(default_factory=Limits)
    flight: FlightConfig = field(default_factory=FlightConfig)
    vehicle: VehicleModel = field(default_factory=VehicleModel.typical)
    compensation: Compensation = field(default_factory=Compensation)
    gains_auto: bool = False  # gains derived from the vehicle model (gains: auto or no gains section)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    source: str = "<config>"
    controller: str = "path_following"  # one of CONTROLLERS (pf_offboard.control.select)
    speed_profile: SpeedProfileSpec | None = None  # None: the constant speed_m_s (the paper)
    feedforward: str = "on_path"  # body-rate feed-forward: on_path (the paper) | any_state

    @property
    def needs_origin(self) -> bool:
        """The path is in latitude / longitude and its local frame's origin is not known yet."""
        return self.path.geodetic is not None and not self.path.waypoints_enu_m

    def require_local(self, hint: str = "") -> Config:
        """This config, if its path is in the local frame; else a ConfigError naming path.origin."""
        if self.needs_origin:
            raise ConfigError("path.origin", "the path is in latitude/longitude (path.file) and no origin is known: add "
                              "path.origin: [lat_deg, lon_deg, alt_amsl_m]" + (f" ({hint})" if hint else ""))  # fmt: skip
        return self


# ---------------------------------------------------------------------------------- helpers
# A config file is text of a few kB; anything far larger is not one (and would be slow to parse).
MAX_CONFIG_BYTES = 1 << 20
# Positive quantities have a smallest meaningful value: "> 0" alone lets 1e-320 through, which
# passes the check and divides by zero later.
MIN_BANDWIDTH_HZ = 0.01
MIN_DAMPING = 0.01
MIN_SPEED_M_S = 0.01
MIN_TILT_DEG = 1.0
MIN_STATE_TIMEOUT_S = 0.01

_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxdict, _REPR.maxstring, _REPR.maxother, _REPR.maxlong = 3, 6, 6, 60, 60, 40


def _show(value: Any) -> str:
    """A short, one-line, depth-limited repr of a value from the file, for error messages."""
    try:
        return _REPR.repr(value)
    except Exception:  # noqa: BLE001 - an exotic object's repr must not turn an error into a traceback
        return f"<{type(value).__name__}>"


def _to_float(v: int | float, name: str) -> float:
    try:
        return float(v)
    except OverflowError:  # an integer written with hundreds of digits (1e400)
        raise ConfigError(name, f"number out of range: {_show(v)}") from None
def _section(data: Any, name: str, allowed: tuple[str, ...], required: bool = False) -> Mapping[str, Any]:
    if data is None:
        if required:
            raise ConfigError(name, "missing (required section)")
        return {}
    if not isinstance(data, Mapping):
        raise ConfigError(name or "<top level>", f"must be a mapping, got {type(data).__name__}")
    for key in data:
        if not isinstance(key, str) or key not in allowed:
            shown = key if isinstance(key, str) else _show(key)
            raise ConfigError(f"{name}.{shown}" if name else shown, f"unknown key (allowed: {', '.join(allowed)})")
    return data


def _number(
    data: Mapping[str, Any],
    key: str,
    name: str,
    default: float | None,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    nullable: bool = False,
) -> float | None:
    if key not in data:
        return default
    v = data[key]
    if v is None and nullable:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ConfigError(name, f"must be a number, got {_show(v)}")
    v = _to_float(v, name)
    if not math.isfinite(v):
        raise ConfigError(name, f"must be finite, got {v}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ConfigError(name, f"must be {'>' if lo_open else '>='} {lo:g}, got {v:g}")
    if hi is not None and v > hi:
        raise ConfigError(name, f"must be <= {hi:g}, got {v:g}")
    return v


def _choice(data: Mapping[str, Any], key: str, name: str, default: str, choices: tuple[str, ...]) -> str:
    v = data.get(key, default)
    if not isinstance(v, str) or v not in choices:
        raise ConfigError(name, f"must be one of {', '.join(choices)}, got {_show(v)}")
    return v


def _bool(data: Mapping[str, Any], key: str, name: str, default: bool) -> bool:
    v = data.get(key, default)
    if not isinstance(v, bool):
        raise ConfigError(name, f"must be true or false, got {_show(v)}")
    return v


def _pairs(value: Any, name: str, width: int) -> list[list[float]]:
    if not isinstance(value, (list, tuple)):
        raise ConfigError(name, f"must be a list of [{', '.join(['number'] * width)}] entries")
    out = []
    for i, row in enumerate(value):
        item = f"{name}[{i}]"
        if not isinstance(row, (list, tuple)) or len(row) != width:
            raise ConfigError(item, f"must be a list of {width} numbers, got {_show(row)}")
        vals = []
        for x in row:
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                raise ConfigError(item, f"must be {width} numbers, got {_show(row)}")
            f = _to_float(x, item)
            if not math.isfinite(f):
                raise ConfigError(item, f"must be finite, got {_show(row)}")
            vals.append(f)
        out.append(vals)
    return out


# ---------------------------------------------------------------------------------- sections
def _build_path(waypoints: tuple[tuple[float, float, float], ...], closed: bool, moving: str) -> Any:
    # Build the path once so that every geometric problem (duplicates, too few points, a spline
    # that doubles back, frenet on a straight piece) is reported at load time, named in config terms.
    from pf_offboard.path import Path

    try:
        return Path.from_waypoints(waypoints, closed=closed, frame=moving)
    except InputError as exc:
        fld = exc.field if exc.field.startswith("path.") else f"path.{exc.field}"
        raise ConfigError(fld, exc.reason) from None


def _path(data: Any, base_dir: str | None = None) -> PathConfig:
    d = _section(data, "path", ("frame", "closed", "moving_frame", "waypoints", "file", "altitude_reference", "origin"), required=True)
    closed = _bool(d, "closed", "path.closed", False)
    moving = _choice(d, "moving_frame", "path.moving_frame", "auto", MOVING_FRAMES)
    if "file" in d:
        return _geodetic_path(d, closed, moving, base_dir)
    for key in ("altitude_reference", "origin"):
        if key in d:
            raise ConfigError(f"path.{key}", "only applies to a path from a file (path.file: mission.plan | .waypoints | .csv | .geojson | .kml)")
    frame = _choice(d, "frame", "path.frame", "enu", FRAMES)
    if "waypoints" not in d:
        raise ConfigError("path.waypoints", "missing (required; or path.file: a way-point file from a planning tool)")
    pts = _pairs(d["waypoints"], "path.waypoints", 3)
    if frame == "ned":
        pts = [ned_to_enu(p).tolist() for p in pts]
    waypoints = tuple((p[0], p[1], p[2]) for p in pts)
    _build_path(waypoints, closed, moving)
    return PathConfig(waypoints, closed, frame, moving)


def _geodetic_path(d: Mapping[str, Any], closed: bool, moving: str, base_dir: str | None) -> PathConfig:
    """``path.file`` (+ ``altitude_reference``, optional ``origin``): way-points in latitude /
    longitude from a planning tool; converted now if the origin is given, else at connect time."""
    from pf_offboard.geopath import ALTITUDE_REFERENCES, read_geopath

    for key in ("waypoints", "frame"):
        if key in d:
            raise ConfigError(f"path.{key}", "cannot be combined with path.file (the way-points come from the file)")
    name = d["file"]
    if not isinstance(name, str) or not name.strip():
        raise ConfigError("path.file", f"must be a file name, got {name!r}")
    if "altitude_reference" not in d:
        raise ConfigError("path.altitude_reference", "missing (required with path.file): relative_home (altitudes above "
                          "the home position) or amsl (above mean sea level)")  # fmt: skip
    reference = _choice(d, "altitude_reference", "path.altitude_reference", "", ALTITUDE_REFERENCES)
    file_path = os.path.join(base_dir, name) if base_dir and not os.path.isabs(name) else name
    geo = read_geopath(file_path)  # PathFileError names the file and the item
    if geo.altitude_reference is not None and geo.altitude_reference != reference:
        raise ConfigError("path.altitude_reference", f"is {reference}, but {file_path} gives its altitudes as {geo.altitude_reference}; make them agree")
    origin: GeoPoint | None = None
    if "origin" in d:
        o = d["origin"]
        if not isinstance(o, (list, tuple)) or len(o) != 3:
            raise ConfigError("path.origin", f"must be [lat_deg, lon_deg, alt_amsl_m], got {o!r}")
        try:
            origin = GeoPoint(*o)
        except InputError as exc:
            raise ConfigError("path.origin", exc.reason) from None
    source = GeodeticSource(
        file=file_path,
        file_format=geo.file_format,
        altitude_reference=reference,
        waypoints_lat_lon_alt=tuple((w.lat_deg, w.lon_deg, w.alt_m) for w in geo.waypoints),
        names=tuple(w.where for w in geo.waypoints),
        skipped=geo.skipped,
        takeoff_alt_m=geo.takeoff_alt_m,
    )
    path = PathConfig((), closed, "enu", moving, source)
    return _localise(path, origin, None) if origin is not None else path


def _localise(path: PathConfig, origin: GeoPoint, home_alt_amsl_m: float | None) -> PathConfig:
    from pf_offboard.geopath import GeoPath, GeoWaypoint, to_local

    src = path.geodetic
    assert src is not None
    geo = GeoPath(src.file, src.file_format, tuple(GeoWaypoint(*p, n) for p, n in zip(src.waypoints_lat_lon_alt, src.names)), None)
    local = to_local(geo, src.altitude_reference, origin, home_alt_amsl_m)
    waypoints = tuple((float(p[0]), float(p[1]), float(p[2])) for p in local)
    _build_path(waypoints, path.closed, path.moving_frame)
    from dataclasses import replace

    return replace(path, waypoints_enu_m=waypoints, geodetic=replace(src, origin=origin, home_alt_amsl_m=home_alt_amsl_m))


def with_origin(config: Config, origin: GeoPoint, home_alt_amsl_m: float | None = None) -> Config:
    """``config`` with its geodetic path converted to the local ENU frame of ``origin`` (the
    vehicle's EKF origin, AMSL). ``home_alt_amsl_m``: the home position's altitude for
    ``altitude_reference: relative_home`` (default: the origin's). Refuses way-points farther
    than :data:`pf_offboard.geopath.MAX_DISTANCE_FROM_ORIGIN_M` from the origin."""
    from dataclasses import replace

    if config.path.geodetic is None:
        return config
    return replace(config, path=_localise(config.path, origin, home_alt_amsl_m))


def local_config_data(config: Config, data: Mapping[str, Any]) -> dict[str, Any]:
    """The YAML mapping ``data`` of ``config`` with its geodetic path replaced by the local ENU
    way-points it was converted to (a self-contained copy for the flight's logs: replay and plot
    rebuild exactly the path that was flown)."""
    out = dict(data)
    path = dict(out.get("path") or {})
    for key in ("file", "altitude_reference", "origin"):
        path.pop(key, None)
    path["frame"] = "enu"
    path["waypoints"] = [list(p) for p in config.path.waypoints_enu_m]
    out["path"] = path
    return out


def _gains(data: Any) -> Gains:
    d = _section(data, "gains", ("transversal", "tangential"))
    default = Gains()
    vals = {}
    for loop in ("transversal", "tangential"):
        sub = _section(d.get(loop), f"gains.{loop}", ("bandwidth_hz", "damping"))
        vals[f"{loop}_bandwidth_hz"] = _number(
            sub, "bandwidth_hz", f"gains.{loop}.bandwidth_hz", getattr(default, f"{loop}_bandwidth_hz"), MIN_BANDWIDTH_HZ, 50.0
        )
        vals[f"{loop}_damping"] = _number(
            sub, "damping", f"gains.{loop}.damping", getattr(default, f"{loop}_damping"), MIN_DAMPING, 5.0
        )
    return Gains(**vals)  # type: ignore[arg-type]


def _yaw(data: Any, frame: str, closed: bool) -> YawSpec:
    d = _section(data, "yaw", ("mode", "yaw_deg", "table"))
    # no mode: a table given is flown, else a constant heading (yaw_deg, default 0: east)
    mode = _choice(d, "mode", "yaw.mode", "table" if "table" in d else "constant", YAW_MODES)
    if mode == "hold" and "yaw_deg" in d:
        raise ConfigError("yaw.yaw_deg", "not used with mode hold (the heading the vehicle has at activation); use mode constant")
    yaw_deg = _number(d, "yaw_deg", "yaw.yaw_deg", 0.0, -3600.0, 3600.0)
    assert yaw_deg is not None
    yaw = math.radians(yaw_deg)
    if frame == "ned":
        # a heading converts as a heading; an offset from the tangent is a rotation sense
        yaw = yaw_ned_to_enu(yaw) if mode == "constant" else yaw_rate_ned_to_enu(yaw)
    table: list[tuple[float, float]] = []
    if "table" in d:
        rows = _pairs(d["table"], "yaw.table", 2)
        prev = -math.inf
        for i, (s, psi_deg) in enumerate(rows):
            if s < 0.0:
                raise ConfigError(f"yaw.table[{i}]", f"eta1 must be >= 0 m, got {s:g}")
            if s <= prev:
                raise ConfigError(f"yaw.table[{i}]", "eta1 values must be strictly increasing")
            prev = s
            psi = math.radians(psi_deg)
            table.append((s, yaw_ned_to_enu(psi) if frame == "ned" else psi))
        if frame == "ned":
            # keep the table continuous after the per-entry wrap of the conversion
            unwrapped = [table[0][1]]
            for _, p in table[1:]:
                unwrapped.append(unwrapped[-1] + math.remainder(p - unwrapped[-1], 2.0 * math.pi))
            table = [(s, p) for (s, _), p in zip(table, unwrapped)]
    if mode == "table" and len(table) < 2:
        raise ConfigError("yaw.table", "mode table needs at least 2 [eta1_m, yaw_deg] entries")
    return YawSpec(mode, yaw, tuple(table))


def _limits(data: Any) -> Limits:
    d = _section(
        data, "limits",
        ("max_tilt_deg", "min_thrust_m_s2", "max_thrust_m_s2", "max_approach_speed_m_s", "max_tilt_rate_rad_s", "max_tangential_accel_m_s2"),
    )  # fmt: skip
    default = Limits()
    g = GRAVITY_M_S2
    tilt = _number(d, "max_tilt_deg", "limits.max_tilt_deg", default.max_tilt_deg, MIN_TILT_DEG, 80.0)
    tmin = _number(
        d, "min_thrust_m_s2", "limits.min_thrust_m_s2", default.min_thrust_m_s2, MIN_THRUST_FLOOR_M_S2, round(0.9 * g, 3)
    )
    tmax = _number(d, "max_thrust_m_s2", "limits.max_thrust_m_s2", default.max_thrust_m_s2, round(1.1 * g, 3), 100.0)
    vapp = _number(
        d, "max_approach_speed_m_s", "limits.max_approach_speed_m_s", default.max_approach_speed_m_s, 0.05, 20.0
    )
    # null: no slew limit (the paper's linear laws everywhere; only for an ideal inner loop)
    rate = _number(
        d, "max_tilt_rate_rad_s", "limits.max_tilt_rate_rad_s", default.max_tilt_rate_rad_s, 0.1, 100.0, nullable=True
    )
    # null: no bound on the speed loop's correction (the paper's ideal inner loop)
    acc_t = _number(
        d, "max_tangential_accel_m_s2", "limits.max_tangential_accel_m_s2", default.max_tangential_accel_m_s2, 0.1, 100.0, nullable=True
    )
    return Limits(tilt, tmin, tmax, vapp, rate, acc_t)  # type: ignore[arg-type]


def _flight(data: Any) -> FlightConfig:
    keys = (
        "output_mode",
        "setpoint_rate_hz",
        "state_timeout_s",
        "hover_thrust",
        "takeoff_altitude_m",
        "throw_activation_height_m",
        "end_action",
        "attitude_time_constant_s",
        "velocity_correction_s",
    )
    d = _section(data, "flight", keys)
    f = FlightConfig()
    return FlightConfig(
        output_mode=_choice(d, "output_mode", "flight.output_mode", f.output_mode, OUTPUT_MODES),
        setpoint_rate_hz=_number(d, "setpoint_rate_hz", "flight.setpoint_rate_hz", f.setpoint_rate_hz, 20.0, 1000.0),  # type: ignore[arg-type]
        state_timeout_s=_number(d, "state_timeout_s", "flight.state_timeout_s", f.state_timeout_s, MIN_STATE_TIMEOUT_S, 5.0),  # type: ignore[arg-type]
        hover_thrust=_number(d, "hover_thrust", "flight.hover_thrust", f.hover_thrust, 0.05, 0.95, nullable=True),
        takeoff_altitude_m=_number(d, "takeoff_altitude_m", "flight.takeoff_altitude_m", f.takeoff_altitude_m, 0.3, 100.0),  # type: ignore[arg-type]
        throw_activation_height_m=_number(
            d, "throw_activation_height_m", "flight.throw_activation_height_m", f.throw_activation_height_m, 0.3, 100.0, nullable=True
        ),
        end_action=_choice(d, "end_action", "flight.end_action", f.end_action, END_ACTIONS),
        attitude_time_constant_s=_number(
            d, "attitude_time_constant_s", "flight.attitude_time_constant_s", f.attitude_time_constant_s, 0.01, 2.0,
            nullable=True,
        ),
        velocity_correction_s=(VELOCITY_CORRECTION_AUTO if d.get("velocity_correction_s") == VELOCITY_CORRECTION_AUTO else _number(
            d, "velocity_correction_s", "flight.velocity_correction_s", f.velocity_correction_s, *VELOCITY_CORRECTION_RANGE_S, nullable=True,
        )),  # fmt: skip
    )


def _compensation(data: Any) -> Compensation:
    d = _section(data, "compensation", ("enabled", "observer_rad_s", "integral_rad_s", "phase_margin_deg", "tangential_phase_margin_deg",
                                        "identify_online"))
    c = Compensation()
    return Compensation(
        enabled=_bool(d, "enabled", "compensation.enabled", c.enabled),
        observer_rad_s=_number(d, "observer_rad_s", "compensation.observer_rad_s", c.observer_rad_s, 0.0, 50.0),  # type: ignore[arg-type]
        integral_rad_s=_number(d, "integral_rad_s", "compensation.integral_rad_s", c.integral_rad_s, 0.0, 10.0),  # type: ignore[arg-type]
        phase_margin_deg=_number(d, "phase_margin_deg", "compensation.phase_margin_deg", c.phase_margin_deg, 10.0, 80.0),  # type: ignore[arg-type]
        tangential_phase_margin_deg=_number(  # type: ignore[arg-type]
            d, "tangential_phase_margin_deg", "compensation.tangential_phase_margin_deg", c.tangential_phase_margin_deg, 10.0, 80.0,
        ),
        identify_online=_bool(d, "identify_online", "compensation.identify_online", c.identify_online),
    )


def _vehicle(data: Any) -> VehicleModel:
    """``vehicle:`` section (written by ``pf-offboard identify``); keys are VehicleModel's fields."""
    names = tuple(f.name for f in fields(VehicleModel))
    d = _section(data, "vehicle", names)
    default = VehicleModel.typical()
    vals = {}
    for name in names:
        lo, hi = (0.2, 5.0) if name.startswith("accel_gain") else (0.0, 10.0)
        vals[name] = _number(d, name, f"vehicle.{name}", getattr(default, name), lo, hi, nullable=name == "accel_delay_z_s")
    try:
        return VehicleModel(**vals)  # type: ignore[arg-type]
    except InputError as exc:
        raise ConfigError(exc.field, exc.reason) from None


def _safety(data: Any) -> SafetyConfig:
    """``safety:`` section: the flight envelope (pf_offboard.safety; docs/app.md lists the fields)."""
    names = tuple(f.name for f in fields(SafetyConfig))
    d = _section(data, "safety", names)
    default = SafetyConfig()

    def num(name: str, lo: float, hi: float, lo_open: bool = False) -> float:
        return _number(d, name, f"safety.{name}", getattr(default, name), lo, hi, lo_open=lo_open)  # type: ignore[return-value]

    def vector(name: str, width: int) -> tuple[float, ...] | None:
        if d.get(name) is None:
            return None
        return tuple(_pairs([d[name]], f"safety.{name}", width)[0])

    fmin, fmax = vector("fence_min_enu_m", 3), vector("fence_max_enu_m", 3)
    if (fmin is None) != (fmax is None):
        raise ConfigError("safety.fence_min_enu_m", "give both fence_min_enu_m and fence_max_enu_m, or neither (fence around the path)")
    if fmin is not None and fmax is not None and not all(lo < hi for lo, hi in zip(fmin, fmax)):
        raise ConfigError("safety.fence_max_enu_m", f"must exceed fence_min_enu_m on every axis, got {list(fmin)} .. {list(fmax)}")
    center = vector("fence_center_enu_m", 2)
    radius = _number(d, "fence_radius_m", "safety.fence_radius_m", None, 0.0, 1e5, lo_open=True, nullable=True)
    if (center is None) != (radius is None):
        raise ConfigError("safety.fence_radius_m", "give both fence_center_enu_m and fence_radius_m, or neither (cylinder around the path)")
    floor = num("min_altitude_m", -1e4, 1e4)
    ceiling = num("max_altitude_m", -1e4, 1e5)
    if ceiling <= floor:
        raise ConfigError("safety.max_altitude_m", f"must exceed safety.min_altitude_m ({floor:g}), got {ceiling:g}")
    return SafetyConfig(
        enabled=_bool(d, "enabled", "safety.enabled", default.enabled),
        action=_choice(d, "action", "safety.action", default.action, SAFETY_ACTIONS),
        fence_shape=_choice(d, "fence_shape", "safety.fence_shape", default.fence_shape, FENCE_SHAPES),
        fence_margin_m=num("fence_margin_m", 0.0, 1e4),
        fence_min_enu_m=fmin,  # type: ignore[arg-type]
        fence_max_enu_m=fmax,  # type: ignore[arg-type]
        fence_center_enu_m=center,  # type: ignore[arg-type]
        fence_radius_m=radius,
        min_altitude_m=floor,
        max_altitude_m=ceiling,
        max_path_distance_at_activation_m=num("max_path_distance_at_activation_m", 0.0, 1e4, lo_open=True),
        max_path_distance_m=num("max_path_distance_m", 0.0, 1e4, lo_open=True),
        max_tilt_deg=num("max_tilt_deg", 0.0, 90.0, lo_open=True),
        max_body_rate_rad_s=num("max_body_rate_rad_s", 0.0, 100.0, lo_open=True),
        max_attitude_error_deg=num("max_attitude_error_deg", 0.0, 180.0, lo_open=True),
        attitude_error_time_s=num("attitude_error_time_s", 0.0, 60.0),
        max_descent_speed_m_s=num("max_descent_speed_m_s", 0.0, 100.0, lo_open=True),
        falling_confirm_s=num("falling_confirm_s", 0.0, 5.0),
        max_estimator_reset_m=num("max_estimator_reset_m", 0.0, 1e4, lo_open=True),
        no_progress_s=num("no_progress_s", 0.0, 3600.0, lo_open=True),
        min_progress_m=num("min_progress_m", 0.0, 1e4, lo_open=True),
        safe_mode_timeout_s=num("safe_mode_timeout_s", 0.0, 600.0, lo_open=True),
        heartbeat_timeout_s=num("heartbeat_timeout_s", 0.0, 60.0, lo_open=True),
        tilt_lookahead_s=num("tilt_lookahead_s", 0.0, 2.0),
    )


TOP_LEVEL = (
    "path", "speed_m_s", "gains", "yaw", "limits", "flight", "vehicle", "compensation", "safety", "speed_profile",
    "feedforward", "controller",
)  # fmt: skip


def _speed_profile(data: Any) -> SpeedProfileSpec | None:
    """``speed_profile:`` section (absent or null: the constant ``speed_m_s``)."""
    if data is None:
        return None
    keys = ("max_speed_m_s", "table", "max_tangential_accel_m_s2", "max_tangential_jerk_m_s3", "accel_share", "max_body_rate_rad_s")
    d = _section(data, "speed_profile", keys)
    if "max_speed_m_s" not in d:
        raise ConfigError("speed_profile.max_speed_m_s", "missing (required in a speed_profile section)")
    default = SpeedProfileSpec(1.0)
    vals = {
        "max_speed_m_s": _number(d, "max_speed_m_s", "speed_profile.max_speed_m_s", None, 0.05, MAX_SPEED_M_S),
        "max_tangential_accel_m_s2": _number(d, "max_tangential_accel_m_s2", "speed_profile.max_tangential_accel_m_s2",
                                             default.max_tangential_accel_m_s2, 0.05, 50.0),
        "max_tangential_jerk_m_s3": _number(d, "max_tangential_jerk_m_s3", "speed_profile.max_tangential_jerk_m_s3",
                                            default.max_tangential_jerk_m_s3, 0.1, 1000.0),
        "accel_share": _number(d, "accel_share", "speed_profile.accel_share", default.accel_share, 0.05, 1.0),
        "max_body_rate_rad_s": _number(d, "max_body_rate_rad_s", "speed_profile.max_body_rate_rad_s",
                                       default.max_body_rate_rad_s, 0.1, 20.0),
    }  # fmt: skip
    table = _pairs(d["table"], "speed_profile.table", 2) if d.get("table") is not None else []
    try:
        return SpeedProfileSpec(table_eta1_m_speed_m_s=tuple((a, b) for a, b in table), **vals)  # type: ignore[arg-type]
    except InputError as exc:
        raise ConfigError(exc.field, exc.reason) from None


def parse_config(data: Any, source: str = "<config>") -> Config:
    """Validate a parsed YAML mapping into a :class:`Config` (ENU). A ``path.file`` is read
    relative to the directory of ``source`` (when ``source`` is a file)."""
    if data is not None and not isinstance(data, Mapping):
        # Name the file: "<top level>" alone does not say which config was wrong.
        raise ConfigError(source, f"must be a mapping of sections ({', '.join(TOP_LEVEL)}), got {type(data).__name__}")
    d = _section(data, "", TOP_LEVEL, required=True) if data is not None else None
    if d is None:
        raise ConfigError("path", "missing (required section); the config is empty")
    base_dir = os.path.dirname(source) if os.path.isfile(source) else None
    path = _path(d.get("path"), base_dir)
    speed = _number(d, "speed_m_s", "speed_m_s", DEFAULT_SPEED_M_S, -MAX_SPEED_M_S, MAX_SPEED_M_S)
    assert speed is not None
    if abs(speed) < MIN_SPEED_M_S:
        raise ConfigError("speed_m_s", f"must be non-zero, |speed| >= {MIN_SPEED_M_S:g} m/s (its sign picks the direction of travel), got {speed:g}")
    vehicle = _vehicle(d.get("vehicle"))
    compensation = _compensation(d.get("compensation"))
    raw_gains = d.get("gains")
    # gains: auto (or no gains section): derived from the vehicle model with a phase margin
    gains_auto = raw_gains is None or raw_gains == "auto"
    if gains_auto:
        from pf_offboard.control.tuning import gains_for_vehicle

        gains = gains_for_vehicle(vehicle, compensation.phase_margin_deg, compensation.tangential_phase_margin_deg)
    elif isinstance(raw_gains, str):
        raise ConfigError("gains", f"must be 'auto' or a mapping (transversal, tangential), got {raw_gains!r}")
    else:
        gains = _gains(raw_gains)
    profile = _speed_profile(d.get("speed_profile"))
    table = profile.table_eta1_m_speed_m_s if profile is not None else ()
    if table and path.closed and path.waypoints_enu_m:
        length = _build_path(path.waypoints_enu_m, path.closed, path.moving_frame).length_m
        if table[-1][0] >= table[0][0] + length:
            raise ConfigError("speed_profile.table", f"eta1 values must span less than one lap ({length:.3f} m) on a closed path")
    feedforward = _choice(d, "feedforward", "feedforward", "on_path", FEEDFORWARD_MODES)
    if feedforward == "any_state" and compensation.enabled:
        raise ConfigError("feedforward", ANY_STATE_NEEDS_NO_COMPENSATION)
    return Config(
        path=path,
        speed_m_s=speed,
        gains=gains,
        gains_auto=gains_auto,
        compensation=compensation,
        yaw=_yaw(d.get("yaw"), path.frame, path.closed),
        limits=_limits(d.get("limits")),
        flight=_flight(d.get("flight")),
        vehicle=vehicle,
        safety=_safety(d.get("safety")),
        source=source,
        controller=_choice(d, "controller", "controller", "path_following", CONTROLLERS),
        speed_profile=profile,
        feedforward=feedforward,
    )


class _StrictLoader:
    """A SafeLoader that rejects duplicate keys (a silently overridden key is a typo too)."""

    @staticmethod
    def make() -> type:
        import yaml

        # libyaml's parser when PyYAML was built with it (5x faster: configs are loaded by every
        # command and thousands of times by the fuzz tests); the constructors stay PyYAML's safe ones.
        base = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

        class Loader(base):  # type: ignore[misc, valid-type]
            pass

        def construct_mapping(loader: Any, node: Any, deep: bool = False) -> dict[Any, Any]:
            seen: dict[Any, Any] = {}
            if not isinstance(node, yaml.MappingNode):
                raise ConfigError(f"line {node.start_mark.line + 1}", "expected a mapping")
            for key_node, value_node in node.value:
                line = key_node.start_mark.line + 1
                if not isinstance(key_node, yaml.ScalarNode):
                    # a list or mapping as a key (`? [a, b]`): never a config field (and unhashable)
                    raise ConfigError(f"line {line}", f"a key must be a plain name, not a {key_node.id}")
                key = loader.construct_object(key_node, deep=deep)
                try:
                    duplicate = key in seen
                except TypeError:  # an unhashable scalar (e.g. !!binary is bytes: hashable; belt and braces)
                    raise ConfigError(f"line {line}", f"unusable key {_show(key)}") from None
                if duplicate:
                    raise ConfigError(_show(key) if not isinstance(key, str) else key, f"duplicate key at line {line}")
                seen[key] = loader.construct_object(value_node, deep=deep)
            return seen

        Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, construct_mapping)
        return Loader


def load_config(path: str | os.PathLike[str]) -> Config:
    """Read and validate a YAML config file."""
    from pf_offboard.inputfile import read_bounded

    source = os.fspath(path)
    try:
        data = read_bounded(source, MAX_CONFIG_BYTES)
    except ValueError as exc:
        raise ConfigError(_short(source), f"config file: {exc}") from None
    return parse_config_bytes(data, source)


def _short(name: str, limit: int = 200) -> str:
    """A file name for a one-line message (a 5000-character name is cut in the middle)."""
    return name if len(name) <= limit else f"{name[: limit // 2]}...{name[-limit // 2 :]} ({len(name)} characters)"


def parse_config_bytes(data: bytes, source: str = "<config>") -> Config:
    """Validate a config file's content: UTF-8 YAML text. Every failure is one :class:`ConfigError`
    (non-UTF-8 bytes, oversized, YAML syntax, keys that are lists / mappings, nesting deeper than
    the parser can follow, integers too long to read) naming the file or the field."""
    import yaml

    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(source, f"larger than {MAX_CONFIG_BYTES // 1024} kB: not a config file")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ConfigError(source, f"not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}, line {line})") from None
    try:
        loaded = yaml.load(text, Loader=_StrictLoader.make())  # noqa: S506 - a SafeLoader subclass
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark is not None else "unknown position"
        raise ConfigError(source, f"YAML syntax error at {where}: {exc.problem or exc.context}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(source, f"YAML error: {_one_line(exc)}") from None
    except RecursionError:
        raise ConfigError(source, "YAML nested too deeply (a config is a few levels deep)") from None
    except ConfigError:
        raise
    except Exception as exc:  # noqa: BLE001
        # PyYAML's constructors are not hardened against hostile text: an integer of more than 4300
        # digits raises ValueError (Python's int limit), an explicit `!!timestamp x` AttributeError,
        # bad base64 binascii.Error. Whatever it is, the file is unreadable: one line, not a traceback.
        raise ConfigError(source, f"unreadable YAML value ({type(exc).__name__}: {_one_line(exc)})") from None
    try:
        return parse_config(loaded, source=source)
    except RecursionError:  # a deep structure in a value (its repr in a message, or a comparison)
        raise ConfigError(source, "YAML nested too deeply (a config is a few levels deep)") from None


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 200 else text[:197] + "..."
