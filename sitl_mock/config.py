"""Configuration of the mock autopilot: profile, vehicle, spawn, transports, clock, faults.

Frozen dataclasses with units in the field names. Frames: NED (the autopilot's own), metres,
seconds. Every validation error is a :class:`MockConfigError` naming the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sitl_mock.dynamics import DEFAULT_VEHICLE, PRESET_NAMES, Push, Wind
from sitl_mock.profiles import PROFILES

MAX_WIND_M_S = 20.0  # beyond what a small multicopter flies in (and the tilt limits allow)
MAX_SPAWN_RATE_RAD_S = 35.0  # ~2000 deg/s, a gyro's usual full scale: beyond any throw


class MockConfigError(ValueError):
    """Bad mock configuration; ``field`` names the offending option."""

    def __init__(self, field_name: str, reason: str) -> None:
        super().__init__(f"{field_name}: {reason}")
        self.field = field_name
        self.reason = reason


@dataclass(frozen=True)
class SpawnSpec:
    """Initial vehicle state (NED, metres, m/s).

    kind ``ground``: landed, disarmed, at ``position_ned_m`` (z forced to 0).
    kind ``hover``: armed, in the profile's hold mode, hovering at ``position_ned_m``.
    kind ``throw``: armed with motors locked (like PX4 COM_THROW_EN), ballistic from
    ``position_ned_m`` with ``velocity_ned_m_s``, attitude ``q_ned_frd`` (body FRD to world NED,
    (w, x, y, z)) and body rates ``rates_frd_rad_s`` until the client commands a mode. Only a throw
    takes an attitude or body rates (a ground or hover spawn is level and at rest).
    """

    kind: str = "ground"
    position_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    q_ned_frd: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    rates_frd_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def validate(self) -> None:
        if self.kind not in ("ground", "hover", "throw"):
            raise MockConfigError("spawn", f"unknown kind {self.kind!r}")
        for name in ("position_ned_m", "velocity_ned_m_s"):
            value = getattr(self, name)
            if len(value) != 3 or not all(math.isfinite(v) for v in value):
                raise MockConfigError(f"spawn.{name}", f"must be 3 finite numbers, got {value!r}")
        if self.kind != "ground" and self.position_ned_m[2] > 0.0:
            raise MockConfigError("spawn.position_ned_m", f"z must be <= 0 (NED, z = -altitude), got {self.position_ned_m[2]}")
        q, w = self.q_ned_frd, self.rates_frd_rad_s
        if len(q) != 4 or not all(math.isfinite(v) for v in q) or abs(math.sqrt(sum(v * v for v in q)) - 1.0) > 1e-6:
            raise MockConfigError("spawn.q_ned_frd", f"must be a unit quaternion (w, x, y, z), got {q!r}")
        if len(w) != 3 or not all(math.isfinite(v) for v in w):
            raise MockConfigError("spawn.rates_frd_rad_s", f"must be 3 finite numbers, got {w!r}")
        if math.sqrt(sum(v * v for v in w)) > MAX_SPAWN_RATE_RAD_S:
            raise MockConfigError("spawn.rates_frd_rad_s", f"must be <= {MAX_SPAWN_RATE_RAD_S:g} rad/s in norm, got {w!r}")
        if self.kind != "throw" and (tuple(q) != (1.0, 0.0, 0.0, 0.0) or any(w)):
            raise MockConfigError("spawn", f"only a throw spawn takes an attitude or body rates, not {self.kind!r}")

    @staticmethod
    def parse(text: str) -> SpawnSpec:
        """``ground`` | ``hover:x,y,z`` | ``throw:x,y,z,vx,vy,vz[,qw,qx,qy,qz,p,q,r]`` (NED: z =
        -altitude; the attitude body FRD to world NED, the body rates FRD rad/s)."""
        kind, _, rest = text.partition(":")
        try:
            values = tuple(float(v) for v in rest.split(",")) if rest else ()
        except ValueError:
            raise MockConfigError("spawn", f"numbers expected after '{kind}:', got {rest!r}") from None
        if not all(math.isfinite(v) for v in values):
            raise MockConfigError("spawn", "values must be finite")
        if kind == "ground" and len(values) in (0, 2, 3):
            pos = (values + (0.0, 0.0, 0.0))[:2] + (0.0,) if values else (0.0, 0.0, 0.0)
            return SpawnSpec("ground", pos)
        if kind in ("hover", "throw") and len(values) >= 3 and values[2] > 0.0:
            raise MockConfigError("spawn", f"z must be <= 0 (NED, z = -altitude), got {values[2]}")
        if kind == "hover" and len(values) == 3:
            return SpawnSpec("hover", values)  # type: ignore[arg-type]
        if kind == "throw" and len(values) == 6:
            return SpawnSpec("throw", values[:3], values[3:])  # type: ignore[arg-type]
        if kind == "throw" and len(values) == 13:
            return SpawnSpec("throw", values[:3], values[3:6], values[6:10], values[10:])  # type: ignore[arg-type]
        raise MockConfigError(
            "spawn", f"expected ground | hover:x,y,z | throw:x,y,z,vx,vy,vz[,qw,qx,qy,qz,p,q,r] (NED), got {text!r}"
        )

    def args(self) -> str:
        """The ``--spawn`` text that :meth:`parse` reads back into this spawn."""
        if self.kind == "ground":
            return "ground:" + ",".join(repr(v) for v in self.position_ned_m[:2])
        if self.kind == "hover":
            return "hover:" + ",".join(repr(v) for v in self.position_ned_m)
        values = tuple(self.position_ned_m) + tuple(self.velocity_ned_m_s)
        if tuple(self.q_ned_frd) != (1.0, 0.0, 0.0, 0.0) or any(self.rates_frd_rad_s):
            values += tuple(self.q_ned_frd) + tuple(self.rates_frd_rad_s)
        return "throw:" + ",".join(repr(v) for v in values)


@dataclass(frozen=True)
class FaultConfig:
    """Fault injection; all randomness from the mock's seeded Generator.

    Probabilities are fractions 0..1 per datagram. ``loss`` drops outgoing and incoming
    datagrams; ``duplicate``, ``corrupt`` and latency apply to outgoing datagrams (telemetry).
    Times are simulated seconds since boot.
    """

    loss: float = 0.0
    duplicate: float = 0.0
    corrupt: float = 0.0  # a payload byte flipped after encoding: the receiver's CRC check fails
    latency_s: float = 0.0
    jitter_s: float = 0.0  # uniform extra delay in [0, jitter_s)
    blackout_s: tuple[float, float] | None = None  # no outgoing datagrams for t in [t0, t1)
    estimator_reset_at_s: float | None = None
    estimator_reset_ned_m: tuple[float, float, float] = (2.0, -1.0, 0.0)
    takeover_at_s: float | None = None
    takeover_mode: str | None = None  # default: the profile's hold mode (POSCTL-like position hold)
    # the takeover instead (or as well: whichever comes first) the first time the armed vehicle is
    # above this height (m above its spawn's ground): "the operator takes over during the climb"
    # without depending on how long the client took to arm (a timed fault did, under CI load)
    takeover_above_m: float | None = None
    gust_at_s: float | None = None
    gust_ned_m_s: tuple[float, float, float] = (3.0, 0.0, 0.0)
    gust_duration_s: float = 1.0
    # safety-test faults (tests/faults): the vehicle disarms / loses its motors (falls, crashes),
    # mode requests are refused as TEMPORARILY_REJECTED (a busy autopilot), HEARTBEATs are lost
    disarm_at_s: float | None = None
    motor_failure_at_s: float | None = None
    mode_refused_s: tuple[float, float] | None = None  # DO_SET_MODE refused for t in [t0, t1)
    heartbeat_mute_s: tuple[float, float] | None = None  # no HEARTBEAT sent for t in [t0, t1)
    # blackout_s / heartbeat_mute_s count from the first entry into OFFBOARD / GUIDED instead of
    # boot (a test's fault then falls inside the flight however long the client took to start)
    windows_from_offboard: bool = False
    # loss only from the first entry into OFFBOARD / GUIDED: a test of the flight through a lossy link
    # whose connection and mode switch are not the case under test (through 40 % loss both ways they
    # can take longer than the app's 5 s command timeout, and the test would fail before its fault)
    loss_from_offboard: bool = False
    # the autopilot's clock jumps: from clock_jump_at_s on, every time_boot_ms / time_usec it sends
    # is off by clock_jump_s (forward or back: a reboot, a clock reset); the vehicle does not move
    clock_jump_at_s: float | None = None
    clock_jump_s: float = -20.0
    clock_at_start_s: float = 0.0  # the clock the autopilot reports at the mock's start (booted that long ago)
    # ATTITUDE_QUATERNION reordered: each sample is held back with this probability and sent after
    # the next one (an older sample arriving after a newer one); at attitude_future_at_s one extra
    # sample dated attitude_future_by_s ahead, carrying a 90 deg roll (flown, it would flip the vehicle)
    attitude_reorder: float = 0.0
    attitude_future_at_s: float | None = None
    attitude_future_by_s: float = 5.0
    # every motor's full thrust x thrust_loss_factor from thrust_loss_at_s (a sagging battery,
    # damaged propellers): below 1 / thrust-to-weight the vehicle sinks and lands whatever it is told
    thrust_loss_at_s: float | None = None
    thrust_loss_factor: float = 0.25
    # from offboard_stuck_at_s the autopilot stays in OFFBOARD / GUIDED and accepts setpoints but no
    # longer flies them: it holds where it is (a vehicle that cannot make progress)
    offboard_stuck_at_s: float | None = None
    # every DO_SET_MODE answered is followed by a DENIED COMMAND_ACK addressed to another GCS
    # (target system 255, component 190): what a client sees when someone else's request is refused
    foreign_denied_ack: bool = False
    # SET_MESSAGE_INTERVAL for HEARTBEAT refused (DENIED), as real PX4 does: HEARTBEAT stays at 1 Hz
    heartbeat_rate_fixed: bool = False
    # from estimate_lost_at_s the position estimate is lost: ODOMETRY quality -1, ESTIMATOR_STATUS /
    # EKF_STATUS_REPORT (2 Hz) without a position solution, and the estimate drifts at
    # estimate_lost_drift_ned_m_s (a vehicle flown on it drifts the other way)
    estimate_lost_at_s: float | None = None
    estimate_lost_drift_ned_m_s: tuple[float, float, float] = (0.6, 0.0, 0.0)
    # at failsafe_at_s the autopilot's own failsafe (a critical battery) takes over: PX4 AUTO.LAND /
    # ArduPilot LAND (or failsafe_mode), HEARTBEAT system_status CRITICAL; it is not undone by setpoints
    failsafe_at_s: float | None = None
    failsafe_mode: str | None = None
    # one corrupt LOCAL_POSITION_NED / ODOMETRY sample each (t, dx, dy, dz, vx, vy, vz): at t, 1 ms
    # after the regular sample, the estimate + (dx, dy, dz) with the velocity (vx, vy, vz) (NED)
    corrupt_states: tuple[tuple[float, float, float, float, float, float, float], ...] = ()

    def validate(self) -> None:
        for name in ("loss", "duplicate", "corrupt", "attitude_reorder"):
            value = getattr(self, name)
            if not (0.0 <= value <= 1.0):
                raise MockConfigError(f"faults.{name}", f"must be a fraction in [0, 1], got {value}")
        for name in ("latency_s", "jitter_s", "gust_duration_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise MockConfigError(f"faults.{name}", f"must be >= 0 s, got {value}")
        for name in ("blackout_s", "mode_refused_s", "heartbeat_mute_s"):
            window = getattr(self, name)
            if window is not None:
                t0, t1 = window
                if not (math.isfinite(t0) and math.isfinite(t1) and 0 <= t0 <= t1):
                    raise MockConfigError(f"faults.{name}", f"need 0 <= t0 <= t1, got {window}")
        for name in ("estimator_reset_ned_m", "gust_ned_m_s", "estimate_lost_drift_ned_m_s"):
            if not all(math.isfinite(v) for v in getattr(self, name)):
                raise MockConfigError(f"faults.{name}", "values must be finite")
        for name in ("estimator_reset_at_s", "takeover_at_s", "gust_at_s", "disarm_at_s", "motor_failure_at_s",
                     "clock_jump_at_s", "attitude_future_at_s", "thrust_loss_at_s", "offboard_stuck_at_s",
                     "estimate_lost_at_s", "failsafe_at_s"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value >= 0.0):
                raise MockConfigError(f"faults.{name}", f"must be a finite time >= 0 s, got {value}")
        if self.takeover_above_m is not None and not (math.isfinite(self.takeover_above_m) and self.takeover_above_m > 0.0):
            raise MockConfigError("faults.takeover_above_m", f"must be a finite height > 0 m, got {self.takeover_above_m}")
        if not (math.isfinite(self.clock_at_start_s) and 0.0 <= self.clock_at_start_s <= 1e6):
            raise MockConfigError("faults.clock_at_start_s", f"must be in [0, 1e6] s, got {self.clock_at_start_s}")
        at = self.clock_jump_at_s
        if not math.isfinite(self.clock_jump_s) or (at is not None and self.clock_at_start_s + at + self.clock_jump_s < 0.0):
            raise MockConfigError("faults.clock_jump_s", f"must be finite and keep the clock >= 0 (clock {self.clock_at_start_s:g} s "
                                  f"+ jump at {at} s), got {self.clock_jump_s}")
        if not (math.isfinite(self.attitude_future_by_s) and self.attitude_future_by_s > 0.0):
            raise MockConfigError("faults.attitude_future_by_s", f"must be > 0 s, got {self.attitude_future_by_s}")
        for item in self.corrupt_states:
            if len(item) != 7 or not all(math.isfinite(v) for v in item) or item[0] < 0.0:
                raise MockConfigError("faults.corrupt_states", f"each must be (t >= 0, dx, dy, dz, vx, vy, vz), finite; got {item!r}")
        if not (math.isfinite(self.thrust_loss_factor) and 0.0 < self.thrust_loss_factor <= 1.0):
            raise MockConfigError("faults.thrust_loss_factor", f"must be in (0, 1], got {self.thrust_loss_factor}")


@dataclass(frozen=True)
class MockConfig:
    """Everything :class:`sitl_mock.MockAutopilot` needs.

    Ports: ``0`` = ephemeral (read the bound ports from ``MockAutopilot.ports``); ``None``
    disables that transport. ``udp_remote`` is where the UDP link sends before any client
    has talked to it (PX4 SITL's 127.0.0.1:14540); every address that sends to the UDP port
    is answered too.
    """

    profile: str = "px4"
    vehicle: str = DEFAULT_VEHICLE  # a sitl_mock.dynamics preset name
    spawn: SpawnSpec = SpawnSpec()
    seed: int = 0
    udp_local_port: int | None = 14580
    udp_remote: tuple[str, int] | None = ("127.0.0.1", 14540)
    tcp_port: int | None = None  # ArduPilot SITL uses 5760
    host: str = "127.0.0.1"
    speed: float = 1.0  # × real time (ignored in lockstep)
    lockstep: bool = False
    lockstep_dt_s: float = 0.004  # simulated time per received setpoint in lockstep
    physics_dt_s: float = 0.001  # dynamics substep
    step_dt_s: float = 0.004  # autopilot loop period (telemetry granularity) outside lockstep
    ekf_ready_delay_s: float = 0.5  # position estimate ready after this (real ArduPilot: ~20-40 s)
    home_lat_deg: float = 47.397742
    home_lon_deg: float = 8.545594
    home_alt_m: float = 488.0
    faults: FaultConfig = field(default_factory=FaultConfig)
    duration_s: float | None = None  # stop after this much simulated time
    truth_log: str | None = None  # CSV of the true vehicle state, one row per autopilot step
    scale_timeouts_with_speed: bool | None = None  # None: like the autopilot (PX4 yes, AP no)
    # Wind, world NED (air velocity, m/s): a constant mean plus gusts (first-order Gauss–Markov
    # turbulence per axis, std and time constant) drawn from the simulation's own Generator.
    wind_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    wind_gust_std_m_s: float = 0.0
    wind_gust_time_constant_s: float = 2.0
    # External pushes (sitl_mock.dynamics.Push: start, duration, specific force NED m/s^2).
    pushes: tuple[Push, ...] = ()
    # Parameter values at start, as (name, value) pairs (like PX4_PARAM_NAME=value or a parameter
    # file): e.g. (("MPC_TILTMAX_AIR", 30.0),) clips the acceleration path at 30 deg.
    params: tuple[tuple[str, float], ...] = ()
    # MAVLink 2 signing key file (32 raw bytes, 64 hex digits or a passphrase; sitl_mock.signing):
    # sign everything sent, drop unsigned / wrongly signed frames. None: no signing.
    signing_key_file: str | None = None
    # Relay every client's setpoints (SET_POSITION_TARGET_* / SET_ATTITUDE_TARGET) to the other
    # clients, as a MAVLink router or an autopilot forwarding between its links does: a second
    # controller's setpoints are then seen by the first. False: like a bare SITL port.
    relay_setpoints: bool = False
    # The pilot's RC throttle stick, 0 (down) .. 1 (up); None: centred (or no RC). ArduCopter's
    # LOITER / POSHOLD climb or descend with it outside the 10 % dead zone around the middle: the
    # SITL's RC input with nobody at the sticks is 1000 us, stick fully down (AP_RCProtocol_UDP),
    # so a vehicle handed to LOITER there descends at PILOT_SPEED_UP (2.5 m/s) to the ground.
    rc_throttle: float | None = None

    def validate(self) -> None:
        if self.profile not in PROFILES:
            raise MockConfigError("profile", f"must be one of {sorted(PROFILES)}, got {self.profile!r}")
        if self.vehicle not in PRESET_NAMES:
            raise MockConfigError("vehicle", f"must be one of {', '.join(PRESET_NAMES)}, got {self.vehicle!r}")
        wind = tuple(self.wind_ned_m_s)
        if len(wind) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in wind):
            raise MockConfigError("wind_ned_m_s", f"expected 3 finite numbers (NED m/s), got {self.wind_ned_m_s!r}")
        if math.sqrt(sum(v * v for v in wind)) > MAX_WIND_M_S:
            raise MockConfigError("wind_ned_m_s", f"wind speed must be <= {MAX_WIND_M_S:g} m/s, got {wind}")
        if not (math.isfinite(self.wind_gust_std_m_s) and 0.0 <= self.wind_gust_std_m_s <= MAX_WIND_M_S / 2):
            raise MockConfigError("wind_gust_std_m_s", f"must be in [0, {MAX_WIND_M_S / 2:g}] m/s, got {self.wind_gust_std_m_s}")
        if not (math.isfinite(self.wind_gust_time_constant_s) and 0.05 <= self.wind_gust_time_constant_s <= 600.0):
            raise MockConfigError("wind_gust_time_constant_s",
                                  f"must be in [0.05, 600] s, got {self.wind_gust_time_constant_s}")
        known = {spec.name for spec in PROFILES[self.profile].params}
        for i, item in enumerate(self.params):
            if not (isinstance(item, tuple) and len(item) == 2 and item[0] in known and math.isfinite(float(item[1]))):
                raise MockConfigError(f"params[{i}]", f"expected (a {self.profile} parameter name, a finite value), got {item!r}")
        for i, push in enumerate(self.pushes):
            if not isinstance(push, Push):
                raise MockConfigError(f"pushes[{i}]", f"expected a sitl_mock.dynamics.Push, got {push!r}")
        if not (math.isfinite(self.speed) and self.speed > 0):
            raise MockConfigError("speed", f"must be > 0, got {self.speed}")
        for name in ("lockstep_dt_s", "physics_dt_s", "step_dt_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0 < value <= 0.1):
                raise MockConfigError(name, f"must be in (0, 0.1] s, got {value}")
        if self.ekf_ready_delay_s < 0 or not math.isfinite(self.ekf_ready_delay_s):
            raise MockConfigError("ekf_ready_delay_s", "must be >= 0")
        for name in ("udp_local_port", "tcp_port"):
            port = getattr(self, name)
            if port is not None and not (0 <= port <= 65535):
                raise MockConfigError(name, f"port out of range: {port}")
        if self.udp_remote is not None:
            host, port = self.udp_remote
            if host not in ("127.0.0.1", "localhost") or isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= 65535:
                raise MockConfigError("udp_remote", f"must be (127.0.0.1, port 1..65535), got {self.udp_remote!r}")
        if self.udp_local_port is None and self.tcp_port is None:
            raise MockConfigError("transports", "enable UDP and/or TCP")
        if self.host not in ("127.0.0.1", "localhost", "::1"):
            raise MockConfigError("host", "the mock binds loopback only (127.0.0.1)")
        if self.duration_s is not None and not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise MockConfigError("duration_s", f"must be finite and > 0 s, got {self.duration_s}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise MockConfigError("seed", f"must be a non-negative integer, got {self.seed!r}")
        self.spawn.validate()
        if not (math.isfinite(self.home_lat_deg) and abs(self.home_lat_deg) <= 90.0
                and math.isfinite(self.home_lon_deg) and abs(self.home_lon_deg) <= 180.0
                and math.isfinite(self.home_alt_m)):
            raise MockConfigError("home", f"need finite lat in [-90, 90], lon in [-180, 180], alt; got "
                                  f"{(self.home_lat_deg, self.home_lon_deg, self.home_alt_m)}")
        self.faults.validate()
        if self.signing_key_file is not None:
            self.signing_key()

    def signing_key(self) -> bytes | None:
        """The 32-byte key of ``signing_key_file`` (None without one); MockConfigError if unusable."""
        if self.signing_key_file is None:
            return None
        from sitl_mock.signing import read_key_file

        try:
            return read_key_file(self.signing_key_file)
        except OSError as exc:
            raise MockConfigError("signing_key_file", f"cannot read {self.signing_key_file}: {exc.strerror or exc}") from None
        except ValueError as exc:
            raise MockConfigError("signing_key_file", f"{self.signing_key_file}: {exc}") from None

    def wind(self) -> Wind:
        """The dynamics' wind model for this configuration."""
        return Wind(tuple(map(float, self.wind_ned_m_s)), turbulence_std_m_s=self.wind_gust_std_m_s,  # type: ignore[arg-type]
                    turbulence_time_constant_s=self.wind_gust_time_constant_s)

    def rng(self) -> np.random.Generator:
        return np.random.default_rng(self.seed)

    @property
    def timeouts_scale(self) -> float:
        """Factor on offboard-loss timeouts in simulated time (PX4 scales them under speed-up)."""
        scale = self.scale_timeouts_with_speed
        if scale is None:
            scale = self.profile == "px4"
        return self.speed if (scale and not self.lockstep) else 1.0
