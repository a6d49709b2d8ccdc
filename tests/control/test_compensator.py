"""Inner-loop compensation: observer, delay predictor, inversion, integral action, gains from a model.

The plant here is the compensator's own model class (dead time + first-order lag + gain + linear
drag + an unknown disturbance), integrated finely and independently of the compensator's code, so
the tests check the compensator's algebra and the closed loop's invariance and attractiveness on a
non-ideal inner loop. Closed-loop checks against the mock's full quadrotor are in
tests/sim/test_realistic_flight.py.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque

import numpy as np
import pytest

from pf_offboard.control import Compensation, Gains, Limits, PathFollower, VehicleModel
from pf_offboard.control.compensator import (
    MAX_DRAG_FEEDBACK_M_S2,
    OVERSPEED_MARGIN_M_S,
    InnerLoopCompensator,
    drag_velocity,
    overspeed_bounded,
)
from pf_offboard.control.tuning import gains_for_vehicle, phase_margin_deg
from pf_offboard.errors import InputError
from pf_offboard.path import Path

DT_CTRL_S = 0.01
SUBSTEPS = 20


class ModelPlant:
    """dv/dt = a_f - drag v + d(t), tau da_f/dt = gain a_sp(t - delay) - a_f (per axis, ENU)."""

    def __init__(self, model: VehicleModel, position, velocity, disturbance=lambda t: (0.0, 0.0, 0.0), gain_scale=lambda t: 1.0):
        self.m = model
        self.p = np.array(position, float)
        self.v = np.array(velocity, float)
        self.a_f = np.zeros(3)
        self.t = 0.0
        self.d = disturbance
        self.gain_scale = gain_scale
        # one queue per axis group: x/y after accel_delay_s, z after accel_delay_z_s (if given)
        n = int(round(model.accel_delay_s / DT_CTRL_S))
        delay_z = model.accel_delay_s if model.accel_delay_z_s is None else model.accel_delay_z_s
        self.queue: deque[np.ndarray] = deque([np.zeros(3)] * n)
        self.queue_z: deque[float] = deque([0.0] * int(round(delay_z / DT_CTRL_S)))
        self.lag = np.array([model.accel_lag_xy_s, model.accel_lag_xy_s, model.accel_lag_z_s])
        self.gain = np.array([model.accel_gain_xy, model.accel_gain_xy, model.accel_gain_z])
        self.drag = np.array([model.drag_xy_1_s, model.drag_xy_1_s, model.drag_z_1_s])

    def step(self, a_sp) -> None:
        a_sp = np.asarray(a_sp, float)
        self.queue.append(a_sp)
        self.queue_z.append(float(a_sp[2]))
        u = self.queue.popleft().copy()
        u[2] = self.queue_z.popleft()
        u = (u * self.gain * self.gain_scale(self.t)).tolist()
        h = DT_CTRL_S / SUBSTEPS
        hh = 0.5 * h * h
        # the same float operations per axis as the array expressions they replace (bit for bit),
        # on Python floats: numpy's per-call cost on 3-vectors was most of this file's time
        keep = [1.0 - math.exp(-h / lag) if lag > 0 else None for lag in self.lag.tolist()]
        a_f, drag, p, v = self.a_f.tolist(), self.drag.tolist(), self.p.tolist(), self.v.tolist()
        t = self.t
        for _ in range(SUBSTEPS):
            for i in range(3):
                k = keep[i]
                a_f[i] = u[i] if k is None else a_f[i] + (u[i] - a_f[i]) * k
            d = self.d(t)
            for i in range(3):
                acc = a_f[i] - drag[i] * v[i] + float(d[i])
                p[i] += h * v[i] + hh * acc
                v[i] += h * acc
            t += h
        self.a_f[:], self.p[:], self.v[:], self.t = a_f, p, v, t


MODEL = VehicleModel(accel_lag_xy_s=0.08, accel_lag_z_s=0.04, accel_delay_s=0.1, accel_gain_xy=0.8,
                     accel_gain_z=1.1, drag_xy_1_s=0.6, drag_z_1_s=0.4)


def test_observer_learns_a_constant_disturbance() -> None:
    rng = np.random.default_rng(3)
    d = (0.7, -1.2, 0.4)
    plant = ModelPlant(MODEL, (0, 0, 0), (0.5, 0, 0), disturbance=lambda t: d)
    comp = InnerLoopCompensator(MODEL, observer_rad_s=6.0)
    a_sp = np.zeros(3)
    for k in range(500):
        comp.predict(plant.t, tuple(plant.p), tuple(plant.v))
        if k % 20 == 0:  # a rich, arbitrary excitation
            a_sp = rng.normal(0.0, 1.0, 3)
        comp.record(plant.t, tuple(a_sp))
        plant.step(a_sp)
    assert np.allclose(comp.disturbance, d, atol=0.01), comp.disturbance


def test_observer_is_bounded_and_resets() -> None:
    comp = InnerLoopCompensator(MODEL, observer_rad_s=6.0, max_disturbance_m_s2=2.0)
    for k in range(300):  # free fall, commands say hover: a -9.81 m/s^2 "disturbance"
        t = k * DT_CTRL_S
        comp.predict(t, (0.0, 0.0, -0.5 * 9.81 * t * t), (0.0, 0.0, -9.81 * t))
        comp.record(t, (0.0, 0.0, 0.0))
    assert comp.disturbance[2] == pytest.approx(-2.0)  # anti-windup bound
    comp.reset()
    assert comp.disturbance == (0.0, 0.0, 0.0) and comp.integral_offsets() == (0.0, 0.0, 0.0)


def test_an_adopted_drag_is_handed_over_by_the_observer_without_a_jump() -> None:
    """As an adoption slews the model's drag in, d̂ gives up what the drag now explains
    (d̂ += Δdrag ⊙ v̂): the modelled acceleration (−drag·v̂ + d̂) is the same before and after each
    slew step, and at the end d̂ holds only what the drag does not explain (here nothing)."""
    plant = ModelPlant(MODEL, (0, 0, 0), (2.0, -1.0, 0.5))
    comp = InnerLoopCompensator(dataclasses.replace(MODEL, drag_xy_1_s=0.0, drag_z_1_s=0.0), observer_rad_s=4.0)
    a_sp = np.array([1.2, -0.6, 0.2]) / np.array([MODEL.accel_gain_xy, MODEL.accel_gain_xy, MODEL.accel_gain_z])
    jumps = []
    while plant.t < 9.0:
        comp.predict(plant.t, tuple(plant.p), tuple(plant.v))
        if plant.t > 4.0:  # the observer has absorbed the drag: d̂ = -0.6 v (x, y), -0.4 v (z)
            before = [-c * v + d for c, v, d in zip(comp.drag, comp._v_hat, comp.disturbance)]
            comp._move_to_target(DT_CTRL_S, (MODEL.accel_lag_xy_s, MODEL.accel_delay_s), MODEL.drag_xy_1_s,
                                 MODEL.accel_gain_xy, (MODEL.accel_gain_z, MODEL.drag_z_1_s))
            after = [-c * v + d for c, v, d in zip(comp.drag, comp._v_hat, comp.disturbance)]
            jumps.append(max(abs(a - b) for a, b in zip(after, before)))
        comp.record(plant.t, tuple(a_sp))
        plant.step(a_sp)
    assert comp.drag == pytest.approx((0.6, 0.6, 0.4))
    assert max(jumps) < 1e-12
    assert np.allclose(comp.disturbance, 0.0, atol=0.02), comp.disturbance


def test_predictor_is_exact_for_its_model() -> None:
    """With the disturbance known, the prediction equals the plant's own future state."""
    rng = np.random.default_rng(5)
    plant = ModelPlant(MODEL, (1.0, 2.0, 3.0), (0.3, -0.2, 0.1))
    comp = InnerLoopCompensator(MODEL, observer_rad_s=0.0)  # no observer: d = 0 is known
    history = []
    for k in range(200):
        pred = comp.predict(plant.t, tuple(plant.p), tuple(plant.v))
        history.append((plant.t, pred))
        a_sp = rng.normal(0.0, 2.0, 3)
        comp.record(plant.t, tuple(a_sp))
        plant.step(a_sp)
    states = {}
    replay = ModelPlant(MODEL, (1.0, 2.0, 3.0), (0.3, -0.2, 0.1))
    rng = np.random.default_rng(5)
    for k in range(200):
        states[k] = (replay.p.copy(), replay.v.copy())
        replay.step(rng.normal(0.0, 2.0, 3))
    n = int(round(MODEL.accel_delay_s / DT_CTRL_S))
    worst = 0.0
    for k in range(20, 200 - n):
        (p_pred, v_pred) = history[k][1]
        p_true, v_true = states[k + n]
        worst = max(worst, float(np.abs(np.array(p_pred) - p_true).max()), float(np.abs(np.array(v_pred) - v_true).max()))
    # the plant's sub-steps are first order: 2.9e-3 at 5, 0.87e-3 at 20, 0.47e-3 at 50 sub-steps
    assert worst < 1.5e-3, worst


# PX4 answers a vertical acceleration setpoint (thrust) well before a horizontal one (tilt):
# identify on its SIH puts the vertical dead time at 0.00-0.04 s against 0.10-0.15 s.
TWO_DELAYS = VehicleModel(accel_lag_xy_s=0.08, accel_lag_z_s=0.04, accel_delay_s=0.12, accel_delay_z_s=0.03,
                          accel_gain_xy=0.8, accel_gain_z=1.1, drag_xy_1_s=0.6, drag_z_1_s=0.4)


def _prediction_errors(model: VehicleModel, hold: bool) -> np.ndarray:
    """Per axis, the worst |prediction made at t - state of the plant at t + horizon_s| (position
    and velocity), with the setpoints sent as :meth:`outgoing` says (``hold``) or as computed."""
    rng = np.random.default_rng(7)
    plant = ModelPlant(model, (1.0, 2.0, 3.0), (0.3, -0.2, 0.1))
    comp = InnerLoopCompensator(model, observer_rad_s=0.0)  # d = 0 is known
    preds, states = [], []
    for _ in range(200):
        preds.append(comp.predict(plant.t, tuple(plant.p), tuple(plant.v)))
        states.append((plant.p.copy(), plant.v.copy()))
        a = tuple(rng.normal(0.0, 2.0, 3))
        comp.record(plant.t, a)
        plant.step(comp.outgoing(plant.t) if hold else a)
    n = int(round(comp.horizon_s / DT_CTRL_S))
    worst = np.zeros(3)
    for k in range(30, 200 - n):
        (p_pred, v_pred), (p_true, v_true) = preds[k], states[k + n]
        worst = np.maximum(worst, np.maximum(np.abs(np.array(p_pred) - p_true), np.abs(np.array(v_pred) - v_true)))
    return worst


def test_two_delays_predict_one_instant_and_hold_the_faster_group() -> None:
    """With a vertical delay shorter than the horizontal one, the prediction is the whole state at
    one instant (t + the longer delay), and it is exact once the vertical setpoints go out late by
    the difference; sent as computed, the vertical prediction is wrong."""
    comp = InnerLoopCompensator(TWO_DELAYS)
    assert comp.horizon_s == pytest.approx(0.12) and comp.hold_s == pytest.approx((0.0, 0.0, 0.09)) and comp.holds
    worst = _prediction_errors(TWO_DELAYS, hold=True)
    assert worst.max() < 1.5e-3, worst  # the plant's first-order sub-steps, as for one delay
    unheld = _prediction_errors(TWO_DELAYS, hold=False)
    assert unheld[:2].max() < 1.5e-3 and unheld[2] > 20 * 1.5e-3, unheld  # measured z: 0.15
    single = InnerLoopCompensator(MODEL)
    assert single.horizon_s == MODEL.accel_delay_s and not single.holds


def test_outgoing_sends_each_axis_its_hold_late() -> None:
    comp = InnerLoopCompensator(TWO_DELAYS)
    assert comp.outgoing(0.0) == (0.0, 0.0, 0.0)  # nothing computed yet
    for k in range(30):
        t = k * DT_CTRL_S
        comp.record(t, (float(k), -float(k), 100.0 + k))
        sent = comp.outgoing(t)
        assert sent[:2] == (float(k), -float(k))  # x/y: never held
        # z: the value computed 0.09 s (9 steps) ago; the first one while the history is shorter
        assert sent[2] == 100.0 + max(0, k - 9), (k, sent)


def test_path_invariant_and_close_with_two_delays() -> None:
    """The closed loop on the paper path with a faster vertical group stays invariant (model
    exact: max cross-track 1.1 mm). Predicting each group over its own delay, as before the hold,
    gave the law a state at two instants: the same flight limit-cycled at 8.7 cm, 8.9 cm/s."""
    p0 = _paper_path().eval_floats(0.0)[0:3]
    log = _fly(TWO_DELAYS, TWO_DELAYS, p0, (0, 0, 0), 40.0, lambda t: (0.5, -0.3, 0.2))
    late = log[log[:, 0] > 20.0]
    assert float(np.max(late[:, 1])) < 2e-3, float(np.max(late[:, 1]))
    assert abs(float(np.mean(late[:, 2]))) < 2e-3


def test_inversion_gives_the_requested_acceleration() -> None:
    comp = InnerLoopCompensator(MODEL)
    comp.disturbance = (0.3, -0.4, 0.5)
    v = (1.0, -2.0, 0.5)
    a = (0.7, 0.1, -0.3)
    sp = comp.invert(0.0, a, v)
    gain = (MODEL.accel_gain_xy, MODEL.accel_gain_xy, MODEL.accel_gain_z)
    drag = (MODEL.drag_xy_1_s, MODEL.drag_xy_1_s, MODEL.drag_z_1_s)
    flown = [gain[i] * sp[i] - drag[i] * v[i] + comp.disturbance[i] for i in range(3)]
    assert np.allclose(flown, a, atol=1e-12)


def test_drag_feedback_on_the_deviation_from_the_reference_velocity_is_bounded() -> None:
    """Drag inverted at the velocity is positive velocity feedback: with the reference velocity the
    inversion feeds the drag forward at it and adds at most MAX_DRAG_FEEDBACK_M_S2 per axis for
    the deviation, whatever the drag (the fit's bound, 3 1/s) and however fast the vehicle flies."""
    drag, v_ref = (3.0, 3.0, 0.0), (2.4, 0.0, 0.1)
    small = (2.5, 0.05, 0.3)  # within the bound: exactly the velocity
    assert drag_velocity(drag, small, v_ref) == pytest.approx(small, abs=1e-12)
    for fast in ((3.9, 0.0, 0.1), (9.0, -4.0, 2.0)):
        vd = drag_velocity(drag, fast, v_ref)
        assert all(abs(drag[i] * (vd[i] - v_ref[i])) <= MAX_DRAG_FEEDBACK_M_S2 + 1e-12 for i in range(2))
        assert vd[2] == pytest.approx(fast[2])  # no drag on the axis: nothing fed back


def test_overspeed_scales_only_the_forward_push() -> None:
    """Faster than the reference by more than the margin, the compensation's push along the velocity
    is scaled to the reference's: the perpendicular part and any braking push are kept."""
    v, ref = (4.0, 0.0, 0.0), (2.4, 0.0, 0.0)
    out = overspeed_bounded((3.0, 1.0, -0.5), v, ref)
    assert out == pytest.approx((3.0 * (2.4 + OVERSPEED_MARGIN_M_S) / 4.0, 1.0, -0.5), abs=1e-12)
    assert overspeed_bounded((-3.0, 1.0, 0.0), v, ref) == (-3.0, 1.0, 0.0)  # braking: kept
    assert overspeed_bounded((3.0, 1.0, 0.0), (2.5, 0.0, 0.0), ref) == (3.0, 1.0, 0.0)  # within the margin
    comp = InnerLoopCompensator(VehicleModel(drag_xy_1_s=1.0))
    sp = comp.invert(0.0, (0.0, 0.0, 0.0), v, ref)  # drag 1 1/s at 4 m/s: 2.9 m/s (feedback bound), scaled
    assert sp[0] == pytest.approx((2.4 + MAX_DRAG_FEEDBACK_M_S2) * (2.4 + OVERSPEED_MARGIN_M_S) / 4.0, abs=1e-12)


def test_bad_settings_are_named() -> None:
    with pytest.raises(InputError, match="observer_rad_s"):
        InnerLoopCompensator(MODEL, observer_rad_s=math.nan)
    with pytest.raises(InputError, match="vehicle.accel_delay_s"):
        VehicleModel(accel_delay_s=-0.1)


# ---------------------------------------------------------------------------------- closed loop
def _paper_path() -> Path:
    from pf_offboard.config import load_config

    cfg = load_config(__import__("pathlib").Path(__file__).parents[2] / "configs" / "paper.yaml")
    return Path.from_waypoints(cfg.path.waypoints_enu_m, closed=True, frame=cfg.path.moving_frame)


def _fly(model_true: VehicleModel, model_ctrl: VehicleModel | None, start_p, start_v, seconds: float,
         disturbance=lambda t: (0.0, 0.0, 0.0), gain_scale=lambda t: 1.0, speed: float = -1.5):
    path = _paper_path()
    comp = InnerLoopCompensator(model_ctrl) if model_ctrl is not None else None
    gains = gains_for_vehicle(model_ctrl or model_true)
    f = PathFollower(path, speed, gains=gains, limits=Limits(max_tilt_deg=45.0, max_thrust_m_s2=20.0), compensator=comp,
                     compensation=None if comp is not None else Compensation.off())
    plant = ModelPlant(model_true, start_p, start_v, disturbance, gain_scale)
    log = []
    for _ in range(int(round(seconds / DT_CTRL_S))):
        cmd = f.update(tuple(plant.p), tuple(plant.v), time_s=plant.t)
        log.append((plant.t, cmd.cross_track_m, cmd.state.eta2 - speed))
        plant.step(cmd.acceleration)
    return np.array(log)


def test_disturbances_leave_no_steady_error() -> None:
    """Drag, a 3 m/s-wind-like force, a 25 % wrong gain (hover thrust) and a battery sag (gain
    falling 15 % over the flight): after convergence the cross-track error and the mean speed
    error vanish; without compensation the same vehicle flies slow and off the path."""
    p0 = _paper_path().eval_floats(0.0)[0:3]
    true = VehicleModel(accel_lag_xy_s=0.08, accel_lag_z_s=0.04, accel_delay_s=0.1, accel_gain_xy=0.75,
                        accel_gain_z=0.75, drag_xy_1_s=1.0, drag_z_1_s=0.5)
    # identified horizontal response; no drag, and the hover thrust (vertical gain) 25 % off
    ctrl = VehicleModel(accel_lag_xy_s=0.08, accel_lag_z_s=0.04, accel_delay_s=0.1, accel_gain_xy=0.75)
    wind = lambda t: (2.0, -1.5, 0.0)  # noqa: E731 - wind force per unit mass, m/s^2
    sag = lambda t: 1.0 - 0.15 * min(t / 40.0, 1.0)  # noqa: E731
    log = _fly(true, ctrl, p0, (0, 0, 0), 40.0, wind, sag)
    late = log[log[:, 0] > 25.0]
    ct_rms = float(np.sqrt(np.mean(late[:, 1] ** 2)))
    speed_mean = float(np.mean(late[:, 2]))
    print(f"compensated: cross-track RMS {ct_rms:.4f} m, mean speed error {speed_mean:.4f} m/s")
    assert ct_rms < 0.03 and abs(speed_mean) < 0.01, (ct_rms, speed_mean)  # measured 0.020 m, -0.002 m/s
    base = _fly(true, None, p0, (0, 0, 0), 40.0, wind, sag)  # the paper's law, same gains
    late_b = base[base[:, 0] > 25.0]
    print(f"paper law: cross-track RMS {float(np.sqrt(np.mean(late_b[:, 1] ** 2))):.4f} m, mean speed error {float(np.mean(late_b[:, 2])):.4f} m/s")
    assert float(np.sqrt(np.mean(late_b[:, 1] ** 2))) > 3 * ct_rms
    assert abs(float(np.mean(late_b[:, 2]))) > 0.05


def test_path_invariant_with_exact_model() -> None:
    """Once on the path, it stays there: with the model exact (incl. a constant disturbance the
    observer has learnt), the cross-track error stays at numerical noise for 30 s."""
    p0 = _paper_path().eval_floats(0.0)[0:3]
    d = lambda t: (0.5, -0.3, 0.2)  # noqa: E731
    log = _fly(MODEL, MODEL, p0, (0, 0, 0), 60.0, d)
    late = log[log[:, 0] > 30.0]
    assert float(np.max(late[:, 1])) < 2e-3, float(np.max(late[:, 1]))
    assert abs(float(np.mean(late[:, 2]))) < 2e-3


@pytest.mark.parametrize("seed", range(6))
def test_attractive_from_random_starts(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    path = _paper_path()
    p0 = np.array(path.eval_floats(rng.uniform(0.0, path.lam_max))[0:3]) + rng.uniform(-2.5, 2.5, 3) * [1, 1, 0.4]
    v0 = rng.uniform(-2.5, 2.5, 3)
    log = _fly(MODEL, MODEL, p0, v0, 25.0)
    within = log[:, 1] < 0.01
    assert within[-500:].all(), float(log[-500:, 1].max())
    t_conv = float(log[np.argmax(within), 0])
    assert t_conv < 15.0


@pytest.mark.parametrize("yaw_mode", ["constant", "tangent"])
def test_lag_lead_replaces_the_roll_pitch_rate_feed_forward(yaw_mode: str) -> None:
    """With the compensator, the lag lead (lag * on-path jerk) anticipates the path's motion and
    the command's body rates carry the yaw-rate feed-forward only: the attitude loop tracks the
    led setpoint, so the paper's omega_ff on top would lead twice. Without it: the paper's omega_ff."""
    from pf_offboard.control import YawSpec
    from pf_offboard.control.feedforward import attitude_from_thrust, body_rates
    from pf_offboard.control.types import GRAVITY_M_S2

    path = _paper_path()
    yaw = YawSpec(mode=yaw_mode)
    speed = -1.5
    gains = gains_for_vehicle(MODEL)
    paper_law = PathFollower(path, speed, gains=gains, yaw=yaw, compensation=Compensation.off())  # the paper's law: no compensator state
    worst_paper = 0.0
    for lam in np.linspace(0.0, path.lam_max, 13)[:-1]:
        q = path.eval_floats(float(lam))
        t = np.array(q[3:6]) / np.linalg.norm(q[3:6])
        p, v = tuple(q[0:3]), tuple(speed * t)
        paper = paper_law.update(p, v)
        # a fresh compensator per state: its first sample has no setpoint history to predict over
        comp = PathFollower(path, speed, gains=gains, yaw=yaw, compensator=InnerLoopCompensator(MODEL))
        cmd = comp.update(p, v, time_s=0.0)
        f = (cmd.acceleration[0], cmd.acceleration[1], cmd.acceleration[2] + GRAVITY_M_S2)
        yaw_only = body_rates(attitude_from_thrust(f, cmd.yaw), cmd.thrust, (0.0, 0.0, 0.0), cmd.yaw_rate)
        np.testing.assert_allclose(cmd.body_rates, yaw_only, atol=1e-12)
        if yaw_mode == "constant":
            assert np.abs(cmd.body_rates).max() < 1e-12
        worst_paper = max(worst_paper, float(np.linalg.norm(paper.body_rates[:2])))
    assert worst_paper > 0.1  # the paper's omega_ff is there without the compensator (rad/s)
    # and the lead itself: accel + lag * jerk per axis
    c = InnerLoopCompensator(MODEL)
    assert c.lead((1.0, 2.0, 3.0), (10.0, -10.0, 5.0)) == pytest.approx((1.0 + 0.8, 2.0 - 0.8, 3.0 + 0.2))


def test_any_state_feed_forward_is_refused_with_the_compensator() -> None:
    with pytest.raises(InputError) as err:
        PathFollower(_paper_path(), -1.5, feedforward="any_state", compensator=InnerLoopCompensator(MODEL))
    assert err.value.field == "feedforward" and "compensation.enabled: false" in err.value.reason
    with pytest.raises(InputError):
        PathFollower(_paper_path(), -1.5, feedforward="any_state")  # the default compensates
    PathFollower(_paper_path(), -1.5, feedforward="any_state", compensation=Compensation.off())  # the paper's ideal inner loop: fine


def test_gains_from_model_keep_the_margin() -> None:
    assert gains_for_vehicle(VehicleModel()) == Gains.paper()  # ideal inner loop: the paper's gains
    assert gains_for_vehicle(VehicleModel.typical()) == Gains()  # the defaults: the typical vehicle's auto gains
    slow = VehicleModel(accel_lag_xy_s=0.2, accel_delay_s=0.1)
    fast = VehicleModel(accel_lag_xy_s=0.05, accel_delay_s=0.05)
    g_slow, g_fast = gains_for_vehicle(slow, 30.0), gains_for_vehicle(fast, 30.0)
    assert g_slow.transversal_bandwidth_hz < g_fast.transversal_bandwidth_hz < Gains.paper().transversal_bandwidth_hz
    w = 2 * math.pi * g_slow.transversal_bandwidth_hz
    z = g_slow.transversal_damping

    def loop(om: float, w: float = w) -> complex:
        s = 1j * om
        return (w * w + 2 * z * w * s) / (s * s * (slow.accel_lag_xy_s * s + 1))

    assert phase_margin_deg(loop) == pytest.approx(30.0, abs=0.5)
    assert gains_for_vehicle(slow, 45.0).transversal_bandwidth_hz < g_slow.transversal_bandwidth_hz


def test_speed_loop_keeps_its_own_margin_uncapped_by_the_transversal_one() -> None:
    """The tangential P gets ``tangential_phase_margin_deg`` on 1 / (s (lag s + 1)), whatever the
    transversal loops get: a real EKF's velocity error is mostly low-frequency, where a faster speed
    loop rejects it (docs/controller.md)."""
    slow = VehicleModel(accel_lag_xy_s=0.2, accel_delay_s=0.1)
    for margin in (30.0, 40.0, 60.0):
        g = gains_for_vehicle(slow, 30.0, margin)
        kd = 2.0 * g.tangential_damping * 2.0 * math.pi * g.tangential_bandwidth_hz

        def loop(om: float, kd: float = kd) -> complex:
            s = 1j * om
            return kd / (s * (slow.accel_lag_xy_s * s + 1))

        assert phase_margin_deg(loop) == pytest.approx(margin, abs=0.5)
        assert g.transversal_bandwidth_hz == gains_for_vehicle(slow, 30.0).transversal_bandwidth_hz
    assert gains_for_vehicle(slow, 30.0, 40.0).tangential_bandwidth_hz > gains_for_vehicle(slow, 30.0).transversal_bandwidth_hz
    assert gains_for_vehicle(slow, 30.0, 60.0).tangential_bandwidth_hz < gains_for_vehicle(slow, 30.0, 40.0).tangential_bandwidth_hz
    with pytest.raises(InputError, match="tangential_phase_margin_deg"):
        gains_for_vehicle(slow, 30.0, 90.0)


def test_reported_speed_stays_finite_far_from_the_path(paper_path) -> None:
    """Outside the tube the exact eta2 at the measured state is singular (1 - kappa xi1 -> 0 at the
    centre of curvature): the reported state uses the speed along the tangent there (a thrown
    start 2.5 m off the path once logged eta2 = 3e9 m/s, a whole-flight speed error of 8e7 m/s)."""
    from pf_offboard.control import PathFollower

    f = PathFollower(paper_path, speed=-1.5, compensator=InnerLoopCompensator(MODEL))
    worst = 0.0
    for i, lam in enumerate(np.linspace(0.05, 0.95, 19) * paper_path.lam_max):
        d1, d2 = paper_path.eval(lam).d1, paper_path.eval(lam).d2
        # just inside the centre of curvature: 1 - kappa xi1 = 1e-7
        n = d2 - np.dot(d2, d1) / np.dot(d1, d1) * d1
        kappa = np.linalg.norm(np.cross(d1, d2)) / np.linalg.norm(d1) ** 3
        y = paper_path.eval(lam).sigma + n / np.linalg.norm(n) * (1.0 - 1e-7) / kappa
        v = 1.5 * d1 / np.linalg.norm(d1)
        f.reset()
        cmd = f.update(y, v, time_s=float(i))
        assert math.isfinite(cmd.state.eta2)
        worst = max(worst, abs(cmd.state.eta2))
    # inside the tube the exact eta2 = v_t / (1 - kappa xi1) is at most 10 |v| (tube bound 0.9)
    assert worst <= 10.0 * 1.5


def test_offset_integrators_run_only_near_the_path() -> None:
    """The offset integrators wait until the vehicle is within OFFSET_INTEGRAL_BAND_M of the path:
    an approach from metres away must not wind them up (it did, to their 0.1 m bound, and the
    vehicle then overshot the path by that much); the speed integrator is not gated."""
    from pf_offboard.control.compensator import OFFSET_INTEGRAL_BAND_M

    comp = InnerLoopCompensator(MODEL)
    for k in range(200):  # 2 s approaching from 0.5-1 m off: frozen
        comp.integrate(k * DT_CTRL_S, 0.1, 1.0 - 0.0025 * k, 0.0, True)
    speed, xi, phi = comp.integral_offsets()
    assert (xi, phi) == (0.0, 0.0) and speed == pytest.approx(0.2, rel=0.02)
    comp.reset()
    near = 0.9 * OFFSET_INTEGRAL_BAND_M
    for k in range(101):  # 1 s at 0.9 band off: integrates at offset_integral_rad_s (1 rad/s)
        comp.integrate(k * DT_CTRL_S, 0.0, 0.0, -0.05, True)
    assert comp.integral_offsets()[2] == pytest.approx(-0.05, rel=0.02)
    comp.reset()
    for k in range(51):
        comp.integrate(k * DT_CTRL_S, 0.0, near * 0.6, near * 0.8, True)  # |e| = 0.9 band: inside
    assert comp.integral_offsets()[1] == pytest.approx(0.27 * OFFSET_INTEGRAL_BAND_M, rel=0.02)
