"""pf_offboard.logs.measures."""

from __future__ import annotations

import numpy as np

from pf_offboard.logs.measures import final_slowdown


def test_the_final_slowdown_is_where_the_reference_falls_for_good():
    """An open path's end: the reference falls to 0 and never rises again; a dip and rise before it
    (a speed profile re-planned in flight: 2.39 then 2.48 m/s) is not the end's slow-down."""
    t = np.arange(0.0, 15.0, 0.02)
    ref = np.where(t < 7.0, 2.39, 2.39 + 0.09 * np.clip((t - 7.0) / 2.0, 0.0, 1.0))  # re-planned from 7 s
    ref = np.where(t > 13.5, np.maximum(0.0, 2.48 - 2.0 * (t - 13.5)), ref)  # the stop at the end
    ref[(t > 8.0) & (t < 8.5)] -= 0.05  # a dip that rises again
    after = t > 8.0
    first = t[final_slowdown(ref, after)][0]
    assert 13.5 < first < 13.6
    # the old rule (below 0.99 of the flight's largest reference after activation + 8 s) took 8 s
    assert t[after & (ref < 0.99 * ref.max())][0] < 8.1
    assert not final_slowdown(np.full(10, 1.5), np.ones(10, dtype=bool)).any()
    assert final_slowdown([], []).size == 0


def test_a_peak_before_the_window_does_not_make_the_cruise_a_slowdown():
    """The held-out helix at max 3 m/s (real PX4 SIH): the start ramp peaks at 2.471 m/s, the plan
    then cruises at 2.442 (+-0.007): the cruise is below 0.99 of the flight's peak and never rises
    above it again, which the rule before (the peak over the whole flight) took for the end's
    slow-down, leaving no window at all."""
    t = np.arange(0.0, 15.0, 0.02)
    ref = np.where(t < 2.0, 2.471, 2.442 + 0.007 * (np.sin(3.0 * t) > 0.9))
    ref = np.where(t > 13.5, np.maximum(0.0, 2.442 - 2.0 * (t - 13.5)), ref)
    after = t > 8.0
    assert 13.5 < t[final_slowdown(ref, after)][0] < 13.6
