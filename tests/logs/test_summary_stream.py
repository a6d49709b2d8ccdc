"""The streaming summary (issue 9, item 7) equals the definition on the whole step list."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pf_offboard.logs.steplog import read_steplog
from pf_offboard.logs.summary import MAX_EVENTS, SAT_FLAGS, SummaryAccumulator

DATA = Path(__file__).resolve().parents[1] / "data"


def _batch(records, tol_ct=0.05, tol_v=0.1):
    """The definitions written directly over the list (the reference)."""
    t = np.array([r.time_s for r in records])
    active = np.array([r.active for r in records])
    dt = np.diff(t, append=t[-1])
    sat = {k: float(np.sum(dt[active & np.array([getattr(r, k) for r in records])])) for k in SAT_FLAGS}
    idx = np.flatnonzero(active)
    ct = np.array([r.cross_track_m for r in records])[idx]
    err = np.array([r.eta2_m_s - r.speed_ref_m_s for r in records])[idx]
    good = (ct <= tol_ct) & (np.abs(err) <= tol_v)
    bad = np.flatnonzero(~good)
    first = 0 if bad.size == 0 else int(bad[-1]) + 1
    if first >= idx.size:
        return sat, None, None, None
    return sat, float(t[idx[first]] - t[idx[0]]), math.sqrt(np.mean(ct[first:] ** 2)), float(np.max(ct[first:]))


@pytest.mark.parametrize("log", sorted(DATA.glob("*.csv.gz")), ids=lambda p: p.name)
def test_streamed_summary_matches_the_definition(log) -> None:
    records = read_steplog(log)
    # also a late bad step: convergence restarts, the sums must restart with it
    spoiled = records[:-50] + [type(records[0])(**{**records[-50].__dict__, "cross_track_m": 1.0})] + records[-49:]
    for recs in (records, spoiled):
        acc = SummaryAccumulator()
        for r in recs:
            acc.add(r)
        s = acc.result()
        sat, conv, rms, mx = _batch(recs)
        assert s.steps == len(recs)
        assert s.saturation_s == pytest.approx(sat)
        if conv is None:
            assert s.convergence_time_s is None
        else:
            assert s.convergence_time_s == pytest.approx(conv, abs=1e-12)
            assert s.cross_track_rms_m == pytest.approx(rms, rel=1e-12) and s.cross_track_max_m == mx


def test_events_are_bounded() -> None:
    records = read_steplog(sorted(DATA.glob("*.csv.gz"))[0])
    acc = SummaryAccumulator()
    for i in range(3 * MAX_EVENTS):
        acc.add(type(records[0])(**{**records[0].__dict__, "time_s": float(i), "event": f"e{i}"}))
    events = acc.result().events
    assert len(events) == MAX_EVENTS + 1 and f"{2 * MAX_EVENTS} more events" in events[-1][1]
