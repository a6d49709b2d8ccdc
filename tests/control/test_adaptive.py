"""The in-flight identification of the inner loop (control/adaptive.py): on a simulated plant with
a known dead time and drag, the bank names them; with the typical model's own response, or a
slower one, the model stays."""

from __future__ import annotations

import math

import pytest

from pf_offboard.control import VehicleModel
from pf_offboard.control.compensator import InnerLoopCompensator, vertical_lag


def _fly(delay_s: float, lag_s: float, drag_1_s: float, seconds: float = 8.0, longer_lags_s: float | None = None,
         gain: float = 1.0, amplitude_m_s2: float = 2.0) -> InnerLoopCompensator:  # fmt: skip
    """Circle-like setpoints through a first-order lag + dead time + gain + linear drag plant (100 Hz).
    ``longer_lags_s``: :meth:`InnerLoopCompensator.identify_lags_up_to` with it first."""
    comp = InnerLoopCompensator(VehicleModel.typical(), adapt=True)
    if longer_lags_s is not None:
        comp.identify_lags_up_to(longer_lags_s)
    dt, sub = 0.01, 10
    v = [1.5, 0.0]
    a_f = [0.0, 0.0]
    t = 0.0
    for _ in range(int(seconds / dt)):
        comp.predict(t, (0.0, 0.0, 2.0), (v[0], v[1], 0.0))
        w = 1.5
        amp = amplitude_m_s2
        sp = (-amp * math.sin(w * t), amp * math.cos(w * t) * math.cos(0.7 * t), 0.0)
        comp.record(t, sp)
        for k in range(sub):  # the plant: setpoints act after delay_s through the lag
            tau = t + k * dt / sub
            acting = comp.outgoing(tau - delay_s) if tau - delay_s >= 0.0 else (0.0, 0.0, 0.0)
            for i in (0, 1):
                a_f[i] += (gain * acting[i] - a_f[i]) * (dt / sub) / lag_s
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
    assert comp.lag[2] == 0.05  # a shorter dead time keeps the model's vertical lag


@pytest.mark.parametrize("drag_1_s,gain", [(0.0, 1.0), (0.8, 0.85)])
def test_the_typical_model_is_kept_when_its_dead_time_fits(drag_1_s, gain):
    """The typical model's response, with or without PX4 SIH's gain and drag: nothing longer is
    adopted (the initial candidate, with its own fitted gain and drag, explains it)."""
    comp = _fly(0.1, 0.1, drag_1_s, seconds=12.0, gain=gain)
    assert comp.identified is None and comp.delay_s == 0.1 and comp.gain == (1.0, 1.0, 1.0)
    ident = comp.identifier
    assert ident is not None
    _, _, g, c = ident.fit(ident.joint_initial)  # its fit is the plant's
    assert abs(g - gain) <= 0.01 and abs(c - drag_1_s) <= 0.02


@pytest.mark.parametrize("delay_s,drag_1_s,gain", [(0.2, 0.75, 0.85), (0.16, 1.0, 0.95), (0.13, 0.742, 0.885)])
def test_a_slower_loop_is_adopted_with_its_gain_and_drag(delay_s, drag_1_s, gain):
    """A longer dead time than the guess (PX4 SIH answers after ~0.24 s, with gain 0.885 and drag
    0.742 1/s) is fitted with its gain and drag by least squares and adopted together once settled
    (after 6 s of data at the earliest; the shortest decisive dead time first, 0.2 s by way of a
    shorter one); the compensator slews to all three."""
    early = _fly(delay_s, 0.1, drag_1_s, seconds=5.5, gain=gain)
    assert early.identified is None  # not before LONGER_MIN_DATA_S
    comp = _fly(delay_s, 0.1, drag_1_s, seconds=12.0, gain=gain)
    m = comp.identified
    assert m is not None and m.lag_s == 0.1 and m.delay_s == delay_s and 6.0 <= m.adopted_at_s <= 11.0
    assert abs(m.gain_xy - gain) <= 0.01 and abs(m.drag_1_s - drag_1_s) <= 0.02
    assert comp.delay_s == comp.horizon_s == delay_s and comp.hold_s == (0.0, 0.0, 0.0)
    assert abs(comp.gain[0] - gain) <= 0.01 and abs(comp.drag[0] - drag_1_s) <= 0.02
    # the vertical axis flies the same gain and drag (a common thrust scale, isotropic drag) and no
    # lag: the longer dead time is the tilt's, the thrust answers within it (compensator.vertical_lag)
    assert abs(comp.gain[2] - gain) <= 0.01 and abs(comp.drag[2] - drag_1_s) <= 0.02 and comp.lag[2] == 0.0
    assert (m.gain_z, m.drag_z_1_s) == (m.gain_xy, m.drag_1_s)


def test_a_nearby_dead_time_is_adopted_at_the_nearest_candidate():
    """PX4 SIH's 0.136 s lies between the candidates: the nearest (0.13 s) is adopted, its gain and
    drag trading off the rest."""
    comp = _fly(0.136, 0.104, 0.742, seconds=12.0, gain=0.885)
    m = comp.identified
    assert m is not None and m.delay_s == 0.13
    assert abs(m.gain_xy - 0.885) <= 0.03 and abs(m.drag_1_s - 0.742) <= 0.1


def test_a_slower_loop_is_not_adopted_without_excitation():
    """Setpoints of 0.3 m/s^2 (below MIN_EXCITATION_M_S2 RMS): the fit is not trusted."""
    comp = _fly(0.2, 0.1, 0.75, seconds=12.0, gain=0.85, amplitude_m_s2=0.3)
    assert comp.identified is None and comp.delay_s == 0.1


def test_the_joint_fit_is_least_squares_exact():
    """The fit of a known system (the plant's own candidate) has no residual; the others do, more
    the further their dead time is from the plant's."""
    comp = _fly(0.16, 0.1, 1.0, seconds=12.0, gain=0.95)
    ident = comp.identifier
    assert ident is not None
    scores = {ident.candidate(k)[1]: ident.joint_score(k) for k in ident.joint}
    assert scores[0.16] <= 0.01 * min(v for d, v in scores.items() if d != 0.16)  # the discretisation's only
    assert scores[0.13] < scores[0.1] and scores[0.2] < scores[0.25] < scores[0.3]


def test_a_longer_lag_is_adopted_only_when_asked_for():
    """ArduCopter's rates output answers like lag 0.15 s + dead time 0.04-0.06 s: the model's lag
    with a shorter dead time cannot describe it; with the longer lags (the app's rates output on
    ArduCopter asks up to its attitude loop's 0.25 s: 1.5 x the model's lag, 0.15 s) the bank
    names it, and the compensator moves there."""
    plain = _fly(0.06, 0.15, 0.3)
    assert plain.lag[0] == 0.1  # the lag is the model's without the longer lags
    comp = _fly(0.06, 0.15, 0.3, longer_lags_s=0.25)
    assert comp.identifier is not None and comp.identifier.lags == (0.1, 0.15)
    assert comp.identified is not None and (comp.identified.lag_s, comp.identified.delay_s) == (0.15, 0.06)
    assert comp.lag[0] == 0.15 and comp.delay_s == 0.06 and comp.lag[2] == 0.05  # the vertical lag stays
    assert abs(comp.identifier.drag_1_s - 0.3) <= 0.15


@pytest.mark.parametrize("delay_s,lag_s", [(0.0, 0.15), (0.02, 0.2), (0.1, 0.15), (0.2, 0.15)])
def test_a_longer_lag_never_comes_with_a_short_or_a_long_dead_time(delay_s, lag_s):
    """A longer lag is adopted with a dead time of 0.06-0.08 s only (lag + dead time at most the
    model's + 0.03 s): a dead time under-modelled by a few hundredths diverged on the real
    ArduCopter (lag 0.2 s, no dead time) and flew 11 cm on the mock (0.04 s for its 0.08 s); a
    longer response than that (the mock's slower airframes: lag 0.15 s + 0.1 s) flew worse."""
    comp = _fly(delay_s, lag_s, 0.0, longer_lags_s=0.25)
    if comp.identified is not None and comp.identified.lag_s > 0.1:
        assert 0.06 <= comp.identified.delay_s <= 0.08
    assert comp.delay_s <= 0.1 and (comp.lag[0] == 0.1 or 0.06 <= comp.delay_s <= 0.08)


def test_no_longer_lags_without_identification_or_beyond_the_bound():
    off = InnerLoopCompensator(VehicleModel.typical())
    off.identify_lags_up_to(0.25)
    assert off.identifier is None
    same = InnerLoopCompensator(VehicleModel.typical(), adapt=True)
    same.identify_lags_up_to(0.1)  # not longer than the model's: the bank is unchanged
    assert same.identifier is not None and same.identifier.lags == (0.1,)
    capped = InnerLoopCompensator(VehicleModel.typical(), adapt=True)
    capped.identify_lags_up_to(2.0)  # at most 1.5 x the model's lag
    assert capped.identifier is not None and capped.identifier.lags == (0.1, 0.15)


def test_the_vertical_lag_with_an_adopted_dead_time():
    """None with a dead time longer than the model's vertical one (the tilt's: the thrust answers
    within it), the model's otherwise; a model with its own vertical dead time counts from it."""
    typical = VehicleModel.typical()
    assert vertical_lag(typical, 0.13) == 0.0 and vertical_lag(typical, 0.1) == 0.05 and vertical_lag(typical, 0.04) == 0.05
    own = VehicleModel(accel_lag_xy_s=0.1, accel_lag_z_s=0.03, accel_delay_s=0.1, accel_delay_z_s=0.15)
    assert vertical_lag(own, 0.13) == 0.03 and vertical_lag(own, 0.16) == 0.0
