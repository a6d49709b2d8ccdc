"""Value objects of the controller: gains, limits, yaw specification, state and command.

World frame ENU (z up), body FLU, quaternions (w, x, y, z) body-to-world. Units are in the names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from pf_offboard.errors import InputError

GRAVITY_M_S2 = 9.81  # the paper's g
MIN_THRUST_FLOOR_M_S2 = 0.5  # lowest allowed min_thrust_m_s2 (attitude needs |f| > 0)
DEFAULT_SPEED_M_S = 1.0  # eta2_ref when none is given (PathFollower and a config without speed_m_s)
# body-rate feed-forward: on_path (the paper, eqs. 25-28) | any_state (docs/controller.md § 3b)
FEEDFORWARD_MODES = ("on_path", "any_state")
ANY_STATE_NEEDS_NO_COMPENSATION = (
    "any_state needs compensation.enabled: false (with the inner-loop compensation the lag lead "
    "replaces the roll/pitch body-rate feed-forward)"
)


def _finite(name: str, value: float) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise InputError(name, f"must be a finite number, got {value!r}")
    return v


@dataclass(frozen=True)
class Gains:
    """Loop gains as bandwidth [Hz] and damping ratio.

    The defaults are what ``gains: auto`` derives for :meth:`VehicleModel.typical` (a typical PX4 /
    ArduPilot inner loop: lag 0.1 s, delay 0.1 s) with the default :class:`Compensation`'s phase
    margins (``pf_offboard.control.tuning.gains_for_vehicle``; a test keeps them equal). The
    paper's 6 Hz / 0.7 and 4 Hz / 0.8 are :meth:`paper`: they need an ideal inner loop.

    Transversal (xi, phi): ``u = -kp e - kd e_dot`` with ``w = 2 pi f``, ``kp = w^2``,
    ``kd = 2 zeta w``. Tangential: velocity loop ``u_eta = kd_t (eta2_ref - eta2)``,
    ``kd_t = 2 zeta_t w_t`` (see docs/controller.md).
    """

    transversal_bandwidth_hz: float = 0.927
    transversal_damping: float = 1.0
    tangential_bandwidth_hz: float = 1.475
    tangential_damping: float = 1.0

    @classmethod
    def paper(cls) -> Gains:
        """The paper's gains (6 Hz / 0.7 transversal, 4 Hz / 0.8 tangential). They assume the
        paper's ideal inner loop (an acceleration flown at once); on a real PX4 / ArduPilot inner
        loop they leave a negative phase margin and limit-cycle."""
        return cls(6.0, 0.7, 4.0, 0.8)

    def __post_init__(self) -> None:
        for name in ("transversal_bandwidth_hz", "transversal_damping", "tangential_bandwidth_hz", "tangential_damping"):
            v = _finite(name, getattr(self, name))
            if v <= 0.0:
                raise InputError(name, f"must be > 0, got {v}")
        for name in ("transversal_bandwidth_hz", "tangential_bandwidth_hz"):
            if getattr(self, name) > 50.0:
                raise InputError(name, f"must be <= 50 Hz, got {getattr(self, name)}")
        for name in ("transversal_damping", "tangential_damping"):
            if getattr(self, name) > 5.0:
                raise InputError(name, f"must be <= 5, got {getattr(self, name)}")

    @classmethod
    def from_bandwidth(
        cls, transversal_hz: float, tangential_hz: float | None = None, *, damping: float = 1.0
    ) -> Gains:
        """Both loops from bandwidths (Hz) with one damping ratio (tangential: same as transversal)."""
        return cls(transversal_hz, damping, transversal_hz if tangential_hz is None else tangential_hz, damping)

    @property
    def transversal_kp(self) -> float:
        """1/s^2."""
        w = 2.0 * math.pi * self.transversal_bandwidth_hz
        return w * w

    @property
    def transversal_kd(self) -> float:
        """1/s."""
        return 2.0 * self.transversal_damping * 2.0 * math.pi * self.transversal_bandwidth_hz

    @property
    def tangential_kd(self) -> float:
        """1/s (tangential velocity-loop gain)."""
        return 2.0 * self.tangential_damping * 2.0 * math.pi * self.tangential_bandwidth_hz

    @property
    def tangential_kp(self) -> float:
        """1/s^2, used only to stop at the end of an open path."""
        w = 2.0 * math.pi * self.tangential_bandwidth_hz
        return w * w


@dataclass(frozen=True)
class Limits:
    """What the vehicle can do. f = a + g e_z is the mass-normalised thrust vector.

    Enforced on every command: angle of f from vertical <= ``max_tilt_deg``,
    ``|f| <= max_thrust_m_s2``, vertical component ``f_z >= min_thrust_m_s2`` (which implies
    ``|f| >= min_thrust_m_s2``), and the commanded speed of approach to the path <=
    ``max_approach_speed_m_s``.

    ``max_tilt_rate_rad_s`` is the slew limit: the rate (rad/s) at which the controller plans to
    turn the thrust vector, i.e. a jerk ``J = g * max_tilt_rate_rad_s``. Velocity corrections are
    shaped (square-root law beyond ``J/kd^2``) so that the demand never swings faster than that;
    near the path the paper's linear laws act unchanged. Choose about 1/3-1/2 of what the vehicle
    really slews. ``None``: no shaping (the paper's laws everywhere; ideal inner loop only).

    ``max_tangential_accel_m_s2`` is the start ramp's acceleration: after activation (``reset()``)
    the reference speed rises from the speed along the path at this rate over the distance
    travelled, with its feed-forward, the speed loop's correction bounded by it meanwhile; once the
    reference is reached the speed loop is never bounded (a static bound fought the steady state:
    PX4 SIH's drag at 1.5 m/s equals 1.5 m/s^2). An unramped start from rest leans 38 deg at
    1.5 m/s, which tripped the tilt watchdog on a real ArduCopter SITL. ``None``: no ramp (the
    paper's ideal inner loop).
    """

    max_tilt_deg: float = 45.0  # PX4 MPC_TILTMAX_AIR default; the shipped configs flew 45-50 on both real SITLs
    min_thrust_m_s2: float = 2.0
    max_thrust_m_s2: float = 20.0
    max_approach_speed_m_s: float = 2.0
    max_tilt_rate_rad_s: float | None = 2.0
    max_tangential_accel_m_s2: float | None = 1.5

    def __post_init__(self) -> None:
        for name in ("max_tilt_deg", "min_thrust_m_s2", "max_thrust_m_s2", "max_approach_speed_m_s"):
            _finite(name, getattr(self, name))
        if self.max_tilt_rate_rad_s is not None:
            rate = _finite("max_tilt_rate_rad_s", self.max_tilt_rate_rad_s)
            if not 0.1 <= rate <= 100.0:
                raise InputError("max_tilt_rate_rad_s", f"must be in [0.1, 100] rad/s (or None: no slew limit), got {rate}")
        if self.max_tangential_accel_m_s2 is not None:
            acc = _finite("max_tangential_accel_m_s2", self.max_tangential_accel_m_s2)
            if not 0.1 <= acc <= 100.0:
                raise InputError("max_tangential_accel_m_s2", f"must be in [0.1, 100] m/s^2 (or None: no bound), got {acc}")
        if not 0.0 < self.max_tilt_deg <= 80.0:
            raise InputError("max_tilt_deg", f"must be in (0, 80] deg, got {self.max_tilt_deg}")
        # > 0: at zero thrust the attitude (body z along f) is undefined
        if not MIN_THRUST_FLOOR_M_S2 <= self.min_thrust_m_s2 <= 0.9 * GRAVITY_M_S2:
            raise InputError(
                "min_thrust_m_s2",
                f"must be in [{MIN_THRUST_FLOOR_M_S2}, {0.9 * GRAVITY_M_S2:.3f}] m/s^2, got {self.min_thrust_m_s2}",
            )
        if not 1.1 * GRAVITY_M_S2 <= self.max_thrust_m_s2 <= 100.0:
            raise InputError(
                "max_thrust_m_s2", f"must be in [{1.1 * GRAVITY_M_S2:.3f}, 100] m/s^2 (above hover), got {self.max_thrust_m_s2}"
            )
        if not 0.05 <= self.max_approach_speed_m_s <= 20.0:
            raise InputError("max_approach_speed_m_s", f"must be in [0.05, 20] m/s, got {self.max_approach_speed_m_s}")

    def with_tilt_at_most(self, max_tilt_deg: float) -> Limits:
        """These limits with ``max_tilt_deg`` lowered to ``max_tilt_deg`` (an autopilot's own tilt
        limit); ``self`` when it is not lower."""
        return replace(self, max_tilt_deg=float(max_tilt_deg)) if max_tilt_deg < self.max_tilt_deg else self

    @property
    def tan_tilt(self) -> float:
        return math.tan(math.radians(self.max_tilt_deg))

    @property
    def guaranteed_accel_m_s2(self) -> float:
        """Radius of the ball of accelerations around hover that is entirely feasible (m/s^2)."""
        g = GRAVITY_M_S2
        # distance from (0, 0, g) to the tilt cone, to the max-thrust sphere and to f_z = min thrust
        cone = g * math.sin(math.radians(self.max_tilt_deg))
        return min(cone, self.max_thrust_m_s2 - g, g - self.min_thrust_m_s2)


@dataclass(frozen=True)
class VehicleModel:
    """Identified response of the vehicle + autopilot inner loops to an acceleration setpoint.

    Per axis group (horizontal x/y, vertical z; the vertical dead time is ``accel_delay_z_s`` when
    given, else ``accel_delay_s``), world frame, velocity v and wind w:
    ``dv/dt = a + d``, ``a(s) = gain * exp(-delay s) / (lag s + 1) * a_sp(s) - drag * (v - w)``
    (``d``: what the model does not explain, estimated by the disturbance observer).
    ``rate_time_constant_s``: the autopilot's closed body-rate loop (first-order), used by the
    ``rates`` output's attitude loop. Written by ``pf-offboard identify`` as the ``vehicle:``
    config section; the defaults are an ideal inner loop (the paper's assumption).
    """

    accel_lag_xy_s: float = 0.0
    accel_lag_z_s: float = 0.0
    accel_delay_s: float = 0.0
    accel_gain_xy: float = 1.0
    accel_gain_z: float = 1.0
    drag_xy_1_s: float = 0.0
    drag_z_1_s: float = 0.0
    rate_time_constant_s: float = 0.0
    accel_delay_z_s: float | None = None  # vertical dead time if it differs (None: accel_delay_s)

    @classmethod
    def typical(cls) -> VehicleModel:
        """What a config without a ``vehicle:`` section assumes: a typical PX4 / ArduPilot
        multicopter (lag 0.1 s, delay 0.1 s, unit gain; drag is left to the observer). Its rate
        loop's 0.0625 s gives ``rates`` output an attitude loop of 4 x that = 0.25 s: on the
        px4-sih mock 0.2 s flew 5-6 cm and 18-34 cm/s (speed loop oscillating), 0.25 s 1.9-3.1 cm,
        2.2-7.8 cm/s, 0.3 s worse again; the arducopter mock flies 0.25 s as well as before."""
        return cls(accel_lag_xy_s=0.1, accel_lag_z_s=0.05, accel_delay_s=0.1, rate_time_constant_s=0.0625)

    @property
    def vertical_delay_s(self) -> float:
        """The vertical group's dead time (s): ``accel_delay_z_s``, else ``accel_delay_s``."""
        return self.accel_delay_s if self.accel_delay_z_s is None else self.accel_delay_z_s

    def __post_init__(self) -> None:
        bounds = {
            "accel_lag_xy_s": (0.0, 2.0),
            "accel_lag_z_s": (0.0, 2.0),
            "accel_delay_s": (0.0, 1.0),
            "accel_gain_xy": (0.2, 5.0),
            "accel_gain_z": (0.2, 5.0),
            "drag_xy_1_s": (0.0, 10.0),
            "drag_z_1_s": (0.0, 10.0),
            "rate_time_constant_s": (0.0, 1.0),
        }
        if self.accel_delay_z_s is not None:
            bounds["accel_delay_z_s"] = (0.0, 1.0)
        for name, (lo, hi) in bounds.items():
            v = _finite(f"vehicle.{name}", getattr(self, name))
            if not lo <= v <= hi:
                raise InputError(f"vehicle.{name}", f"must be in [{lo:g}, {hi:g}], got {v:g}")
            object.__setattr__(self, name, v)


@dataclass(frozen=True)
class Compensation:
    """Inner-loop compensation settings (:class:`~pf_offboard.control.compensator.InnerLoopCompensator`:
    disturbance observer + delay predictor + gain/drag inversion + integral action, from a
    :class:`VehicleModel`), and the phase margins ``gains: auto`` keeps on that model.

    The defaults are the shipped choice (the ``compensation:`` section's defaults too).
    ``Compensation.off()``: the paper's law as published (no observer, predictor or integral).
    """

    enabled: bool = True
    observer_rad_s: float = 8.0  # disturbance-observer poles (rad/s)
    integral_rad_s: float = 1.0  # integral action on speed and transversal offsets (rad/s)
    phase_margin_deg: float = 30.0  # transversal loops, for gains: auto
    tangential_phase_margin_deg: float = 40.0  # the speed loop's, for gains: auto
    # A shorter dead time readily, a longer one with its gain and drag once settled and decisive
    # (docs/controller.md, Identifying the inner loop in flight); both engines (the scalar
    # follower, sim/batch) identify alike
    identify_online: bool = True  # without a vehicle: section, identify the inner loop's dead time, gain and drag in flight

    def __post_init__(self) -> None:
        for name, lo, hi in (("observer_rad_s", 0.0, 50.0), ("integral_rad_s", 0.0, 10.0),
                             ("phase_margin_deg", 10.0, 80.0), ("tangential_phase_margin_deg", 10.0, 80.0)):  # fmt: skip
            v = _finite(f"compensation.{name}", getattr(self, name))
            if not lo <= v <= hi:
                raise InputError(f"compensation.{name}", f"must be in [{lo:g}, {hi:g}], got {v:g}")

    @classmethod
    def off(cls) -> Compensation:
        """No compensation: the paper's stateless law (for an ideal inner loop)."""
        return cls(enabled=False)


YAW_MODES = ("constant", "hold", "tangent", "table")


@dataclass(frozen=True)
class YawSpec:
    """Yaw as a function of arclength eta1 (ENU yaw: from east, counter-clockwise, radians).

    - ``constant`` (the default): ``yaw_rad``.
    - ``hold``: the heading the vehicle has when following starts, held constant — no turn at
      activation. The app sets it at activation from the attitude estimate
      (``PathFollower.hold_heading``); until a heading is given, ``yaw_rad``.
    - ``tangent``: heading of the direction of travel (``sign(speed) * t``) plus ``yaw_rad``.
    - ``table``: ``table_eta1_m_yaw_rad`` = ((eta1_m, yaw_rad), ...), interpolated by a C2 cubic
      spline (periodic on closed paths, angles unwrapped; natural on open paths, extended
      linearly beyond the table).
    """

    mode: str = "constant"
    yaw_rad: float = 0.0
    table_eta1_m_yaw_rad: tuple[tuple[float, float], ...] = field(default=())

    def __post_init__(self) -> None:
        if self.mode not in YAW_MODES:
            raise InputError("yaw.mode", f"must be one of {', '.join(YAW_MODES)}, got {self.mode!r}")
        _finite("yaw.yaw_rad", self.yaw_rad)
        table = tuple((float(a), float(b)) for a, b in self.table_eta1_m_yaw_rad)
        object.__setattr__(self, "table_eta1_m_yaw_rad", table)
        for i, (s, y) in enumerate(table):
            if not (math.isfinite(s) and math.isfinite(y)):
                raise InputError(f"yaw.table[{i}]", "must be finite numbers")
        if self.mode == "table":
            if len(table) < 2:
                raise InputError("yaw.table", "needs at least 2 (eta1_m, yaw) entries")
            for i in range(1, len(table)):
                if table[i][0] <= table[i - 1][0]:
                    raise InputError(f"yaw.table[{i}]", "eta1 values must be strictly increasing")

    @classmethod
    def hold(cls) -> YawSpec:
        return cls("hold")

    @classmethod
    def constant(cls, yaw_rad: float = 0.0) -> YawSpec:
        return cls("constant", yaw_rad)

    @classmethod
    def tangent(cls, offset_rad: float = 0.0) -> YawSpec:
        return cls("tangent", offset_rad)

    @classmethod
    def table(cls, points: tuple[tuple[float, float], ...] | list[list[float]]) -> YawSpec:
        return cls("table", 0.0, tuple((float(a), float(b)) for a, b in points))


class TransverseState(NamedTuple):
    """T(x) of eq. (20): tangential position (m) and speed (m/s), transversal offsets (m) and rates (m/s)."""

    eta1: float
    eta2: float
    xi1: float
    xi2: float
    phi1: float
    phi2: float


class Saturation(NamedTuple):
    """Which limit shaped the command this step."""

    tangential: bool  # tangential acceleration reduced to make room for the transversal correction
    transversal: bool  # transversal correction itself reduced (acceleration bound or no room)
    tilt: bool  # thrust vector on the tilt cone
    thrust: bool  # thrust on its min or max bound
    approach_speed: bool  # desired approach speed clipped to max_approach_speed_m_s


@dataclass(frozen=True)
class Command:
    """One control output. World ENU, body FLU."""

    acceleration: NDArray[np.float64]  # (3,) m/s^2, gravity excluded (the a of eq. 1)
    thrust: float  # mass-normalised collective thrust |f|, m/s^2
    attitude: NDArray[np.float64]  # (4,) unit quaternion (w, x, y, z) body FLU -> world ENU
    body_rates: NDArray[np.float64]  # (3,) rad/s body FLU (the feed-forward omega_ff)
    yaw: float  # rad, ENU
    yaw_rate: float  # rad/s about world z (up)
    state: TransverseState
    lam: float  # path parameter of the closest point
    cross_track_m: float  # distance to the closest point of the path
    saturation: Saturation
    eta2_ref_m_s: float = math.nan  # the reference speed eta2_ref(eta1) at state.eta1 (with a compensator the measured state's; the law tracked it at the prediction's)
