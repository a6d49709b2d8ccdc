"""Pipeline: pure and deterministic; one step per fresh sample; resets; core failures become a hold."""

import math

import numpy as np
import pytest

from pf_offboard.app.encoders import Encoder
from pf_offboard.app.estimator import Estimator
from pf_offboard.app.pipeline import Pipeline
from pf_offboard.app.profiles import ARDUPILOT, PX4

from .helpers import attitude_quaternion, command, local_position, odometry


class FakeFollower:
    """Stateful like the real one: the command depends on the inputs and on a counter."""

    speed = -1.5

    def __init__(self, fail_at: int | None = None) -> None:
        self.calls = 0
        self.resets = 0
        self.fail_at = fail_at

    def update(self, position, velocity):
        self.calls += 1
        if self.calls == self.fail_at:
            raise ValueError("projection diverged")
        p, v = np.asarray(position), np.asarray(velocity)
        return command(acceleration=-p - v + 0.001 * self.calls, yaw=float(p[0]), thrust=9.81 + p[2])

    def reset(self) -> None:
        self.resets += 1


def telemetry():
    for k in range(20):
        yield attitude_quaternion(4 * k)
        yield local_position(4 * k, (0.01 * k, -0.02 * k, -2.0), (0.1, 0.0, 0.0))


def run(mode: str):
    pipe = Pipeline(FakeFollower(), Encoder(mode, PX4, 1, 1, hover_thrust=0.5))
    out = []
    for msg in telemetry():
        pipe.on_message(msg)
        step = pipe.step()
        if step is not None:
            out.append(step)
    return out


@pytest.mark.parametrize("mode", ["acceleration", "attitude", "rates"])
def test_one_step_per_fresh_sample_and_deterministic(mode: str) -> None:
    a, b = run(mode), run(mode)
    assert len(a) == 20
    for x, y in zip(a, b):
        assert x.setpoint.get_type() == y.setpoint.get_type()
        for name in x.setpoint.get_fieldnames():
            assert getattr(x.setpoint, name) == getattr(y.setpoint, name)
        assert x.record == y.record
    # setpoint timestamps come from the telemetry, not a clock
    assert [s.setpoint.time_boot_ms for s in a] == [4 * k for k in range(20)]
    rec = a[3].record
    assert rec.time_s == pytest.approx(0.012)
    assert rec.position_enu_m == pytest.approx((-0.06, 0.03, 2.0))
    assert rec.speed_ref_m_s == -1.5 and rec.active and rec.mode == "following"


def test_no_step_without_fresh_state() -> None:
    pipe = Pipeline(FakeFollower(), Encoder("acceleration", PX4, 1, 1))
    assert pipe.step() is None
    pipe.on_message(attitude_quaternion(0))
    assert pipe.step() is None
    pipe.on_message(local_position(0))
    assert pipe.step() is not None
    assert pipe.step() is None
    pipe.on_message(local_position(4))
    pipe.mark_consumed()
    assert pipe.step() is None


def test_estimator_reset_resets_the_follower() -> None:
    follower = FakeFollower()
    pipe = Pipeline(follower, Encoder("acceleration", PX4, 1, 1), Estimator("odometry"))
    pipe.on_message(odometry(1000, (0, 0, -2), (0, 0, 0), reset_counter=0))
    assert "estimator_reset" not in pipe.step().record.event
    pipe.on_message(odometry(5000, (2, -1, -2), (0, 0, 0), reset_counter=1))
    step = pipe.step()
    assert follower.resets == 1 and "estimator_reset" in step.record.event


def test_core_failure_sends_hold_and_logs_it() -> None:
    pipe = Pipeline(FakeFollower(fail_at=2), Encoder("acceleration", PX4, 1, 1))
    pipe.on_message(local_position(0))
    assert not pipe.step().encoded.replaced
    pipe.on_message(local_position(4))
    step = pipe.step()
    assert step.command is None and step.encoded.replaced.startswith("controller failed")
    assert math.isnan(step.record.thrust_cmd_m_s2) and "hold" in step.record.event
    assert all(math.isfinite(getattr(step.setpoint, n)) for n in ("afx", "afy", "afz", "yaw"))
    assert pipe.replaced_steps == 1


@pytest.mark.parametrize(("profile", "mode", "lags"), [
    (ARDUPILOT, "rates", (0.1, 0.15)), (ARDUPILOT, "attitude", (0.1,)), (PX4, "rates", (0.1,)), (PX4, "attitude", (0.1,)),
])  # fmt: skip
def test_the_rates_output_through_an_attitude_target_lets_the_identifier_adopt_a_longer_lag(profile, mode, lags) -> None:
    """ArduCopter flies body rates through its own attitude target (Profile.rates_through_attitude_target):
    under the app's attitude loop the response is a longer lag, which the identifier may then adopt
    (closed loop: tests/sim/test_rates_identification.py)."""
    from pf_offboard import Path, PathFollower

    follower = PathFollower(Path.from_waypoints([(0, 0, 2), (2, 0, 2), (2, 2, 2), (0, 2, 2)], closed=True), 1.0)
    Pipeline(follower, Encoder(mode, profile, 1, 1, hover_thrust=0.5))
    assert follower.compensator is not None and follower.compensator.identifier is not None
    assert follower.compensator.identifier.lags == lags


@pytest.mark.parametrize("profile,reference_lag_s", [(PX4, 0.075), (ARDUPILOT, None)])
def test_the_rates_output_is_the_cores_default_and_starts_over_at_activation(profile, reference_lag_s) -> None:
    """The app's rates output is the core's default (AttitudeTracker.from_vehicle on the follower's
    model: a 0.075 s reference, engaged once the rate loop is identified fast); ArduCopter, which
    flies rates through its own attitude target, keeps the law alone. Activation resets it."""
    from pf_offboard import Path, PathFollower
    from pf_offboard.control import AttitudeTracker, Compensation, VehicleModel

    follower = PathFollower(Path.from_waypoints([(0, 0, 2), (2, 0, 2), (2, 2, 2), (0, 2, 2)], closed=True), 1.0)
    pipe = Pipeline(follower, Encoder("rates", profile, 1, 1, hover_thrust=0.5))
    out = pipe.encoder.rates_output
    assert isinstance(out, AttitudeTracker) and out.law is pipe.encoder.rate_law
    assert out.reference_lag_s == (None if reference_lag_s is None else pytest.approx(reference_lag_s))
    assert (out.rate_loop is not None) is (reference_lag_s is not None)
    default = AttitudeTracker.from_vehicle(VehicleModel.typical())
    if reference_lag_s is not None:
        assert default.reference_lag_s == pytest.approx(out.reference_lag_s)
    # the encoder copies the dialect makes keep it
    assert pipe.encoder.with_hover_thrust(0.4).rates_output is out
    resets = []
    out.reset = lambda: resets.append(1)  # type: ignore[method-assign]
    for msg in telemetry():
        pipe.on_message(msg)
        pipe.step(active=len(resets) > 0 or msg.get_type() == "LOCAL_POSITION_NED" and msg.time_boot_ms >= 40)
    assert resets == [1]
    # without an inner-loop model (no compensation) there is no lag to answer with: the law alone
    bare = PathFollower(Path.from_waypoints([(0, 0, 2), (2, 0, 2), (2, 2, 2)]), 1.0, compensation=Compensation.off())
    assert Pipeline(bare, Encoder("rates", PX4, 1, 1, hover_thrust=0.5)).encoder.rates_output.reference_lag_s is None


def test_an_adoption_and_its_rollback_are_logged_once_each() -> None:
    """The compensator's ``identified`` (an adoption) and ``rolled_back`` (the guard undid it):
    one ``identified: ...`` event, then one ``rolled_back: ...``; the model restored (none here) is
    not logged as an adoption."""
    from types import SimpleNamespace

    from pf_offboard.control.adaptive import IdentifiedModel
    from pf_offboard.control.compensator import RolledBack

    bad = IdentifiedModel(0.1, 0.25, 3.0, 0.02, gain_xy=0.5, gain_z=0.5, drag_z_1_s=3.0)

    class Timed(FakeFollower):
        compensator = SimpleNamespace(identified=None, rolled_back=None)

        def update(self, position, velocity, time_s=None):  # type: ignore[no-untyped-def]
            comp = self.compensator
            if self.calls == 5:
                comp.identified = bad
            if self.calls == 10:
                comp.identified, comp.rolled_back = None, RolledBack(bad, time_s, 0.11, 0.024, 0.4, 0.06)
            return super().update(position, velocity)

    pipe = Pipeline(Timed(), Encoder("attitude", PX4, 1, 1, hover_thrust=0.5))
    events = []
    for msg in telemetry():
        pipe.on_message(msg)
        step = pipe.step()
        if step is not None and step.record.event:
            events.append(step.record.event)
    assert sum(e.count("identified: ") for e in events) == 1
    rolled = [e for e in events if e.startswith("rolled_back: ")]
    assert len(rolled) == 1 and "delay_s=0.25" in rolled[0] and "gain_xy=0.5" in rolled[0] and "reference_cross_track_rms_m=0.024" in rolled[0]
