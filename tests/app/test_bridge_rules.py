"""The bridge's pure decision rules: throw trigger, lap counting, end conditions, param encoding."""

import math

import pytest

import numpy as np

from pf_offboard.app.params import param_value_decode, param_value_encode
from pf_offboard.app.rules import EndSpec, LapCounter, TakeoffSettle, ThrowTrigger, end_reason
from pf_offboard.errors import InputError


def test_throw_upwards_through_h_fires_once_after_confirmation() -> None:
    trig = ThrowTrigger(2.0, min_speed_m_s=0.5, confirm=2)
    samples = [(1.2, 3.0), (1.6, 3.0), (1.95, 3.0), (2.05, 3.0), (2.3, 2.5), (2.6, 2.0), (1.9, 1.0)]
    fired = [trig.update(h, v) for h, v in samples]
    assert fired == [False, False, False, False, True, False, False]


def test_throw_downwards_through_h_fires() -> None:
    trig = ThrowTrigger(4.0)
    assert [trig.update(h, 3.0) for h in (5.0, 4.5, 3.9, 3.7)] == [False, False, False, True]


def test_single_noisy_sample_does_not_fire() -> None:
    trig = ThrowTrigger(2.0)
    assert not any(trig.update(h, 3.0) for h in (1.9, 2.01, 1.99, 1.98))


def test_slow_carry_past_h_does_not_fire_but_a_later_throw_does() -> None:
    trig = ThrowTrigger(2.0, min_speed_m_s=0.5)
    # carried up slowly past 2 m: no trigger, the new side is accepted
    assert not any(trig.update(h, 0.2) for h in (1.8, 1.9, 2.1, 2.2, 2.3))
    # then thrown and falling through 2 m fast
    assert [trig.update(h, 2.0) for h in (2.1, 1.95, 1.8)] == [False, False, True]


def test_throw_height_must_be_positive() -> None:
    with pytest.raises(InputError):
        ThrowTrigger(0.0)


def test_lap_counter_wraps_on_closed_paths_either_direction() -> None:
    laps = LapCounter(10.0, closed=True)  # no direction given: either way round
    eta = 9.0
    for _ in range(30):  # backwards (eta2 < 0) through the wrap, 0.5 m per step
        laps.update(eta)
        eta = (eta - 0.5) % 10.0
    assert laps.laps == pytest.approx(29 * 0.5 / 10.0)
    open_laps = LapCounter(10.0, closed=False)
    for e in (0.0, 2.0, 5.0):
        open_laps.update(e)
    assert open_laps.laps == pytest.approx(0.5)
    assert open_laps.update(math.nan) == pytest.approx(0.5)


def test_laps_count_net_progress_not_jitter() -> None:
    """A vehicle jittering in place for 356 s (here: ±5 cm at 50 Hz around η1 = 3 m, and around
    the closed path's start point where η1 wraps) completes 0 laps; the old |Δη1| sum gave ~35."""
    rng = np.random.default_rng(0)
    for centre in (3.0, 0.0):
        for direction in (-1.5, 1.5, None):
            laps = LapCounter(15.578, closed=True, direction=direction)
            for _ in range(int(356 * 50)):
                laps.update((centre + rng.uniform(-0.05, 0.05)) % 15.578)
            assert laps.laps < 0.01, (centre, direction, laps.laps)


def test_laps_count_in_the_direction_of_travel_only() -> None:
    laps = LapCounter(10.0, closed=True, direction=-1.0)  # eta2_ref < 0: eta1 decreasing
    eta = 1.0
    for _ in range(40):  # forwards (decreasing) through the wrap, 0.5 m per step, with a wobble
        laps.update(eta)
        laps.update((eta + 0.2) % 10.0)  # back 0.2 m, then on
        eta = (eta - 0.5) % 10.0
    assert laps.laps == pytest.approx((39 * 0.5 - 0.2) / 10.0)  # net: the last step back 0.2 m counts against
    against = LapCounter(10.0, closed=True, direction=+1.0)
    for k in range(40):
        against.update((1.0 - 0.5 * k) % 10.0)
    assert against.laps == 0.0  # travelling the wrong way is no progress


def test_takeoff_settle_tolerates_gps_hover_but_not_a_climb() -> None:
    """Settled when, over 1 s, the mean altitude error is within 0.3 m and the mean speed below
    0.5 m/s: a GPS vehicle holding 2 m at 0.13-0.43 m/s settles (the old 0.1 m / 0.1 m/s per-sample
    rule never held); a vehicle still climbing through 2 m does not."""
    rng = np.random.default_rng(1)
    hover = TakeoffSettle(2.0)
    t = 0.0
    results = []
    for _ in range(100):  # 2 s at 50 Hz
        t += 0.02
        results.append(hover.update(t, 2.0 + rng.uniform(-0.15, 0.15), rng.uniform(0.13, 0.43)))
    assert not any(results[:49]) and results[-1]  # needs a full 1 s window, then holds
    climbing = TakeoffSettle(2.0)
    t = 0.0
    for k in range(150):  # climbing at 1 m/s from 0.5 m to 3.5 m
        t += 0.02
        assert not climbing.update(t, 0.5 + 1.0 * 0.02 * k, 1.0)
    drifting = TakeoffSettle(2.0)
    assert not any(drifting.update(0.02 * k, 2.0, 0.8) for k in range(200))  # too fast on average
    assert not TakeoffSettle(2.0).update(0.0, 2.0, 0.0)  # one sample is not a window


def test_end_reasons() -> None:
    spec = EndSpec(laps=2, duration_s=30.0)
    assert end_reason(spec, 1.9, 10.0, True, 0.5, 1.0, -1.5, -1.5) == ""
    assert "2 laps" in end_reason(spec, 2.0, 10.0, True, 0.5, 1.0, -1.5, -1.5)
    assert "duration" in end_reason(spec, 0.5, 30.0, True, 0.5, 1.0, -1.5, -1.5)
    # open path: at the end and stopped
    assert "open path" in end_reason(EndSpec(), 0.0, 5.0, False, 1.0, 1.0, 1.5, 0.05)
    assert end_reason(EndSpec(), 0.0, 5.0, False, 1.0, 1.0, 1.5, 0.8) == ""  # still moving
    assert "open path" in end_reason(EndSpec(), 0.0, 5.0, False, 0.0, 1.0, -1.5, -0.01)  # backwards: start is the end
    assert end_reason(EndSpec(), 0.0, 5.0, True, 1.0, 1.0, 1.5, 0.0) == ""  # closed paths never end by themselves


def test_param_encodings() -> None:
    # PX4 packs INT32 bytewise into the float; ArduPilot casts
    packed = param_value_encode(8, 6, bytewise=True)
    assert packed != 8.0 and param_value_decode(packed, 6, bytewise=True) == 8.0
    assert param_value_encode(8, 6, bytewise=False) == 8.0
    assert param_value_decode(0.37, 9, bytewise=True) == pytest.approx(0.37)


def test_status_line_shows_mode_and_transverse_state() -> None:
    import io
    from types import SimpleNamespace

    from pf_offboard.app.flight import Flight as Bridge
    from pf_offboard.app.flight import FlightOptions as BridgeOptions
    from pf_offboard.app.encoders import Encoder
    from pf_offboard.app.pipeline import Pipeline
    from pf_offboard.app.profiles import PX4

    from .helpers import local_position
    from .test_pipeline import FakeFollower

    heartbeat = SimpleNamespace(custom_mode=393216, base_mode=0x91, get_srcComponent=lambda: 1)
    link = SimpleNamespace(target=None, first_heartbeat=heartbeat)
    pipe = Pipeline(FakeFollower(), Encoder("acceleration", PX4, 1, 1))
    bridge = Bridge(link, PX4, pipe, BridgeOptions("airborne", math.nan, EndSpec()), 10.0, True, 1.0, status_stream=io.StringIO())
    assert bridge.status_text().startswith("[preflight] OFFBOARD armed")
    pipe.on_message(local_position(0))
    bridge.last_step = pipe.step()
    text = bridge.status_text()
    for label in ("η1", "η2", "ξ1", "φ1", "e ", "rate"):
        assert label in text
    assert "ξ1 +0.010 m" in text and "φ1 -0.020 m" in text
