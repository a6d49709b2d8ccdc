"""Vehicle parameters (SI units in the names) and the two presets.

Frames: world NED, body FRD. Motors in X configuration, PX4 quad-X numbering:
0 front-right (CCW), 1 rear-left (CCW), 2 front-left (CW), 3 rear-right (CW).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

GRAVITY_M_S2 = 9.80665


@dataclass(frozen=True)
class CascadeGains:
    """Attitude P + rate P/I/D gains of one axis (units: see field names).

    ``rate_d`` is dimensionless: it multiplies the angular acceleration produced by the motors'
    *current* thrusts (the autopilot knows them from motor-speed feedback, INDI-style), which
    cancels most of the motor lag.
    """

    attitude_p_1_s: float
    rate_p_1_s: float
    rate_i_1_s2: float
    rate_d: float
    rate_limit_rad_s: float
    # > 0: the attitude P becomes a square-root controller above the error at which k·e would
    # ask for more than this angular acceleration (ArduPilot's sqrt_controller) — it keeps large
    # steps from overshooting when the motors saturate. 0: pure P (PX4).
    attitude_accel_max_rad_s2: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"CascadeGains.{f.name}: must be finite and >= 0, got {value!r}")
        if self.rate_limit_rad_s <= 0.0:
            raise ValueError(f"CascadeGains.rate_limit_rad_s: must be > 0, got {self.rate_limit_rad_s!r}")


def cascade_gains_for_poles(
    pole_rad_s: float,
    motor_time_constant_s: float,
    rate_limit_rad_s: float,
    rate_i_fraction: float = 0.0,
    attitude_accel_max_rad_s2: float = 0.0,
) -> CascadeGains:
    """Gains placing the attitude→rate→motor cascade's three closed-loop poles at ``-pole_rad_s``.

    Per axis: α_des = k_p·(ω_sp − ω), ω_sp = k_att·e; motor command u = (1 + k_d)·α_des − k_d·x with
    τ_m·dx/dt = u − x (x: angular acceleration of the motors' present thrust). Characteristic
    polynomial τ_m s³ + (1 + k_d) s² + (1 + k_d) k_p s + (1 + k_d) k_p k_att = τ_m (s + p)³
    (exact when 3·p·τ_m ≥ 1; below that k_d would be negative and is set to 0).
    """
    p, tau = pole_rad_s, motor_time_constant_s
    lead = max(1.0, 3.0 * p * tau)
    rate_p = 3.0 * p * p * tau / lead
    return CascadeGains(
        attitude_p_1_s=p / 3.0,
        rate_p_1_s=rate_p,
        rate_i_1_s2=rate_i_fraction * rate_p,
        rate_d=lead - 1.0,
        rate_limit_rad_s=rate_limit_rad_s,
        attitude_accel_max_rad_s2=attitude_accel_max_rad_s2,
    )


@dataclass(frozen=True)
class VehicleParams:
    """Quadrotor and autopilot parameters. Every field carries its unit in its name.

    ``hover_thrust`` is the *autopilot's* hover-thrust parameter (MPC_THR_HOVER / MOT_THST_HOVER)
    used by the acceleration→thrust mapping; the vehicle's true hover throttle is
    ``1 / thrust_to_weight`` (:attr:`true_hover_thrust`). The presets make them equal.
    """

    name: str
    mass_kg: float
    inertia_xx_kg_m2: float
    inertia_yy_kg_m2: float
    inertia_zz_kg_m2: float
    arm_length_m: float  # centre to motor
    thrust_to_weight: float  # all motors at full thrust / weight
    motor_time_constant_s: float  # first-order lag of each motor's thrust
    motor_idle_fraction: float  # minimum thrust of a running motor, fraction of its maximum
    yaw_torque_per_thrust_m: float  # rotor drag torque / rotor thrust
    drag_1_s: float  # linear drag: force / mass = -drag · (velocity - wind)
    hover_thrust: float  # autopilot parameter, normalised 0..1
    # Autopilot inner loops.
    roll_pitch: CascadeGains
    yaw: CascadeGains
    airmode: bool  # mixer may raise the collective thrust to keep roll/pitch authority
    # Collective-thrust lead against the motors' present thrust (motor-speed feedback): the
    # collective's effective lag becomes motor_time_constant_s / (1 + thrust_lead). 0: plain lag.
    thrust_lead: float
    attitude_loop_hz: float  # attitude controller rate (rate loop and physics run at 1 kHz)
    tilt_max_rad: float  # acceleration mode tilt limit (MPC_TILTMAX_AIR)
    # MPC_ACC_DECOUPLE (PX4 default 1): the tilt ignores the vertical acceleration demand, so the
    # horizontal acceleration flown is a_xy·(g − a_z)/g. False: tilt from the full demand (exact).
    accel_decouple: bool
    thrust_min_norm: float  # acceleration mode thrust floor (MPC_THR_MIN)
    thrust_max_norm: float  # acceleration mode thrust ceiling (MPC_THR_MAX)
    # Autopilot position controller (PositionSetpoint: hold, loiter, land, takeoff, brake).
    position_p_1_s: float
    velocity_p_1_s: float
    velocity_i_1_s2: float
    velocity_max_xy_m_s: float
    velocity_max_up_m_s: float
    velocity_max_down_m_s: float
    land_speed_m_s: float
    # Ground contact.
    crash_speed_m_s: float  # vertical touchdown speed above which `crashed` is set
    ground_friction: float  # Coulomb friction coefficient (dimensionless)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float | int) and not isinstance(value, bool):
                if not math.isfinite(value):
                    raise ValueError(f"VehicleParams.{f.name}: must be finite, got {value!r}")
        positive = (
            "mass_kg", "inertia_xx_kg_m2", "inertia_yy_kg_m2", "inertia_zz_kg_m2", "arm_length_m",
            "motor_time_constant_s", "yaw_torque_per_thrust_m", "attitude_loop_hz", "tilt_max_rad",
            "crash_speed_m_s", "velocity_max_xy_m_s", "velocity_max_up_m_s", "velocity_max_down_m_s",
            "land_speed_m_s",
        )
        for name in positive:
            if getattr(self, name) <= 0.0:
                raise ValueError(f"VehicleParams.{name}: must be > 0, got {getattr(self, name)!r}")
        if self.thrust_to_weight <= 1.0:
            raise ValueError(f"VehicleParams.thrust_to_weight: must be > 1 to fly, got {self.thrust_to_weight!r}")
        if not 0.0 < self.hover_thrust < 1.0:
            raise ValueError(f"VehicleParams.hover_thrust: must be in (0, 1), got {self.hover_thrust!r}")
        if not 0.0 <= self.motor_idle_fraction < 1.0:
            raise ValueError(f"VehicleParams.motor_idle_fraction: must be in [0, 1), got {self.motor_idle_fraction!r}")
        if not 0.0 <= self.thrust_min_norm < self.thrust_max_norm <= 1.0:
            raise ValueError("VehicleParams.thrust_min_norm/thrust_max_norm: need 0 <= min < max <= 1")
        if self.tilt_max_rad >= math.pi / 2:
            raise ValueError(f"VehicleParams.tilt_max_rad: must be < pi/2, got {self.tilt_max_rad!r}")
        if self.drag_1_s < 0.0 or self.ground_friction < 0.0 or self.thrust_lead < 0.0:
            raise ValueError("VehicleParams.drag_1_s/ground_friction/thrust_lead: must be >= 0")
        if 1000.0 % self.attitude_loop_hz > 1e-9 or self.attitude_loop_hz > 1000.0:
            raise ValueError(
                f"VehicleParams.attitude_loop_hz: must divide 1000 (physics rate), got {self.attitude_loop_hz!r}"
            )

    @property
    def weight_n(self) -> float:
        return self.mass_kg * GRAVITY_M_S2

    @property
    def motor_thrust_max_n(self) -> float:
        """Full thrust of ONE motor, newtons."""
        return self.thrust_to_weight * self.weight_n / 4.0

    @property
    def true_hover_thrust(self) -> float:
        """Normalised throttle that really holds the vehicle: 1 / thrust_to_weight."""
        return 1.0 / self.thrust_to_weight

    def with_(self, **changes: object) -> VehicleParams:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)


def _fast() -> VehicleParams:
    tau = 0.015
    return VehicleParams(
        name="fast",
        mass_kg=0.6,
        inertia_xx_kg_m2=1.5e-3,
        inertia_yy_kg_m2=1.5e-3,
        inertia_zz_kg_m2=2.6e-3,
        arm_length_m=0.12,
        thrust_to_weight=3.5,
        motor_time_constant_s=tau,
        motor_idle_fraction=0.02,
        yaw_torque_per_thrust_m=0.016,
        drag_1_s=0.2,
        hover_thrust=1.0 / 3.5,
        roll_pitch=cascade_gains_for_poles(280.0, tau, rate_limit_rad_s=20.0, rate_i_fraction=0.0,
                                           attitude_accel_max_rad_s2=60.0),
        yaw=cascade_gains_for_poles(60.0, tau, rate_limit_rad_s=6.0, rate_i_fraction=0.5,
                                    attitude_accel_max_rad_s2=20.0),
        airmode=False,
        thrust_lead=0.0,
        attitude_loop_hz=250.0,
        tilt_max_rad=math.radians(60.0),
        accel_decouple=False,  # MPC_ACC_DECOUPLE = 0: the acceleration is flown exactly
        thrust_min_norm=0.05,
        thrust_max_norm=1.0,
        position_p_1_s=2.0,
        velocity_p_1_s=4.0,
        velocity_i_1_s2=1.0,
        velocity_max_xy_m_s=5.0,
        velocity_max_up_m_s=3.0,
        velocity_max_down_m_s=1.5,
        land_speed_m_s=0.6,
        crash_speed_m_s=3.0,
        ground_friction=0.8,
    )


def _px4_default() -> VehicleParams:
    tau = 0.03
    return VehicleParams(
        name="px4-default",
        mass_kg=1.5,
        inertia_xx_kg_m2=0.022,
        inertia_yy_kg_m2=0.022,
        inertia_zz_kg_m2=0.04,
        arm_length_m=0.25,
        thrust_to_weight=2.0,
        motor_time_constant_s=tau,
        motor_idle_fraction=0.05,
        yaw_torque_per_thrust_m=0.016,
        drag_1_s=0.3,
        hover_thrust=0.5,
        roll_pitch=CascadeGains(  # MC_ROLL_P 6.5; rate loop ~40 rad/s, damping 0.8
            attitude_p_1_s=6.5, rate_p_1_s=0.03 * 40.0**2, rate_i_1_s2=0.03 * 40.0**2 * 0.3,
            rate_d=2 * 0.8 * 40.0 * 0.03 - 1.0, rate_limit_rad_s=math.radians(220.0),
        ),
        yaw=CascadeGains(  # MC_YAW_P 2.8; rate loop ~20 rad/s
            attitude_p_1_s=2.8, rate_p_1_s=0.03 * 20.0**2, rate_i_1_s2=0.03 * 20.0**2 * 0.3,
            rate_d=0.0, rate_limit_rad_s=math.radians(200.0),
        ),
        airmode=False,
        thrust_lead=0.0,
        attitude_loop_hz=250.0,
        tilt_max_rad=math.radians(45.0),
        accel_decouple=True,
        thrust_min_norm=0.12,
        thrust_max_norm=1.0,
        position_p_1_s=0.95,
        velocity_p_1_s=1.8,
        velocity_i_1_s2=0.4,
        velocity_max_xy_m_s=12.0,
        velocity_max_up_m_s=3.0,
        velocity_max_down_m_s=1.5,
        land_speed_m_s=0.7,
        crash_speed_m_s=3.0,
        ground_friction=0.8,
    )


PRESET_NAMES: tuple[str, ...] = ("fast", "px4-default")


def preset(name: str) -> VehicleParams:
    """The named vehicle: ``"fast"`` (paper-like small quad) or ``"px4-default"`` (mid-size)."""
    if name == "fast":
        return _fast()
    if name == "px4-default":
        return _px4_default()
    raise ValueError(f"preset: unknown vehicle {name!r}; choose one of {', '.join(PRESET_NAMES)}")
