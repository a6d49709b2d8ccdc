"""identify on logs of a vehicle that obeys the fitted model exactly; the pieces on their own."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pf_offboard.identify import identify, load_log
from pf_offboard.identify.fit import delayed, lag_increments, lagged

from .synthetic import Truth, write_tlog


@pytest.fixture(scope="module")
def truth_log(tmp_path_factory):
    truth = Truth()
    # the "SITL" clock runs 1.5 % slower than the wall clock: the boot clock must be recovered
    return truth, write_tlog(tmp_path_factory.mktemp("syn") / "flight.tlog", truth, clock_rate=1.015)


def test_recovers_every_parameter_of_an_exact_first_order_vehicle(truth_log) -> None:
    truth, path = truth_log
    log = load_log(path)
    assert log.clock_slope == pytest.approx(1.015, abs=1e-4)
    ident = identify(log.segments)
    xy, z = ident.xy, ident.z
    assert xy.lag_s == pytest.approx(truth.lag_xy_s, abs=0.005)
    assert z.lag_s == pytest.approx(truth.lag_z_s, abs=0.005)
    assert xy.delay_s == pytest.approx(truth.delay_s, abs=0.005)
    assert z.delay_s == pytest.approx(truth.delay_s, abs=0.005)
    assert xy.gain == pytest.approx(truth.gain_xy, rel=0.02)
    assert z.gain == pytest.approx(truth.gain_z, rel=0.02)
    assert xy.drag_1_s == pytest.approx(truth.drag_xy_1_s, rel=0.03)
    assert z.drag_1_s == pytest.approx(truth.drag_z_1_s, rel=0.03)
    assert xy.bias_m_s2 == pytest.approx(truth.bias_enu_m_s2[:2], abs=0.02)
    assert z.bias_m_s2 == pytest.approx(truth.bias_enu_m_s2[2:], abs=0.02)
    assert xy.r2 > 0.999 and z.r2 > 0.999 and xy.nrmse < 0.05


def test_the_vertical_is_fitted_along_the_measured_tilt(tmp_path) -> None:
    """A thrust-vector vehicle (horizontal part lagging like the attitude loop, magnitude like the
    motors; identify's vertical model) with its attitude logged: every vertical parameter comes
    back. Read without the attitude (u = a_sp,z), the same log fits visibly worse: the coupling is
    unexplained (here the steps are independent per axis, so it is noise to that fit; on a path,
    where climbs and turns go together, it became vertical lag: docs/identify.md, *Vertical*)."""
    truth = replace(Truth(), lag_xy_s=0.15, lag_z_s=0.03)
    log = load_log(write_tlog(tmp_path / "tilted.tlog", truth, amplitude_m_s2=3.0, tilt_coupled=True))
    assert all(s.thrust_axis_up is not None for s in log.segments)
    assert min(float(s.thrust_axis_up.min()) for s in log.segments) < 0.95  # tilts beyond 18 degrees
    ident = identify(log.segments)
    z = ident.z
    assert z.measured_tilt_share == 1.0 and ident.xy.measured_tilt_share == 0.0
    assert z.lag_s == pytest.approx(truth.lag_z_s, abs=0.005)
    assert z.delay_s == pytest.approx(truth.delay_s, abs=0.005)
    assert z.gain == pytest.approx(truth.gain_z, rel=0.02)
    assert z.drag_1_s == pytest.approx(truth.drag_z_1_s, rel=0.03)
    assert z.r2 > 0.999
    assert ident.xy.lag_s == pytest.approx(truth.lag_xy_s, abs=0.005)
    plain = identify([replace(s, thrust_axis_up=None) for s in log.segments]).z
    assert plain.measured_tilt_share == 0.0
    assert plain.nrmse > 3.0 * z.nrmse and plain.r2 < z.r2


def test_a_different_vehicle_gives_different_values(tmp_path) -> None:
    # the fit follows the data (not a default): a slow, draggy vehicle
    truth = replace(Truth(), lag_xy_s=0.3, drag_xy_1_s=1.2, gain_xy=0.7)
    ident = identify(load_log(write_tlog(tmp_path / "slow.tlog", truth, seed=3)).segments)
    assert ident.xy.rise_63_s == pytest.approx(truth.lag_xy_s + truth.delay_s, rel=0.08)
    assert ident.xy.drag_1_s == pytest.approx(1.2, rel=0.05)
    assert ident.xy.gain == pytest.approx(0.7, rel=0.05)


def test_samples_before_offboard_are_not_used(tmp_path) -> None:
    path = write_tlog(tmp_path / "late.tlog", duration_s=20.0, offboard_from_s=8.0)
    log = load_log(path)
    assert len(log.segments) == 1
    assert log.segments[0].time_s[0] >= 8.0
    assert log.duration_s == pytest.approx(12.0, abs=0.3)


@pytest.mark.parametrize("clock_rate", [0.1, 0.25, 4.0])
def test_a_lockstep_clock_far_from_real_time_keeps_the_whole_flight(tmp_path, clock_rate) -> None:
    # a lockstep simulator's boot clock runs at any multiple of wall-clock time (the mock over
    # loopback: several times faster): the setpoints' boot stamps must still be recognised (by the
    # log's order, not by a wall-clock line), and the whole OFFBOARD stretch kept
    path = write_tlog(tmp_path / "lockstep.tlog", duration_s=20.0, offboard_from_s=4.0, clock_rate=clock_rate)
    log = load_log(path)
    assert log.clock_slope == pytest.approx(clock_rate, rel=1e-3)
    assert len(log.segments) == 1
    assert log.segments[0].time_s[0] >= 4.0
    assert log.duration_s == pytest.approx(16.0, abs=0.3)


def _fit(group: str, lag: float, delay: float):
    """An AxisFit with these dynamics (gain 1, drag 0.5, R^2 0.99)."""
    from pf_offboard.identify.fit import AxisFit

    return AxisFit(group, lag, delay, 1.0, 0.5, (0.0,), 0.99, 0.1, 100, 1.0)


def test_vehicle_model_writes_one_delay_for_a_faster_vertical_group() -> None:
    from pf_offboard.identify.fit import Identification

    xy = _fit("xy", 0.15, 0.05)
    # a vertical rise (0.03 s) inside the horizontal dead time: the horizontal delay, no lag
    m = Identification(xy, _fit("z", 0.02, 0.01), None, 20.0, ()).vehicle_model()
    assert m.accel_delay_s == pytest.approx(0.05) and m.accel_delay_z_s is None
    assert m.accel_lag_xy_s == pytest.approx(0.15) and m.accel_lag_z_s == 0.0
    # a longer vertical rise (0.11 s) is kept: the horizontal delay plus the rest as lag
    m = Identification(xy, _fit("z", 0.10, 0.01), None, 20.0, ()).vehicle_model()
    assert m.accel_delay_z_s is None and m.accel_delay_s + m.accel_lag_z_s == pytest.approx(0.11)
    # a slower vertical group keeps its own delay (the compensator holds x/y back to it)
    m = Identification(xy, _fit("z", 0.02, 0.08), None, 20.0, ()).vehicle_model()
    assert m.accel_delay_z_s == pytest.approx(0.08) and m.accel_lag_z_s == pytest.approx(0.02)
    # negative drag (not resolved) is written as 0, never as an invalid section
    ident2 = Identification(replace(_fit("xy", 0.1, 0.0), drag_1_s=-0.05), _fit("z", 0.0, 0.0), None, 20.0, ())
    assert ident2.vehicle_model().drag_xy_1_s == 0.0


def test_lag_and_delay_filters() -> None:
    dt = 0.01
    u = np.zeros((100, 1))
    u[10:] = 1.0
    y = lagged(u, dt, 0.1)
    # 63 % one time constant after the step (exact discretisation of a held step)
    assert y[20, 0] == pytest.approx(1.0 - np.exp(-1.0), abs=1e-9)
    assert y[10, 0] == 0.0  # the step is applied from t_10 on: nothing yet at t_10
    assert lagged(u, dt, 0.0) is u
    # the interval integrals add up to the exact integral of the continuous response
    inc = lag_increments(u, dt, 0.1)
    t_end = 0.9  # from the step at 0.1 s to 1.0 s
    assert inc.sum() == pytest.approx(t_end - 0.1 * (1.0 - np.exp(-t_end / 0.1)), abs=1e-12)
    d = delayed(u, dt, 0.025)  # the step moves to t = 0.125 s: interval [0.12, 0.13) is half on
    assert d[11, 0] == 0.0 and d[12, 0] == pytest.approx(0.5) and d[13, 0] == 1.0


def test_written_section_replaces_a_kept_vertical_delay_with_null() -> None:
    """Re-identifying into a config whose section has ``accel_delay_z_s``: a faster vertical group
    writes ``null`` (the horizontal delay), not the old value; fields the fit did not determine
    (the rate loop) are kept; the text loads as a VehicleModel."""
    import yaml

    from pf_offboard.control import VehicleModel
    from pf_offboard.identify.fit import Identification
    from pf_offboard.identify.report import vehicle_yaml

    ident = Identification(_fit("xy", 0.10, 0.14), _fit("z", 0.04, 0.04), None, 20.0, ())
    text = vehicle_yaml(ident, keep={"accel_delay_z_s": 0.04, "rate_time_constant_s": 0.05})
    section = yaml.safe_load(text)["vehicle"]
    assert section["accel_delay_z_s"] is None and section["accel_lag_z_s"] == 0.0
    assert section["rate_time_constant_s"] == 0.05
    assert VehicleModel(**section).accel_delay_z_s is None


def test_an_autopilot_tilting_from_gravity_is_fitted_through_its_mapping(tmp_path) -> None:
    """PX4 (MPC_ACC_DECOUPLE 1, its default) flies a_xy (g + a_up) / g for a setpoint a: identify
    fits the vehicle to that, not to the setpoint as sent; read as sent, the same log fits worse."""
    truth = Truth()
    path = write_tlog(tmp_path / "flight.tlog", truth, amplitude_m_s2=3.0, tilt_from_gravity=True)
    xy = identify(load_log(path).segments).xy
    assert xy.gain == pytest.approx(truth.gain_xy, rel=0.02)
    assert xy.lag_s == pytest.approx(truth.lag_xy_s, abs=0.005)
    assert xy.r2 > 0.999
    # the same log with the autopilot saying it flies the whole demand (MPC_ACC_DECOUPLE 0)
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from pf_offboard.logs.tlog import TlogWriter, read_tlog

    misread = tmp_path / "misread.tlog"
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    entries = read_tlog(path)
    with TlogWriter.open(misread) as out:
        param = mavlink.MAVLink_param_value_message(b"MPC_ACC_DECOUPLE", 0.0, mavlink.MAV_PARAM_TYPE_INT32, 1, 0)
        out.write(param.pack(mav), entries[0].time_unix_s)
        for e in entries:
            out.write(e.message.get_msgbuf(), e.time_unix_s)
    wrong = identify(load_log(misread).segments).xy
    assert 1.0 - wrong.r2 > 5.0 * (1.0 - xy.r2)


def test_a_fit_without_quality_windows_is_not_flyable() -> None:
    """R^2 is measured over 0.6 s windows; active stretches too short for any (1.0-1.2 s, each
    with 0.6 s of filter warm-up) leave it unmeasured (NaN), which the gate treats as poor."""
    import dataclasses
    import math

    from pf_offboard.identify.fit import AxisFit, Identification

    good = AxisFit("xy", 0.1, 0.1, 1.0, 0.5, (0.0, 0.0), 0.99, 0.1, 1000, 1.0)
    unmeasured = dataclasses.replace(good, group="z", bias_m_s2=(0.0,), r2=math.nan)
    ident = Identification(good, unmeasured, None, 10.0, ())
    assert "z R^2 nan" in ident.unflyable()
    assert Identification(good, dataclasses.replace(unmeasured, r2=0.9), None, 10.0, ()).unflyable() == ""


def test_the_setpoint_kind_is_the_one_that_flew(tmp_path) -> None:
    """An ArduCopter `fly` log held 40 s of level attitude targets sent before arming and GUIDED and
    21 s of flown body rates: the kind fitted is the one sent while the autopilot was in the app's
    mode, not the most numerous (that log failed with "no stretch ... where attitude setpoints were
    flying")."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from pf_offboard.logs.tlog import TlogWriter, read_tlog

    path = write_tlog(tmp_path / "flight.tlog", duration_s=20.0, offboard_from_s=12.0)
    padded = tmp_path / "padded.tlog"
    app = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    entries = read_tlog(path)
    t0 = entries[0].time_unix_s
    with TlogWriter.open(padded) as out:
        k = 0
        for e in entries:
            # before OFFBOARD: a level attitude target every 2.5 ms (4800 of them, against 800 flown)
            while t0 + 0.0025 * k < min(e.time_unix_s, t0 + 12.0):
                msg = mavlink.MAVLink_set_attitude_target_message(0, 1, 1, 0x07, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0.5)
                out.write(msg.pack(app), t0 + 0.0025 * k)
                k += 1
            out.write(e.message.get_msgbuf(), e.time_unix_s)
    log = load_log(padded)
    assert log.kind == "acceleration"
    assert log.duration_s == pytest.approx(8.0, abs=0.3)
    assert identify(log.segments).xy.r2 > 0.99
