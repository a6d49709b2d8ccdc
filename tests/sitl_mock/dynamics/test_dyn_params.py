"""Presets and gain design."""

from __future__ import annotations

import numpy as np
import pytest

from sitl_mock.dynamics import PRESET_NAMES, cascade_gains_for_poles, preset


@pytest.mark.parametrize("pole", [100.0, 280.0, 400.0])
def test_cascade_gains_place_a_triple_pole(pole: float) -> None:
    tau = 0.015
    g = cascade_gains_for_poles(pole, tau, rate_limit_rad_s=10.0)
    lead = 1.0 + g.rate_d
    roots = np.roots([tau, lead, lead * g.rate_p_1_s, lead * g.rate_p_1_s * g.attitude_p_1_s])
    np.testing.assert_allclose(roots.real, -pole, rtol=1e-3)
    np.testing.assert_allclose(roots.imag, 0.0, atol=1e-2 * pole)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_presets_are_consistent(name: str) -> None:
    p = preset(name)
    assert p.name == name
    if name == "px4-sih":
        # Deliberate: PX4's hover-thrust parameter (0.5) vs SIH's true 0.490, as on the real one.
        assert p.hover_thrust == 0.5
        assert p.true_hover_thrust == pytest.approx(9.80665 / 20.0, rel=1e-12)
    else:
        assert p.hover_thrust == pytest.approx(p.true_hover_thrust, rel=1e-12)
    assert 4 * p.motor_thrust_max_n == pytest.approx(p.thrust_to_weight * p.weight_n)
    assert preset(name) == p  # a fresh, equal object each call


def test_with_revalidates() -> None:
    p = preset("fast").with_(mass_kg=0.8)
    assert p.mass_kg == 0.8 and p.hover_thrust == preset("fast").hover_thrust
    with pytest.raises(ValueError, match="tilt_max_rad"):
        p.with_(tilt_max_rad=2.0)
