"""Shared set-up of the fault tests: the app (`fly`) against sitl-mock over real loopback sockets.

What each test asserts comes from both sides: the app's exit code and one-line reason, and the
vehicle's end state as the mock saw it (its truth log: mode, armed, attitude, position; or its
state read on its own event loop), plus the app's own tlog for what it sent after the fault.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from pymavlink.dialects.v20 import common as mavlink2
from sitl_mock.config import FaultConfig, MockConfig, SpawnSpec

from pf_offboard.logs.tlog import read_tlog
from app.flights import PAPER, RATE_HZ

HOVER_NED = (-3.0, 0.0, -2.0)  # ENU (0, -3, 2): 1.5 m beside the paper path's PF1 start
SETPOINT_TYPES = ("SET_POSITION_TARGET_LOCAL_NED", "SET_ATTITUDE_TARGET")
PX4_POSCTL = 3 << 16


def write_config(tmp: Path, safety: dict | None = None, rate_hz: float = RATE_HZ, gains: dict | None = None, **flight: object) -> Path:
    data = yaml.safe_load(PAPER.read_text())
    data["speed_m_s"] = -1.5
    if gains is not None:
        data["gains"] = gains
    data["flight"] = {"setpoint_rate_hz": rate_hz, "attitude_time_constant_s": 0.05, **flight}
    if safety is not None:
        data["safety"] = safety
    path = tmp / "flight.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def lockstep(profile: str, spawn: str, **faults: object) -> MockConfig:
    return MockConfig(vehicle="fast", profile=profile, spawn=SpawnSpec.parse(spawn), udp_local_port=0, udp_remote=None,
                      lockstep=True, lockstep_dt_s=1.0 / RATE_HZ, faults=FaultConfig(**faults))  # fmt: skip


def own_clock(profile: str, spawn: str, truth_log: Path, speed: float = 0.5, **faults: object) -> MockConfig:
    """The vehicle on its own clock: a blackout can only be modelled this way, since a lockstep
    vehicle stops with the link (it advances only on the setpoints it receives). At half real
    speed by default: on a loaded CI machine the app's wall-clock latency then costs half as much
    vehicle time, so the flight itself does not depend on the load (the app's wall-clock timeouts
    are then twice as short in vehicle time, which only makes the fault shorter for the old code)."""
    return MockConfig(vehicle="fast", profile=profile, spawn=SpawnSpec.parse(spawn), udp_local_port=0, udp_remote=None,
                      speed=speed, truth_log=str(truth_log), faults=FaultConfig(**faults))  # fmt: skip


def hover(ned: tuple[float, float, float] = HOVER_NED) -> str:
    return "hover:" + ",".join(map(str, ned))


@dataclass(frozen=True)
class Truth:
    """The mock's truth log: one row per autopilot step."""

    time_s: np.ndarray
    position_ned_m: np.ndarray
    tilt_deg: np.ndarray
    armed: np.ndarray
    mode: list[str]
    landed: np.ndarray


def read_truth(path: Path) -> Truth:
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    f = lambda k: np.array([float(r[k]) for r in rows])  # noqa: E731
    qx, qy = f("qx"), f("qy")
    tilt = np.degrees(np.arccos(np.clip(1.0 - 2.0 * (qx**2 + qy**2), -1.0, 1.0)))
    return Truth(f("time_s"), np.stack([f("x_m"), f("y_m"), f("z_m")], axis=1), tilt, f("armed").astype(bool),
                 [r["mode"] for r in rows], f("landed").astype(bool))  # fmt: skip


def last_heartbeat_mode(log_dir: Path, profile: str) -> str:
    """The mode in the vehicle's last HEARTBEAT (its own report: the truth log's last rows can miss
    a mode change made in reply to our request just before the app exited and the mock stopped)."""
    from pf_offboard.app.profiles import PROFILES

    beats = [e.message for e in read_tlog(log_dir / "flight.tlog") if e.direction == "in"
             and e.message.get_type() == "HEARTBEAT" and e.message.get_srcComponent() == 1]  # fmt: skip
    return PROFILES[profile].mode_name(beats[-1].custom_mode)


def outgoing(log_dir: Path) -> list:
    return [e.message for e in read_tlog(log_dir / "flight.tlog") if e.direction == "out"]


def entries(log_dir: Path) -> list:
    return read_tlog(log_dir / "flight.tlog")


def is_mode_request(m) -> bool:
    return m.get_type() == "COMMAND_LONG" and m.command == mavlink2.MAV_CMD_DO_SET_MODE


def is_safe_setpoint(m) -> bool:
    """The app's safe setpoint: zero acceleration (acceleration mode) or a level quaternion with
    the rates ignored (attitude / rates modes); never body rates."""
    if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
        return (m.afx, m.afy, m.afz) == (0.0, 0.0, 0.0) and (m.vx, m.vy, m.vz) == (0.0, 0.0, 0.0)
    if m.get_type() == "SET_ATTITUDE_TARGET":
        w, x, y, z = m.q
        level = abs(x) < 1e-9 and abs(y) < 1e-9 and abs(math.hypot(w, z) - 1.0) < 1e-6
        return not (m.type_mask & 128) and m.type_mask & 7 == 7 and level
    return False
