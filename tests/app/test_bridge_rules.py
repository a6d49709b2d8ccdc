"""The bridge's pure decision rules: throw trigger, lap counting, end conditions, param encoding."""

import math

import pytest

from pf_offboard.app.bridge import EndSpec, LapCounter, ThrowTrigger, end_reason, param_value_decode, param_value_encode
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
    laps = LapCounter(10.0, closed=True)
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

    from pf_offboard.app.bridge import Bridge, BridgeOptions
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
