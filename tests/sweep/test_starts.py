"""Seeded random starts: each flight's draws depend only on (seed, index); every range holds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pf_offboard.config import load_config
from pf_offboard.control import PathFollower
from pf_offboard.errors import InputError
from pf_offboard.sweep.starts import StartRanges, flight_rng, sample_start

from .helpers import PAPER


@pytest.fixture(scope="module")
def path():  # type: ignore[no-untyped-def]
    return PathFollower.from_config(load_config(PAPER)).path


def test_flight_generator_is_the_spawned_child() -> None:
    children = np.random.SeedSequence(42).spawn(6)
    for i in (0, 3, 5):
        np.testing.assert_array_equal(flight_rng(42, i).random(5), np.random.default_rng(children[i]).random(5))


def test_a_start_depends_only_on_seed_and_index(path) -> None:  # type: ignore[no-untyped-def]
    r = StartRanges()
    forward = [sample_start(path, r, 3, i) for i in range(4)]
    backward = [sample_start(path, r, 3, i) for i in reversed(range(4))][::-1]
    assert forward == backward
    assert sample_start(path, r, 4, 0) != forward[0]
    assert len({s.sim_seed for s in forward}) == 4


def test_every_draw_is_inside_its_range(path) -> None:  # type: ignore[no-untyped-def]
    r = StartRanges(max_distance_m=5.0, max_speed_m_s=4.0, max_tilt_deg=60.0, max_rate_rad_s=3.0, max_wind_m_s=2.5,
                    min_height_m=2.0)
    starts = [sample_start(path, r, 11, i) for i in range(150)]
    for s in starts:
        assert s.distance_m <= 5.0 + 1e-9 and s.position_enu_m[2] >= 2.0
        assert s.speed_m_s <= 4.0 + 1e-9 and s.tilt_deg <= 60.0 + 1e-6
        assert math.hypot(*s.body_rates_flu_rad_s) <= 3.0 + 1e-9
        assert math.hypot(*s.wind_enu_m_s) <= 2.5 + 1e-9 and s.wind_enu_m_s[2] == 0.0
        assert abs(math.hypot(*s.q_enu_flu) - 1.0) < 1e-12
        assert 0 <= s.sim_seed < 2**63
    # the ranges are covered, not only respected
    assert max(s.distance_m for s in starts) > 3.5 and max(s.speed_m_s for s in starts) > 3.5
    assert max(s.tilt_deg for s in starts) > 50.0


def test_tilt_is_the_body_z_axis_from_vertical(path) -> None:  # type: ignore[no-untyped-def]
    s = sample_start(path, StartRanges(max_tilt_deg=30.0), 5, 1)
    w, x, y, z = s.q_enu_flu
    body_z_up = 1.0 - 2.0 * (x * x + y * y)  # world z component of the body z axis
    assert math.degrees(math.acos(body_z_up)) == pytest.approx(s.tilt_deg, abs=1e-9)


@pytest.mark.parametrize(("field", "value", "flag"), [
    ("max_distance_m", -1.0, "--max-distance"), ("max_speed_m_s", math.nan, "--max-speed"),
    ("max_tilt_deg", 200.0, "--max-tilt"), ("max_rate_rad_s", 40.0, "--max-rate"),
    ("max_wind_m_s", 25.0, "--max-wind"), ("min_height_m", 0.1, "--min-height"),
])
def test_bad_ranges_name_the_flag(field: str, value: float, flag: str) -> None:
    with pytest.raises(InputError) as exc:
        StartRanges(**{field: value}).validate()
    assert exc.value.field == flag


def test_an_unreachable_min_height_is_an_error(path) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError, match="--min-height"):
        sample_start(path, StartRanges(max_distance_m=1.0, min_height_m=20.0), 0, 0)
