"""The streaming summary (issue 9, item 7) equals the definition on the whole step list."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pf_offboard.config import load_config
from pf_offboard.logs.measures import path_tangent, tracking_of_records
from pf_offboard.logs.steplog import read_steplog
from pf_offboard.logs.summary import MAX_EVENTS, SAT_FLAGS, SummaryAccumulator

DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.mark.parametrize("log", sorted(DATA.glob("*.csv.gz")), ids=lambda p: p.name)
def test_streamed_summary_matches_the_definition(log) -> None:
    """The accumulator (constant memory, a 0.2 s delay line for the position's derivative) equals
    :func:`pf_offboard.logs.measures.tracking` over the whole list, and its saturation times the
    definition written directly."""
    records = read_steplog(log)
    tangent = path_tangent(load_config(log.with_name(log.name.removesuffix(".csv.gz") + ".yaml")).path.spline())
    # also a late bad step (it does not undo convergence) and an early one
    spoiled = records[:-50] + [type(records[0])(**{**records[-50].__dict__, "cross_track_m": 1.0})] + records[-49:]
    for recs in (records, spoiled):
        acc = SummaryAccumulator(tangent, settle_s=2.0)  # the golden flights are short
        for r in recs:
            acc.add(r)
        s = acc.result()
        ref = tracking_of_records(recs, tangent, settle_s=2.0)
        assert ref is not None and s.steps == len(recs)
        t = np.array([r.time_s for r in recs])
        active = np.array([r.active for r in recs])
        dt = np.diff(t, append=t[-1])
        sat = {k: float(np.sum(dt[active & np.array([getattr(r, k) for r in recs])])) for k in SAT_FLAGS}
        assert s.saturation_s == pytest.approx(sat)
        assert s.convergence_time_s == (None if ref.convergence_time_s is None else pytest.approx(ref.convergence_time_s, abs=1e-12))
        for got, want in ((s.settled, ref.settled), (s.whole, ref.whole)):
            assert (got is None) == (want is None)
            if got is not None:
                assert got.samples == want.samples and got.window == want.window
                for k in ("cross_track_rms_m", "cross_track_max_m", "speed_mean_m_s", "speed_error_rms_m_s", "estimator_speed_error_rms_m_s"):
                    assert getattr(got, k) == pytest.approx(getattr(want, k), rel=1e-9, abs=1e-12), k
        assert s.whole is not None and s.whole.speed_error_rms_m_s is not None


def test_events_are_bounded() -> None:
    records = read_steplog(sorted(DATA.glob("*.csv.gz"))[0])
    acc = SummaryAccumulator()
    for i in range(3 * MAX_EVENTS):
        acc.add(type(records[0])(**{**records[0].__dict__, "time_s": float(i), "event": f"e{i}"}))
    events = acc.result().events
    assert len(events) == MAX_EVENTS + 1 and f"{2 * MAX_EVENTS} more events" in events[-1][1]
