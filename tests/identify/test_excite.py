"""The excitation follower on its own: deterministic, bounded, aborting on every limit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pf_offboard.errors import InputError
from pf_offboard.identify.excite import ExcitationFollower, ExcitationSignal, ExcitationSpec


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def _follower(spec: ExcitationSpec, attitude=None) -> tuple[ExcitationFollower, Clock]:
    clock = Clock()
    f = ExcitationFollower(spec, clock, yaw_rad=0.3, attitude=attitude or (lambda: None))
    return f, clock


def _fly(spec: ExcitationSpec, steps: int, dt: float = 0.01, state=None) -> list:
    """Commands along a given state history (default: the vehicle stays at the start, at rest)."""
    f, clock = _follower(spec)
    out = []
    for k in range(steps):
        p, v = state(k * dt) if state else (np.array([1.0, 2.0, 3.0]), np.zeros(3))
        out.append(f.update(p, v))
        clock.t += dt
    return out


def test_same_seed_same_excitation_other_seed_another() -> None:
    a = [c.acceleration for c in _fly(ExcitationSpec(seed=4), 1500)]
    b = [c.acceleration for c in _fly(ExcitationSpec(seed=4), 1500)]
    c = [c.acceleration for c in _fly(ExcitationSpec(seed=5), 1500)]
    assert np.array_equal(np.array(a), np.array(b))
    assert not np.allclose(np.array(a), np.array(c))


def test_settle_then_doublets_bounded_and_zero_mean() -> None:
    spec = ExcitationSpec(duration_s=16.0, settle_s=3.0)
    cmds = _fly(spec, int(20.0 / 0.01))
    acc = np.array([c.acceleration for c in cmds])
    t = np.arange(len(acc)) * 0.01
    assert np.all(acc[t < 3.0] == 0.0)  # at the start, at rest: the hold asks nothing
    exc = acc[(t >= 3.0) & (t < 19.0)]
    assert np.max(np.abs(exc[:, :2])) <= spec.amplitude_xy_m_s2 + 1e-12
    assert np.max(np.abs(exc[:, 2])) <= spec.amplitude_z_m_s2 + 1e-12
    assert np.std(exc, axis=0) == pytest.approx([0.35, 0.35, 0.3], abs=0.15)  # every axis excited
    assert np.all(np.abs(exc.mean(axis=0)) < 0.05)  # doublets: no net push
    assert np.all(acc[t >= 19.5] == 0.0)  # done: hold only
    # the axes are not copies of each other (independent doublets)
    assert abs(np.corrcoef(exc[:, 0], exc[:, 1])[0, 1]) < 0.5
    # attitude and thrust are the acceleration's (ENU, FLU), at the held heading
    c = cmds[500]
    assert c.thrust == pytest.approx(np.linalg.norm(c.acceleration + np.array([0, 0, 9.81])))
    assert c.yaw == 0.3


def test_doublets_steer_towards_the_start() -> None:
    spec = ExcitationSpec(settle_s=0.0, duration_s=10.0, seed=1)
    signal = ExcitationSignal.doublets(spec)
    assert signal.sign_for(0, 0, offset_m=0.5) == -1.0  # east of the start: push west first
    assert signal.sign_for(0, 0, offset_m=-0.5) == 1.0
    assert signal.sign_for(0, 0, offset_m=0.0) == signal.random_sign[0][0]


@pytest.mark.parametrize(
    ("what", "state", "attitude"),
    [
        ("box", lambda t: (np.array([1.0 + 1.2 * (t > 5.0), 2.0, 3.0]), np.zeros(3)), None),
        ("speed", lambda t: (np.array([1.0, 2.0, 3.0]), np.array([0.0, 2.5 * (t > 5.0), 0.0])), None),
        ("tilt", None, lambda: np.array([math.cos(0.35), math.sin(0.35), 0.0, 0.0])),  # 40 deg roll
    ],
)
def test_any_limit_aborts_to_hold(what, state, attitude) -> None:
    spec = ExcitationSpec(settle_s=1.0, duration_s=16.0)
    f, clock = _follower(spec, attitude)
    aborted_at = None
    for k in range(1000):
        p, v = state(k * 0.01) if state else (np.array([1.0, 2.0, 3.0]), np.zeros(3))
        cmd = f.update(p, v)
        if f.abort_reason and aborted_at is None:
            aborted_at = k * 0.01
        clock.t += 0.01
    assert what in f.abort_reason or (what == "box" and "box" in f.abort_reason)
    assert aborted_at is not None and (aborted_at <= 0.01 if what == "tilt" else 5.0 < aborted_at < 5.05)
    # after the abort: hold only (towards the start, no doublets), bounded
    assert np.linalg.norm(cmd.acceleration) <= spec.max_accel_m_s2 + 1e-9
    if what == "box":
        assert cmd.acceleration[0] < 0.0  # back towards the start


def test_bad_specs_are_input_errors() -> None:
    with pytest.raises(InputError, match="--box"):
        ExcitationSpec(box_m=0.0)
    with pytest.raises(InputError, match="--duration"):
        ExcitationSpec(duration_s=600.0)
    with pytest.raises(InputError, match="--max-tilt"):
        ExcitationSpec(max_tilt_deg=math.nan)


def test_a_timed_pipeline_call_flies_the_same_excitation() -> None:
    """A Pipeline built for a compensated follower (configs/px4-sih.yaml) passes each sample's
    time; the excitation runs on its own clock, so the commands are the same (simulate_excitation
    with that config failed on the keyword before)."""
    spec = ExcitationSpec(seed=2)
    plain, clock_a = _follower(spec)
    timed, clock_b = _follower(spec)
    for k in range(800):
        p, v = np.array([1.0, 2.0, 3.0 + 0.01 * math.sin(0.1 * k)]), np.zeros(3)
        a = plain.update(p, v)
        b = timed.update(p, v, time_s=clock_b.t)
        assert a.acceleration == pytest.approx(b.acceleration, abs=0.0)
        clock_a.t += 0.01
        clock_b.t += 0.01
