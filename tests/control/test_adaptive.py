"""The in-flight identification of the inner loop (control/adaptive.py): on a simulated plant with
a known dead time and drag, the bank names them; with the typical model's own response, or a
slower one, the model stays."""

from __future__ import annotations

import math

import pytest

from pf_offboard.control import VehicleModel
from pf_offboard.control.compensator import InnerLoopCompensator


def _fly(delay_s: float, lag_s: float, drag_1_s: float, seconds: float = 8.0) -> InnerLoopCompensator:
    """Circle-like setpoints through a first-order lag + dead time + linear drag plant (100 Hz)."""
    comp = InnerLoopCompensator(VehicleModel.typical(), adapt=True)
    dt, sub = 0.01, 10
    v = [1.5, 0.0]
    a_f = [0.0, 0.0]
    t = 0.0
    for _ in range(int(seconds / dt)):
        comp.predict(t, (0.0, 0.0, 2.0), (v[0], v[1], 0.0))
        w = 1.5
        sp = (-2.0 * math.sin(w * t), 2.0 * math.cos(w * t) * math.cos(0.7 * t), 0.0)
        comp.record(t, sp)
        for k in range(sub):  # the plant: setpoints act after delay_s through the lag
            tau = t + k * dt / sub
            acting = comp.outgoing(tau - delay_s) if tau - delay_s >= 0.0 else (0.0, 0.0, 0.0)
            for i in (0, 1):
                a_f[i] += (acting[i] - a_f[i]) * (dt / sub) / lag_s
                v[i] += (a_f[i] - drag_1_s * v[i]) * dt / sub
        t += dt
    return comp


@pytest.mark.parametrize("delay_s,drag_1_s", [(0.0, 0.5), (0.04, 1.0)])
def test_the_bank_finds_the_dead_time_and_the_drag(delay_s, drag_1_s):
    comp = _fly(delay_s, 0.1, drag_1_s)
    assert comp.identifier is not None and comp.identifier.active is not None
    lag, delay = comp.identifier.candidate(comp.identifier.active)
    assert lag == 0.1 and abs(delay - delay_s) <= 0.045  # dead time and drag trade off a little
    assert abs(comp.identifier.drag_1_s - drag_1_s) <= 0.15
    assert comp.delay_s == delay and comp.horizon_s == delay  # the model moved there


@pytest.mark.parametrize("delay_s", [0.1, 0.2])
def test_the_typical_model_is_kept_when_it_fits_or_the_loop_is_slower(delay_s):
    """A slower inner loop than the guess needs lower gains, not a longer prediction: the dead
    time is only ever shortened."""
    comp = _fly(delay_s, 0.1, 0.0)
    assert comp.delay_s == 0.1 and comp.drag == (0.0, 0.0, 0.0)


def _fly_speeds(drag_1_s: float, seconds: float, scale: float = 1.0, drag_of_t=None) -> InnerLoopCompensator:
    """The typical model's own response (lag 0.1 s, dead time 0.1 s: no candidate is adopted) with
    drag, closed on a circle at ``1.5 * scale`` m/s: a PD on the velocity towards the circle's."""
    comp = InnerLoopCompensator(VehicleModel.typical(), adapt=True)
    dt, sub = 0.01, 10
    w = 1.2
    r = 1.5 * scale / w
    v = [0.0, 1.5 * scale]
    a_f = [0.0, 0.0]
    t = 0.0
    for _ in range(int(seconds / dt)):
        comp.predict(t, (0.0, 0.0, 2.0), (v[0], v[1], 0.0))
        ref = (-r * w * math.sin(w * t), r * w * math.cos(w * t))
        acc = (-r * w * w * math.cos(w * t), -r * w * w * math.sin(w * t))
        law = (acc[0] + 2.0 * (ref[0] - v[0]), acc[1] + 2.0 * (ref[1] - v[1]), 0.0)
        comp.record(t, comp.invert(t, law, (v[0], v[1], 0.0)))
        drag = drag_1_s if drag_of_t is None else drag_of_t(t)
        for k in range(sub):
            tau = t + k * dt / sub
            acting = comp.outgoing(tau - 0.1) if tau - 0.1 >= 0.0 else (0.0, 0.0, 0.0)
            for i in (0, 1):
                a_f[i] += (acting[i] - a_f[i]) * (dt / sub) / 0.1
                v[i] += (a_f[i] - drag * v[i]) * dt / sub
        t += dt
    return comp


def test_the_settled_drag_is_adopted_without_a_candidate():
    """PX4 SIH's case: the dead time is the typical one, so no candidate is adopted, but its drag
    is what the model misses. Once the initial candidate's estimate has settled (averaged, at
    speed) the compensator takes it, and the adoption is logged as identified."""
    comp = _fly_speeds(1.0, 20.0)
    assert comp.identifier is not None and comp.identifier.active is None
    assert abs(comp.drag[0] - 1.0) <= 0.15 and comp.drag[1] == comp.drag[0] and comp.drag[2] == 0.0
    assert comp.identified is not None and abs(comp.identified.drag_1_s - comp.drag[0]) <= 0.1
    assert (comp.identified.lag_s, comp.identified.delay_s) == (0.1, 0.1)
    assert 3.0 + 5.0 <= comp.identified.adopted_at_s <= 20.0


def test_no_drag_is_adopted_that_the_vehicle_does_not_have():
    comp = _fly_speeds(0.0, 20.0)
    assert comp.drag[0] <= 0.1 and comp.identified is None  # nothing worth reporting either


def test_no_drag_is_adopted_from_slow_flight_or_an_unsettled_estimate():
    """Below DRAG_MIN_SPEED_M_S drag hardly shows (it is not counted); a drag that jumps between 0
    and 2/s every 2 s keeps the estimate's spread above DRAG_MAX_STD_1_S: neither is adopted."""
    slow = _fly_speeds(1.0, 20.0, scale=0.5)
    assert slow.drag[0] == 0.0 and slow.identified is None
    jumpy = _fly_speeds(1.0, 20.0, drag_of_t=lambda t: 2.0 * (int(t / 2.0) % 2))
    assert jumpy.identifier is not None and jumpy.identifier.drag_estimate_1_s is None
