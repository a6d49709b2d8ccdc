"""Small builders shared by the app's unit tests (real pymavlink messages, real Command objects)."""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from pf_offboard.control import Command, Saturation, TransverseState

NO_SAT = Saturation(False, False, False, False, False)


def command(
    acceleration=(0.5, -0.25, 0.1),
    thrust: float = 10.0,
    attitude=(1.0, 0.0, 0.0, 0.0),
    body_rates=(0.1, -0.2, 0.3),
    yaw: float = 0.3,
    yaw_rate: float = 0.05,
) -> Command:
    q = np.asarray(attitude, dtype=float)
    return Command(
        acceleration=np.asarray(acceleration, dtype=float),
        thrust=thrust,
        attitude=q / np.linalg.norm(q) if np.all(np.isfinite(q)) else q,
        body_rates=np.asarray(body_rates, dtype=float),
        yaw=yaw,
        yaw_rate=yaw_rate,
        state=TransverseState(1.0, -1.5, 0.01, 0.0, -0.02, 0.0),
        lam=0.5,
        cross_track_m=math.hypot(0.01, 0.02),
        saturation=NO_SAT,
    )


def local_position(t_ms: int, pos_ned=(1.0, 2.0, -3.0), vel_ned=(0.1, 0.2, -0.3)):
    return mavlink2.MAVLink_local_position_ned_message(t_ms, *pos_ned, *vel_ned)


def attitude_quaternion(t_ms: int, q_ned_frd=(1.0, 0.0, 0.0, 0.0), rates_frd=(0.0, 0.0, 0.0)):
    return mavlink2.MAVLink_attitude_quaternion_message(t_ms, *q_ned_frd, *rates_frd, [0.0, 0.0, 0.0, 0.0])


def odometry(t_us: int, pos_ned, vel, q_ned_frd=(1.0, 0.0, 0.0, 0.0), child_frame=12, reset_counter=0, frame=1):
    return mavlink2.MAVLink_odometry_message(
        t_us, frame, child_frame, *pos_ned, list(q_ned_frd), *vel, 0.0, 0.0, 0.0,
        [math.nan] * 21, [math.nan] * 21, reset_counter, 0, 100,
    )  # fmt: skip


def quat_about(axis, angle_rad: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    return np.concatenate([[math.cos(angle_rad / 2)], math.sin(angle_rad / 2) * a])
