"""identify on flights recorded against a real PX4 (SIH quad, default tuning): consistent values.

The extracts in tests/data/identify/ are the recorded flights of shared/data/px4-sih/ trimmed by
scripts/extract_identify_logs.py (the records identify reads, from 2 s before activation to the
end: about 23 s of path following each). The flights are the paper path at 1.5 m/s, not an
excitation: the setpoints are what path following asked for.

Tolerances (measurements, not goldens): fitting each flight's first and second half separately
moves the xy 63 % rise by up to 0.004 s and the drags by up to 0.12 1/s (see docs/identify.md), so
two flights of the same vehicle must agree within 0.03 s (xy rise) and 0.15 1/s (drags). The
plausibility bounds are the vehicle's: SIH's linear drag is 1.0 1/s, PX4's horizontal
acceleration follows a setpoint with about 0.19 s lag (shared/notes/px4-sitl.md).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from pf_offboard.identify import identify, load_log

DATA = Path(__file__).resolve().parents[1] / "data" / "identify"


def _fit(name: str):
    log = load_log(DATA / f"px4-sih-{name}.tlog.gz")
    return log, identify(log.segments)


@pytest.fixture(scope="module")
def accel():
    return _fit("accel-1.5hz")


@pytest.fixture(scope="module")
def attitude():
    return _fit("attitude-1.5hz")


def test_the_extracts_are_what_identify_expects(accel, attitude) -> None:
    log_a, _ = accel
    log_t, _ = attitude
    assert log_a.kind == "acceleration" and log_t.kind == "attitude"
    # only the flying part: the take-off's position setpoints are not used
    assert 20.0 < log_a.duration_s < 26.0 and 20.0 < log_t.duration_s < 26.0
    assert log_t.hover_thrust == pytest.approx(0.5) and "MPC_THR_HOVER" in log_t.hover_thrust_source
    # the SITL ran in lockstep slightly slower than the wall clock: the boot clock is mapped
    assert 1.0 < log_a.clock_slope < 1.03


def test_two_flights_agree(accel, attitude) -> None:
    _, a = accel
    _, t = attitude
    print(f"\naccel:    xy rise {a.xy.rise_63_s:.3f} s gain {a.xy.gain:.3f} drag {a.xy.drag_1_s:.3f}; z rise {a.z.rise_63_s:.3f} gain {a.z.gain:.3f} drag {a.z.drag_1_s:.3f}"
          f"\nattitude: xy rise {t.xy.rise_63_s:.3f} s gain {t.xy.gain:.3f} drag {t.xy.drag_1_s:.3f}; z rise {t.z.rise_63_s:.3f} gain {t.z.gain:.3f} drag {t.z.drag_1_s:.3f}")  # fmt: skip
    assert a.xy.rise_63_s == pytest.approx(t.xy.rise_63_s, abs=0.03)
    assert a.xy.drag_1_s == pytest.approx(t.xy.drag_1_s, abs=0.15)
    assert a.z.drag_1_s == pytest.approx(t.z.drag_1_s, abs=0.15)


@pytest.mark.parametrize("flight", ["accel", "attitude"])
def test_values_are_physically_plausible(flight, request) -> None:
    _, ident = request.getfixturevalue(flight)
    assert 0.12 <= ident.xy.rise_63_s <= 0.30  # about 0.19 s measured on this vehicle
    assert ident.z.rise_63_s < ident.xy.rise_63_s  # thrust is faster than tilting
    for f in (ident.xy, ident.z):
        assert 0.5 <= f.drag_1_s <= 1.5  # SIH: 1.0 1/s
        assert 0.6 <= f.gain <= 1.3
        assert f.r2 > 0.85
    model = ident.vehicle_model()  # and it is a valid vehicle: section
    assert model.drag_xy_1_s == pytest.approx(round(ident.xy.drag_1_s, 3))


def test_rates_flight_gives_the_rate_loop_and_the_drag() -> None:
    log, ident = _fit("rates-1.5hz-tau0.2")
    assert log.kind == "rates" and ident.rate is not None
    # PX4's rate loop on SIH: tens of milliseconds (motor time constant 0.05 s, rate P/I/D)
    assert 0.01 < ident.rate.time_constant_s < 0.15
    assert ident.rate.r2 > 0.9
    # with the attitude measured, the horizontal model is the thrust path plus drag: SIH's 1.0 1/s
    assert ident.xy.drag_1_s == pytest.approx(1.0, abs=0.15)
    assert ident.vehicle_model().rate_time_constant_s == pytest.approx(ident.rate.time_constant_s, abs=1e-3)
