"""The speed profile's plans equal the reference plans (tests/data/speed_profile_plans.json,
generated with scripts/gen_profile_plans.py; until the jerk was planned for the inner loop's
response, by the scalar planner of c7ee081, which the vectorised one matched) to 1e-9 on every
shipped path at max 1.5, 2 and 3 m/s, for the vehicle model and the identified one; and the
vectorised pieces of the planner equal the scalar ones they replace, bit for bit."""

from __future__ import annotations

import importlib.util
import json
import math

import numpy as np
import pytest
from conftest import ROOT

from pf_offboard.config import load_config
from pf_offboard.control import PathFollower
from pf_offboard.control.profile import SpeedProfile, SpeedProfileSpec, _Feasible, _geometry, _passes

_spec = importlib.util.spec_from_file_location("gen_profile_plans", ROOT / "scripts" / "gen_profile_plans.py")
assert _spec is not None and _spec.loader is not None
gen = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(gen)

REF = json.loads((ROOT / "tests" / "data" / "speed_profile_plans.json").read_text())
REL = 1e-9


def _close(got: list[float], want: list[float], scale: float) -> float:
    """Largest difference relative to ``scale`` (the case's largest value)."""
    g, w = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
    assert g.shape == w.shape
    return float(np.max(np.abs(g - w), initial=0.0)) / scale


@pytest.mark.parametrize("config", sorted(REF["configs"]))
def test_plans_equal_the_reference(config: str) -> None:
    cases = [c for c in REF["cases"] if c["config"] == config]
    assert len(cases) >= 6
    base = gen.follower(REF["configs"][config])
    like: dict[float, SpeedProfile] = {}  # per direction: the path sampled once
    for case in cases:
        got, profile = gen.plan(base, case["max_speed_m_s"], case["model"], case["direction"], like.get(case["direction"]))
        like.setdefault(case["direction"], profile)
        where = f"{config} max {case['max_speed_m_s']} m/s {case['model']} direction {case['direction']:+g}"
        assert got["n"] == case["n"], where
        for name, g, w in zip(("travel_time_s", "point_mass_time_s", "max_speed", "min_speed", "max_accel", "max_jerk",
                               "max_accel_use", "max_tilt_rate", "max_tilt"), got["stats"], case["stats"]):  # fmt: skip
            assert g == pytest.approx(w, rel=REL, abs=1e-12), f"{where}: {name}"
        b_scale = max(max(case["b_every"]), 1e-9)
        assert _close(got["b_every"], case["b_every"], b_scale) <= REL, f"{where}: b = V^2 on the grid"
        for k in range(3):  # speed, its first and second eta1-derivatives between grid points
            want = [e[k] for e in case["evaluate"]]
            scale = max(max(abs(x) for x in want), 1e-9)
            assert _close([e[k] for e in got["evaluate"]], want, scale) <= REL, f"{where}: evaluate()[{k}]"


def test_reference_covers_every_shipped_config() -> None:
    assert sorted(REF["configs"]) == sorted(gen.case_name(f) for f in gen.config_files())


# ------------------------------------------------------------------ the vectorised pieces
def _passes_scalar(ub: np.ndarray, feas: _Feasible, ds: float, closed: bool) -> np.ndarray:
    """The passes as they were (c7ee081): every interval evaluated in turn."""
    b = ub.copy()
    n = len(b)
    for _ in range(4 if closed else 1):
        changed = False
        for i in range(n) if closed else range(n - 1):
            j = (i + 1) % n
            iv = feas.interval(i, b[i])
            lim = b[i] + 2.0 * max(iv[1] if iv is not None else 0.0, 0.0) * ds
            if b[j] > lim:
                b[j] = lim
                changed = True
        for i in range(n - 1, -1, -1) if closed else range(n - 2, -1, -1):
            j = (i + 1) % n
            iv = feas.interval(j, b[j])
            lim = b[j] - 2.0 * min(iv[0] if iv is not None else 0.0, 0.0) * ds
            if b[i] > lim:
                b[i] = lim
                changed = True
        if not changed:
            break
    return np.maximum(b, 0.0)


@pytest.mark.parametrize("name", ["real_sitl/configs/figure8-tilted.yaml", "real_sitl/configs/helix.yaml"])
def test_vectorised_pieces_equal_the_scalar_ones(name: str) -> None:
    f = PathFollower.from_config(load_config(ROOT / "tests" / name))
    spec = SpeedProfileSpec(3.0)
    geo = _geometry(f.path, spec, 1.0)
    feas = _Feasible(geo, f.limits, spec, 0.2)
    n = len(geo.u)
    ub = feas.max_bs(geo.cap_b)
    assert ub.tolist() == [feas.max_b(i, c) for i, c in enumerate(geo.cap_b.tolist())]
    assert 0.0 < ub.min() < ub.max() <= 9.0  # some points below the speed cap, so the bisection ran
    rng = np.random.default_rng(7)
    for b in (ub, 0.5 * ub, rng.uniform(0.0, 40.0, n), np.zeros(n)):
        lo, hi, ok = feas.intervals(b)
        for i in range(n):
            iv = feas.interval(i, float(b[i]))
            assert (iv is not None) == bool(ok[i])
            if iv is not None:
                assert (lo[i], hi[i]) == iv
        a = rng.uniform(-4.0, 4.0, n)
        a[::5] = 0.0
        assert feas.uses(b, a).tolist() == [feas.use(i, float(x), float(y)) for i, (x, y) in enumerate(zip(b, a))]
    closed = bool(f.path.closed)
    for start in (ub, np.minimum(ub, geo.rate_cap_b), rng.uniform(0.0, 9.0, n)):
        assert _passes(start, feas, geo.ds, closed).tolist() == _passes_scalar(start, feas, geo.ds, closed).tolist()


def test_reusing_a_profiles_path_sampling_gives_the_same_plan() -> None:
    f = PathFollower.from_config(load_config(ROOT / "tests" / "real_sitl" / "configs" / "racetrack.yaml"))
    first = SpeedProfile(f.path, SpeedProfileSpec(2.0), f.limits, 1.0, 0.3)
    alone = SpeedProfile(f.path, SpeedProfileSpec(3.0), f.limits, -1.0, 0.2)
    like = SpeedProfile(f.path, SpeedProfileSpec(3.0), f.limits, -1.0, 0.2, like=first)  # other direction: resampled
    assert like._c == alone._c and like.stats == alone.stats
    back = SpeedProfile(f.path, SpeedProfileSpec(3.0), f.limits, -1.0, 0.2, like=like)
    assert back._geo.path_geo is like._geo.path_geo and back._c == alone._c and back.stats == alone.stats
    assert all(math.isfinite(x) for x in alone.stats)
