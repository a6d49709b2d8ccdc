"""The braking reserve's gate (control/law.py, braking_reserve_share): a tilt-saturated law keeps
a share of the speed loop's braking only when the vehicle is faster than the reference by more
than BRAKING_RESERVE_MARGIN_M_S. Below it the law is the one without the reserve, output for
output (ungated, the reserve acted in every ordinary tilt-saturated moment and flew worse on real
PX4 SIH); above it the braking grows continuously with the overspeed. The batch law mirrors it."""

from __future__ import annotations

import numpy as np
import pytest

import pf_offboard.control.law as law_module
from pf_offboard.control.law import BRAKING_RESERVE_MARGIN_M_S, BRAKING_RESERVE_SHARE, ControlLaw, braking_reserve_share
from pf_offboard.control.transverse import ExactTerms
from pf_offboard.control.types import Gains, Limits, TransverseState
from pf_offboard.sim.batch.law import BatchLaw, Terms

REF_M_S = 3.0
# a turn flown fast: the centripetal demand (8.6 m/s^2 toward +y) near the 45 deg tilt, the vehicle
# 15 cm outside, so the transversal correction (toward +y too) does not fit in full
ALPHA = (0.0, -8.6, 0.0)
ROWS = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _terms(eta2: float) -> ExactTerms:
    st = TransverseState(eta1=1.0, eta2=eta2, xi1=-0.15, xi2=0.0, phi1=0.0, phi2=0.0)
    return ExactTerms(st, ALPHA, *ROWS, lam_dot=eta2, tube=0.1, tangential_offset_m=0.0)


def _without_reserve(law: ControlLaw, terms: ExactTerms, monkeypatch: pytest.MonkeyPatch):
    with monkeypatch.context() as m:
        m.setattr(law_module, "braking_reserve_share", lambda eta2_ref, eta2: 0.0)
        return law.tube(terms, REF_M_S)


def test_the_share_is_zero_up_to_the_margin_and_ramps_to_its_cap_at_twice_it():
    m = BRAKING_RESERVE_MARGIN_M_S
    assert braking_reserve_share(REF_M_S, REF_M_S + m) == 0.0
    assert braking_reserve_share(REF_M_S, REF_M_S + 0.5 * m) == 0.0
    assert braking_reserve_share(REF_M_S, REF_M_S - 1.0) == 0.0  # slower: never
    assert braking_reserve_share(REF_M_S, REF_M_S + 1.5 * m) == pytest.approx(0.5 * BRAKING_RESERVE_SHARE)
    assert braking_reserve_share(REF_M_S, REF_M_S + 2.0 * m) == pytest.approx(BRAKING_RESERVE_SHARE)
    assert braking_reserve_share(-REF_M_S, -REF_M_S - 3.0 * m) == BRAKING_RESERVE_SHARE  # either direction


def test_below_the_gate_a_tilt_saturated_law_is_the_law_without_the_reserve(monkeypatch: pytest.MonkeyPatch):
    law = ControlLaw(Gains(), Limits())
    for over in (0.05, 0.15, BRAKING_RESERVE_MARGIN_M_S):
        terms = _terms(REF_M_S + over)
        out = law.tube(terms, REF_M_S)
        assert out.transversal, "the state must scale the transversal correction down"
        assert law.tangential(REF_M_S, terms.state.eta2) < 0.0  # and the speed loop brakes
        assert out == _without_reserve(law, terms, monkeypatch)


def test_above_the_gate_the_braking_grows_with_the_overspeed(monkeypatch: pytest.MonkeyPatch):
    law = ControlLaw(Gains(), Limits())
    braking = []
    for over in (0.3, 0.4, 0.5, 0.8):
        terms = _terms(REF_M_S + over)
        out, plain = law.tube(terms, REF_M_S), _without_reserve(law, terms, monkeypatch)
        assert out.transversal
        # along the path (+x) the reserve brakes harder; across it (+y) less correction
        assert out.accel[0] < plain.accel[0] - 0.05 and out.accel[1] < plain.accel[1]
        braking.append(-out.accel[0])
    assert braking == sorted(braking)


def test_the_batch_law_mirrors_the_gate():
    law, batch = ControlLaw(Gains(), Limits()), BatchLaw(Gains(), Limits())
    overs = np.array([0.0, 0.1, 0.25, 0.3, 0.375, 0.5, 0.8, -0.5])
    eta2 = REF_M_S + overs
    n = len(eta2)

    def col(v: float) -> np.ndarray:
        return np.full(n, v)

    terms = Terms(np.ones(n), eta2, col(-0.15), col(0.0), col(0.0), col(0.0), tuple(col(a) for a in ALPHA),
                  *(tuple(col(c) for c in row) for row in ROWS), eta2.copy(), col(0.1), col(0.0))  # fmt: skip
    out, ok = batch.tube(terms, np.full(n, REF_M_S))
    assert ok.all()
    for i, e in enumerate(eta2):
        ref = law.tube(_terms(float(e)), REF_M_S)
        assert np.allclose([out.accel[k][i] for k in range(3)], ref.accel, atol=1e-9, rtol=0.0), float(overs[i])
