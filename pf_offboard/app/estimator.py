"""Vehicle state from MAVLink telemetry, in the core's frames (world ENU, body FLU).

Pure: messages in, :class:`StateEstimate` out; no clocks, no I/O. The one place where telemetry
(NED / FRD) is turned into the core's frames, always through :mod:`pf_offboard.frames`.

Sources: position + velocity from LOCAL_POSITION_NED or ODOMETRY (whichever arrives first is
used from then on, so one sample is never counted twice); attitude and body rates from
ATTITUDE_QUATERNION (or ODOMETRY's pose when that is the source). Non-finite or malformed
samples are rejected and counted, never passed to the controller; so are duplicated or reordered
ones (a sample time not newer than the last), which are not fresh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pf_offboard import frames

MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_BODY_FRD = 12

SOURCES = ("auto", "local_position", "odometry")


@dataclass(frozen=True)
class StateEstimate:
    """Latest vehicle state, core frames. ``time_s`` is the autopilot's clock (s since boot)."""

    time_s: float
    position_enu_m: NDArray[np.float64]
    velocity_enu_m_s: NDArray[np.float64]
    q_enu_flu: NDArray[np.float64] | None  # (w, x, y, z) body FLU -> world ENU; None until known
    rates_flu_rad_s: NDArray[np.float64] | None
    sample: int  # count of position/velocity samples accepted so far


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def rotate(q_wxyz: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotate a vector by a unit quaternion (body -> world, same frame convention both sides)."""
    w, x, y, z = q_wxyz
    u = np.array([x, y, z])
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _unit_quat(q: Any) -> NDArray[np.float64] | None:
    a = np.asarray(q, dtype=float)
    if a.shape != (4,) or not np.all(np.isfinite(a)):
        return None
    n = float(np.linalg.norm(a))
    if abs(n - 1.0) > 1e-2:  # MAVLink quaternions are unit; anything else is corrupt
        return None
    return a / n


# A sample not newer than the last one, by less than this, is a duplicated or reordered datagram
# (not fresh: it must not step the controller or feed the stale-state watchdog). Older by more,
# the autopilot's boot clock restarted (a reboot): accepted, following starts over from it.
REORDER_WINDOW_S = 10.0


class Estimator:
    """Fold telemetry into a :class:`StateEstimate`.

    :meth:`on_message` returns True when the message brought a fresh position/velocity sample
    (the pipeline steps the controller exactly then). ``reset_pending`` turns True when ODOMETRY
    reports an estimator reset (``reset_counter`` changed): the caller resets the follower's warm
    start, since the position may have jumped.
    """

    def __init__(self, source: str = "auto") -> None:
        if source not in SOURCES:
            raise ValueError(f"state source must be one of {SOURCES}, got {source!r}")
        self._source = source
        self._q_ned_frd: NDArray[np.float64] | None = None
        self._rates_frd: NDArray[np.float64] | None = None
        self._latest: StateEstimate | None = None
        self._reset_counter: int | None = None
        self.samples = 0
        self.rejected = 0
        self.reset_pending = False

    @property
    def source(self) -> str:
        return self._source

    @property
    def latest(self) -> StateEstimate | None:
        return self._latest

    def on_message(self, msg: Any) -> bool:
        kind = msg.get_type()
        if kind == "ATTITUDE_QUATERNION":
            self._attitude(msg)
            return False
        if kind == "LOCAL_POSITION_NED" and self._source in ("auto", "local_position"):
            return self._local_position(msg)
        if kind == "ODOMETRY" and self._source in ("auto", "odometry"):
            return self._odometry(msg)
        return False

    def _attitude(self, msg: Any) -> None:
        q = _unit_quat((msg.q1, msg.q2, msg.q3, msg.q4))
        rates = (msg.rollspeed, msg.pitchspeed, msg.yawspeed)
        if q is None or not _finite(*rates):
            self.rejected += 1
            return
        self._q_ned_frd = q
        self._rates_frd = np.array(rates, dtype=float)

    def _accept(self, time_s: float, pos_ned: NDArray[np.float64], vel_ned: NDArray[np.float64], source: str) -> bool:
        if self._source == "auto":
            self._source = source  # lock onto the first source seen
        self.samples += 1
        q = None if self._q_ned_frd is None else frames.quat_ned_frd_to_enu_flu(self._q_ned_frd)
        rates = None if self._rates_frd is None else frames.frd_to_flu(self._rates_frd)
        self._latest = StateEstimate(
            time_s=time_s,
            position_enu_m=frames.ned_to_enu(pos_ned),
            velocity_enu_m_s=frames.ned_to_enu(vel_ned),
            q_enu_flu=q,
            rates_flu_rad_s=rates,
            sample=self.samples,
        )
        return True

    def _not_newer(self, time_s: float) -> bool:
        """True (and counted as rejected) for a duplicated or reordered sample."""
        last = self._latest
        if last is not None and 0.0 <= last.time_s - time_s < REORDER_WINDOW_S:
            self.rejected += 1
            return True
        return False

    def _local_position(self, msg: Any) -> bool:
        values = (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz)
        if self._not_newer(msg.time_boot_ms * 1e-3):
            return False
        if not _finite(*values):
            self.rejected += 1
            return False
        return self._accept(
            msg.time_boot_ms * 1e-3, np.array(values[:3]), np.array(values[3:]), "local_position"
        )

    def _odometry(self, msg: Any) -> bool:
        if msg.frame_id != MAV_FRAME_LOCAL_NED:  # LOCAL_FRD is heading-aligned, not NED
            self.rejected += 1
            return False
        if self._not_newer(msg.time_usec * 1e-6):
            return False
        pos = np.array((msg.x, msg.y, msg.z), dtype=float)
        vel = np.array((msg.vx, msg.vy, msg.vz), dtype=float)
        q = _unit_quat(msg.q)
        rates = np.array((msg.rollspeed, msg.pitchspeed, msg.yawspeed), dtype=float)
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(vel))) or q is None:
            self.rejected += 1
            return False
        if msg.child_frame_id == MAV_FRAME_BODY_FRD:
            vel = rotate(q, vel)  # PX4 reports ODOMETRY velocity in the body frame
        self._q_ned_frd = q
        if np.all(np.isfinite(rates)):
            self._rates_frd = rates
        counter = int(msg.reset_counter)
        if self._reset_counter is not None and counter != self._reset_counter:
            self.reset_pending = True
        self._reset_counter = counter
        return self._accept(msg.time_usec * 1e-6, pos, vel, "odometry")
