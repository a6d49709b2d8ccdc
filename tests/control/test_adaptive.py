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
