"""External pushes (Simulator.add_push / MockConfig.pushes): the exact velocity change, the window
in whole physics ticks, validation, and no effect on a flight without one."""

from __future__ import annotations

import math

import numpy as np
import pytest
from dynhelpers import make_sim

from sitl_mock.config import MockConfig, MockConfigError
from sitl_mock.dynamics import MotorsOff, Push, Spawn, preset


def _ballistic(push: Push | None, steps: int = 250):
    sim = make_sim(preset("fast"), Spawn.thrown((0.0, 0.0, -50.0), (1.0, 0.0, 0.0)))
    if push is not None:
        sim.add_push(push)
    return [sim.step(0.004, MotorsOff()) for _ in range(steps)]


def test_push_adds_exactly_its_impulse_under_drag() -> None:
    """Linear drag c: a push a over [t0, t0 + d] changes the velocity by (a/c)(1 - e^{-c d}),
    decaying as e^{-c (t - t0 - d)} afterwards (the dynamics are linear: free + push response)."""
    c = preset("fast").drag_1_s
    a = np.array([3.0, -2.0, 1.0])
    t0, d = 0.2, 0.5
    free = _ballistic(None)
    pushed = _ballistic(Push(t0, d, tuple(a)))
    for s0, s1 in zip(free, pushed):
        t = s0.time_s
        if t <= t0 + 1e-12:
            np.testing.assert_array_equal(s1.velocity_ned_m_s, s0.velocity_ned_m_s)
            continue
        h = min(t, t0 + d) - t0
        dv = a / c * (1.0 - math.exp(-c * h)) * math.exp(-c * max(t - t0 - d, 0.0))
        np.testing.assert_allclose(s1.velocity_ned_m_s - s0.velocity_ned_m_s, dv, atol=1e-9)


def test_no_push_is_the_same_flight_bit_for_bit() -> None:
    far = _ballistic(Push(100.0, 1.0, (5.0, 0.0, 0.0)), 100)
    none = _ballistic(None, 100)
    for a, b in zip(far, none):
        assert a.position_ned_m.tobytes() == b.position_ned_m.tobytes()
        assert a.velocity_ned_m_s.tobytes() == b.velocity_ned_m_s.tobytes()


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: Push(-1.0, 0.5, (1.0, 0.0, 0.0)), "start_s"),
        (lambda: Push(0.0, 0.0, (1.0, 0.0, 0.0)), "duration_s"),
        (lambda: Push(0.0, 0.5, (1.0, math.nan, 0.0)), "accel_ned_m_s2"),
        (lambda: Push(0.0, 0.5, (1.0, 0.0)), "accel_ned_m_s2"),
        (lambda: Push(0.0, 0.5, (200.0, 0.0, 0.0)), "accel_ned_m_s2"),
    ],
)
def test_bad_push_names_the_field(make, field: str) -> None:
    with pytest.raises(ValueError, match=f"Push.{field}"):
        make()


def test_mock_config_takes_pushes_only() -> None:
    MockConfig(pushes=(Push(1.0, 0.5, (0.0, 10.0, 0.0)),)).validate()
    with pytest.raises(MockConfigError) as exc:
        MockConfig(pushes=((1.0, 0.5, 0.0, 10.0, 0.0),)).validate()  # type: ignore[arg-type]
    assert "pushes[0]" in str(exc.value)
    sim = make_sim(preset("fast"), Spawn.hover((0.0, 0.0, -2.0)))
    with pytest.raises(ValueError, match="add_push"):
        sim.add_push((1.0, 0.5, (1.0, 0.0, 0.0)))  # type: ignore[arg-type]
