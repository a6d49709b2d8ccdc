"""The batched controller against the scalar PathFollower, at run time, on random states.

Each flight's sequence of states is fed to its own scalar follower (the warm start, the
compensator's memory) and to one BatchFollower row: every output must agree to rounding. States
cover the tube's inside, its edge and far outside (the approach law), speeds that saturate the
allocation, open paths past both ends and the self-intersecting px4-sih loop.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from pf_offboard.config import load_config
from pf_offboard.control import PathFollower
from pf_offboard.sim.batch import BatchFollower

from ..helpers import ROOT

CONFIGS = ROOT / "configs"


def _states(path, n: int, rng: np.random.Generator):  # type: ignore[no-untyped-def]
    lam = rng.uniform(-0.5, path.lam_max + 0.5, n)
    base = np.array([path.eval(float(lam_i)).sigma for lam_i in lam])
    # offsets from 1 cm to 6 m (inside, at the edge and far out of the tube)
    scale = np.geomspace(0.01, 6.0, n)[:, None]
    return base + rng.normal(0.0, 1.0, (n, 3)) * scale, rng.normal(0.0, 3.0, (n, 3))


@pytest.mark.parametrize("name", ["px4-sih", "straight", "speed-profile", "racetrack"])
def test_every_output_equals_the_scalar_follower(name: str) -> None:
    cfg = load_config(CONFIGS / f"{name}.yaml")
    n, steps, dt = 16, 50, 0.01
    rng = np.random.default_rng(11)
    proto = PathFollower.from_config(cfg)
    scalar = [copy.deepcopy(proto) for _ in range(n)]
    batch = BatchFollower(copy.deepcopy(proto), n)
    pos, vel = _states(scalar[0].path, n, rng)
    timed = scalar[0].compensator is not None
    worst: dict[str, float] = {}
    saturated = approach = 0
    for k in range(steps):
        t = dt * k if timed else None
        cb = batch.update(pos, vel, t)
        for i, f in enumerate(scalar):
            c = f.update(pos[i], vel[i], t)
            pairs = {
                "acceleration": (c.acceleration, cb.acceleration[i]),
                "attitude": (c.attitude, cb.attitude[i]),
                "body_rates": (c.body_rates, cb.body_rates[i]),
                "state": (np.array(c.state), np.array([cb.eta1[i], cb.eta2[i], cb.xi1[i], cb.xi2[i], cb.phi1[i], cb.phi2[i]])),
                "lam": (c.lam, cb.lam[i]),
                "cross_track": (c.cross_track_m, cb.cross_track_m[i]),
                "yaw": ((c.yaw, c.yaw_rate, c.thrust, c.eta2_ref_m_s), (cb.yaw[i], cb.yaw_rate[i], cb.thrust[i], cb.eta2_ref_m_s[i])),
            }
            for key, (a, b) in pairs.items():
                worst[key] = max(worst.get(key, 0.0), float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)))))
            sat = (cb.sat_tangential[i], cb.sat_transversal[i], cb.sat_tilt[i], cb.sat_thrust[i], cb.sat_approach_speed[i])
            assert tuple(c.saturation) == tuple(bool(x) for x in sat), (name, k, i)
            saturated += bool(c.saturation.transversal or c.saturation.tilt)
            approach += c.cross_track_m > 1.0
        pos = pos + dt * vel
        vel = vel + dt * cb.acceleration + rng.normal(0.0, 0.05, vel.shape)
    assert max(worst.values()) <= 1e-9, worst
    assert saturated > 0 and approach > 0  # the limits and the approach law were exercised


def test_identifying_followers_equal_the_scalar_ones_adoption_by_adoption() -> None:
    """``compensation.identify_online`` (the typical model): on these random states some flights
    adopt a shorter dead time at different instants and some keep the model, so the batch
    compensator predicts over a horizon per flight. Outputs and the identified models agree."""
    cfg = load_config(CONFIGS / "figure8.yaml")
    cfg = dataclasses.replace(cfg, compensation=dataclasses.replace(cfg.compensation, identify_online=True))
    n, steps, dt = 16, 250, 0.02  # the default config's 50 Hz
    rng = np.random.default_rng(11)
    proto = PathFollower.from_config(cfg)
    assert proto.compensator is not None and proto.compensator.identifier is not None
    scalar = [copy.deepcopy(proto) for _ in range(n)]
    batch = BatchFollower(copy.deepcopy(proto), n)
    pos, vel = _states(scalar[0].path, n, rng)
    worst = 0.0
    horizons = set()
    for k in range(steps):
        t = dt * k
        cb = batch.update(pos, vel, t)
        for i, f in enumerate(scalar):
            c = f.update(pos[i], vel[i], t)
            for a, b in ((c.acceleration, cb.acceleration[i]), (c.attitude, cb.attitude[i]), (c.state[:2], (cb.eta1[i], cb.eta2[i]))):
                worst = max(worst, float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)))))
        horizons.add(len(set(np.atleast_1d(batch.compensator.horizon_s).tolist())))  # type: ignore[union-attr]
        pos = pos + dt * vel
        vel = vel + dt * cb.acceleration + rng.normal(0.0, 0.05, vel.shape)
    assert worst <= 1e-9, worst
    assert max(horizons) >= 3  # flights predicted over different horizons at once
    found = batch.compensator.identified()  # type: ignore[union-attr]
    models = [f.compensator.identified for f in scalar]
    assert 0 < sum(m is not None for m in models) < n
    for i, m in enumerate(models):
        if m is None:
            assert np.isnan(found["adopted_at_s"][i])
        else:
            for key in ("lag_s", "delay_s", "drag_1_s", "adopted_at_s", "gain_xy"):
                assert abs(getattr(m, key) - float(found[key][i])) <= 1e-9, (i, key)


def test_rollbacks_equal_the_scalar_ones(monkeypatch: pytest.MonkeyPatch) -> None:
    """The rollback guard (compensator.GUARD_*) per flight: made touchy here (fires when the 1 s RMS
    exceeds half its reference) so that, on these random states, some flights roll adoptions back
    at different instants, some to the typical model; outputs, models and rollbacks agree."""
    import pf_offboard.control.compensator as compensator
    import pf_offboard.sim.batch.follower as batch_follower

    for module in (compensator, batch_follower):
        monkeypatch.setattr(module, "GUARD_RATIO", 0.5)
        monkeypatch.setattr(module, "GUARD_MARGIN_M", 0.0)
    cfg = load_config(CONFIGS / "figure8.yaml")
    cfg = dataclasses.replace(cfg, compensation=dataclasses.replace(cfg.compensation, identify_online=True))
    n, steps, dt = 16, 350, 0.02  # the default config's 50 Hz
    rng = np.random.default_rng(5)
    proto = PathFollower.from_config(cfg)
    scalar = [copy.deepcopy(proto) for _ in range(n)]
    batch = BatchFollower(copy.deepcopy(proto), n)
    pos, vel = _states(scalar[0].path, n, rng)
    pos, vel = 0.05 * pos + 0.95 * np.array([scalar[0].path.eval(0.0).sigma] * n), 0.3 * vel  # nearer the path
    worst = 0.0
    for k in range(steps):
        t = dt * k
        cb = batch.update(pos, vel, t)
        for i, f in enumerate(scalar):
            c = f.update(pos[i], vel[i], t)
            for a, b in ((c.acceleration, cb.acceleration[i]), (c.attitude, cb.attitude[i])):
                worst = max(worst, float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)))))
        pos = pos + dt * vel
        vel = vel + dt * cb.acceleration + rng.normal(0.0, 0.05, vel.shape)
    assert worst <= 1e-9, worst
    rolled, found = batch.compensator.rolled_back(), batch.compensator.identified()  # type: ignore[union-attr]
    fired = [f.compensator.rolled_back for f in scalar]
    assert 0 < sum(r is not None for r in fired) < n, [r is not None for r in fired]
    for i, (f, r) in enumerate(zip(scalar, fired)):
        if r is None:
            assert np.isnan(rolled["at_s"][i])
        else:
            assert abs(r.at_s - rolled["at_s"][i]) <= 1e-9 and abs(r.rejected.delay_s - rolled["delay_s"][i]) <= 1e-9
            assert abs(r.cross_track_rms_m - rolled["cross_track_rms_m"][i]) <= 1e-9
        m = f.compensator.identified
        assert (m is None) == np.isnan(found["adopted_at_s"][i])
        if m is not None:
            assert abs(m.delay_s - found["delay_s"][i]) <= 1e-9 and abs(m.adopted_at_s - found["adopted_at_s"][i]) <= 1e-9


@pytest.mark.parametrize("touchy", [False, True])
def test_identifying_followers_replan_their_speed_profile_as_the_scalar_ones(monkeypatch: pytest.MonkeyPatch, touchy: bool) -> None:
    """With a speed profile and ``identify_online``, each flight re-plans for the identified
    response from its own adoption (``PathFollower.identified_profile``, blended in): the batch
    rows follow their scalar followers through the adoptions and the blends. ``touchy``: the
    rollback guard made to fire (as in test_rollbacks_equal_the_scalar_ones), so that flights
    rolled back to the typical model blend the first plan back in, as the scalar ones."""
    from pf_offboard.control.profile import REPLAN_BLEND_S, SpeedProfileSpec

    if touchy:
        import pf_offboard.control.compensator as compensator
        import pf_offboard.sim.batch.follower as batch_follower

        for module in (compensator, batch_follower):
            monkeypatch.setattr(module, "GUARD_RATIO", 0.5)
            monkeypatch.setattr(module, "GUARD_MARGIN_M", 0.0)

    cfg = load_config(CONFIGS / "figure8.yaml")
    cfg = dataclasses.replace(cfg, compensation=dataclasses.replace(cfg.compensation, identify_online=True),
                              speed_profile=SpeedProfileSpec(max_speed_m_s=3.0))  # fmt: skip
    n, steps, dt = 12, 700, 0.01
    rng = np.random.default_rng(11)
    proto = PathFollower.from_config(cfg)
    assert proto.identified_profile is not None
    scalar = [copy.deepcopy(proto) for _ in range(n)]
    batch = BatchFollower(copy.deepcopy(proto), n)
    pos, vel = _states(scalar[0].path, n, rng)
    worst = 0.0
    blending = set()
    for k in range(steps):
        t = dt * k
        cb = batch.update(pos, vel, t)
        for i, f in enumerate(scalar):
            c = f.update(pos[i], vel[i], t)
            for a, b in ((c.acceleration, cb.acceleration[i]), (c.eta2_ref_m_s, cb.eta2_ref_m_s[i]), (c.state[:2], (cb.eta1[i], cb.eta2[i]))):
                worst = max(worst, float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)))))
            assert f._replan_w == batch._replan_w[i]
            if 0.0 < f._replan_w < 1.0:
                blending.add(i)
        pos = pos + dt * vel
        vel = vel + dt * cb.acceleration + rng.normal(0.0, 0.05, vel.shape)
    assert worst <= 1e-9, worst
    if touchy:  # some flights re-planned, then rolled back to the typical model and blended out
        assert any(f._replan_t0 is not None and not f._replan_target for f in scalar)
        return
    starts = {f._replan_t0 for f in scalar}
    assert blending and len(starts) >= 3 and None not in starts, starts  # re-planned at their own instants
    assert any(f._replan_w == 1.0 for f in scalar) and steps * dt > REPLAN_BLEND_S
