"""Gain sweeps: candidates, the configs that fly them, the ranking."""

from __future__ import annotations

import math

import pytest
import yaml

from pf_offboard.config import parse_config
from pf_offboard.errors import InputError
from pf_offboard.sweep import gains, plan

from .helpers import PX4_SIH


def test_grid_is_bandwidth_major_and_spans_the_box() -> None:
    c = gains.candidates("grid", (1.0, 2.0), (0.6, 1.0), 3, seed=0)
    assert [(x.bandwidth_hz, x.damping) for x in c[:4]] == [(1.0, 0.6), (1.0, 0.8), (1.0, 1.0), (1.5, 0.6)]
    assert [x.id for x in c] == list(range(9))


def test_random_candidates_are_seeded_and_inside_the_box() -> None:
    a = gains.candidates("random", (1.0, 2.0), (0.6, 1.0), 5, seed=3)
    assert a == gains.candidates("random", (1.0, 2.0), (0.6, 1.0), 5, seed=3)
    assert a != gains.candidates("random", (1.0, 2.0), (0.6, 1.0), 5, seed=4)
    assert all(1.0 <= x.bandwidth_hz <= 2.0 and 0.6 <= x.damping <= 1.0 for x in a)


@pytest.mark.parametrize(("text", "flag"), [("x", "--bandwidth"), ("2:1", "--bandwidth"), ("1:2:3", "--bandwidth"),
                                            ("0:60", "--bandwidth")])
def test_bad_ranges_name_the_flag(text: str, flag: str) -> None:
    with pytest.raises(InputError) as exc:
        gains.parse_range(text, flag, gains.BANDWIDTH_HZ)
    assert exc.value.field == flag


def test_too_many_candidates() -> None:
    with pytest.raises(InputError, match="--gain-points"):
        gains.candidates("grid", (1.0, 2.0), (0.6, 1.0), 30, seed=0)


def test_a_candidate_config_flies_its_gains_in_both_loops() -> None:
    cand = gains.GainCandidate(0, 1.25, 0.9)
    config = parse_config(yaml.safe_load(plan.config_yaml(PX4_SIH, cand)))
    g = config.gains
    assert (g.transversal_bandwidth_hz, g.transversal_damping, g.tangential_bandwidth_hz, g.tangential_damping) == (1.25, 0.9, 1.25, 0.9)
    assert not config.gains_auto and config.compensation.enabled  # the rest of the config is kept


def test_ranking_success_first_then_convergence_time() -> None:
    cands = [gains.GainCandidate(i, 1.0 + i, 0.8) for i in range(3)]

    def row(gid: int, ok: bool, t: float) -> dict[str, object]:
        return {"gains_id": gid, "success": ok, "caught_time_s": t if ok else math.nan, "cross_track_rms_after_m": 0.1}

    rows = [row(0, True, 3.0), row(0, True, 3.0), row(1, True, 1.0), row(1, False, 0.0), row(2, True, 2.0), row(2, True, 2.5)]
    ranked = gains.rank(rows, cands)
    assert [r["gains_id"] for r in ranked] == [2, 0, 1] and [r["rank"] for r in ranked] == [1, 2, 3]
    assert ranked[2]["success_rate"] == 0.5 and ranked[2]["caught_p90_s"] == math.inf
