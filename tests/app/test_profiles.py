"""Autopilot profiles: detection from HEARTBEAT, mode encodings, what each output mode needs."""

import pytest

from pf_offboard.app.profiles import ARDUPILOT, PX4, is_armed, px4_custom_mode, select_profile
from pf_offboard.errors import InputError


def test_detection_and_override() -> None:
    assert select_profile("auto", 12) is PX4
    assert select_profile(None, 3) is ARDUPILOT
    assert select_profile("ardupilot", 12) is ARDUPILOT  # the flag wins
    with pytest.raises(InputError) as info:
        select_profile("auto", 8)
    assert info.value.field == "--autopilot"
    with pytest.raises(InputError):
        select_profile("betaflight", 12)


def test_px4_custom_mode_encoding() -> None:
    # values observed on PX4 SITL (see autopilot-facts.md)
    assert px4_custom_mode(6) == 393216
    assert px4_custom_mode(4, 5) == 84148224  # AUTO.RTL
    assert px4_custom_mode(4, 3) == 50593792  # AUTO.LOITER
    assert PX4.is_offboard(393216)
    assert not PX4.is_offboard(50593792)
    assert PX4.mode_name(50593792) == "AUTO.LOITER"
    assert PX4.hold_custom_mode == 50593792


def test_ardupilot_modes() -> None:
    assert ARDUPILOT.is_offboard(4)
    assert not ARDUPILOT.is_offboard(5)
    assert ARDUPILOT.mode_name(17) == "BRAKE"
    assert (ARDUPILOT.hold.param2, ARDUPILOT.land.param2) == (17, 9)


def test_what_each_output_mode_needs() -> None:
    assert PX4.required_guid_options("rates") == 0
    assert ARDUPILOT.required_guid_options("attitude") == 8
    assert ARDUPILOT.required_guid_options("rates") == 8
    assert ARDUPILOT.required_guid_options("acceleration") == 16
    assert PX4.attitude_rates_ff == (False, False, True)  # PX4 drops roll/pitch FF next to a quaternion
    assert ARDUPILOT.attitude_rates_ff == (True, True, True)
    assert PX4.hover_thrust_param == "MPC_THR_HOVER" and ARDUPILOT.hover_thrust_param == "MOT_THST_HOVER"


def test_armed_flag() -> None:
    assert is_armed(0x91) and not is_armed(0x11)


def test_tilt_from_gravity_by_the_reported_parameter() -> None:
    """PX4 reports MPC_ACC_DECOUPLE (1: tilt from g alone, its default); ArduPilot has no such
    parameter and always tilts from g alone. Unreported or invalid: the autopilot's default."""
    assert PX4.accel_tilt_param == "MPC_ACC_DECOUPLE" and ARDUPILOT.accel_tilt_param is None
    assert PX4.tilts_from_gravity(1.0) and not PX4.tilts_from_gravity(0.0)
    assert PX4.tilts_from_gravity(None) and PX4.tilts_from_gravity(2.0) and PX4.tilts_from_gravity(float("nan"))
    assert ARDUPILOT.tilts_from_gravity(None)


def test_acceleration_tilt_limit_by_the_reported_parameters() -> None:
    """PX4: MPC_TILTMAX_AIR (deg). ArduPilot: PSC_ANGLE_MAX (deg) unless 0, then ANGLE_MAX (cdeg),
    as AC_PosControl::get_lean_angle_max_rad. Not (yet) reported: None; nonsense: ValueError
    naming the parameter."""
    assert PX4.accel_tilt_limit_deg({"MPC_TILTMAX_AIR": 30.0}) == 30.0
    assert PX4.accel_tilt_limit_deg({}) is None
    assert ARDUPILOT.accel_tilt_limit_deg({"PSC_ANGLE_MAX": 25.0}) == 25.0
    assert ARDUPILOT.accel_tilt_limit_deg({"PSC_ANGLE_MAX": 0.0}) is None  # ANGLE_MAX not read yet
    assert ARDUPILOT.accel_tilt_limit_deg({"PSC_ANGLE_MAX": 0.0, "ANGLE_MAX": 3000.0}) == 30.0
    for profile, reported in ((PX4, {"MPC_TILTMAX_AIR": float("nan")}), (PX4, {"MPC_TILTMAX_AIR": 0.0}),
                              (PX4, {"MPC_TILTMAX_AIR": 91.0}), (ARDUPILOT, {"PSC_ANGLE_MAX": -5.0}),
                              (ARDUPILOT, {"PSC_ANGLE_MAX": 0.0, "ANGLE_MAX": 0.0})):  # fmt: skip
        name = next(iter(reported)) if next(iter(reported.values())) != 0.0 or len(reported) == 1 else "ANGLE_MAX"
        with pytest.raises(ValueError, match=name):
            profile.accel_tilt_limit_deg(reported)
