"""Gains from an identified vehicle: the largest bandwidths that keep a stated phase margin.

With the :class:`~pf_offboard.control.compensator.InnerLoopCompensator` predicting the delay and
inverting gain and drag, the plant each loop sees is ``e^(-s r) / (s^k (lag s + 1))`` (k = 2 for
the transversal position loops, k = 1 for the tangential velocity loop), where ``r`` is the part of
the delay the prediction may miss (``UNMODELLED_DELAY_SHARE`` of it: identification is never
exact). The transversal PD ``kp + kd s`` (``kp = w², kd = 2 ζ w``) and the tangential P ``kd_t``
are then raised until the loop's phase margin falls to ``phase_margin_deg``, and capped at the
paper's gains (6 Hz / 0.7, 4 Hz / 0.8), which suit an ideal inner loop only.
"""

from __future__ import annotations

import cmath
import functools
import math

from pf_offboard.control.types import Gains, VehicleModel
from pf_offboard.errors import InputError

UNMODELLED_DELAY_SHARE = 0.0
PAPER = Gains.paper()  # 6 Hz / 0.7 transversal, 4 Hz / 0.8 tangential
TRANSVERSAL_DAMPING = 1.0
TANGENTIAL_DAMPING = 1.0


def phase_margin_deg(transfer) -> float:  # type: ignore[no-untyped-def]
    """Phase margin (deg) of an open loop ``transfer(w) -> L(jw)`` with one gain crossover."""
    lo, hi = 1e-3, 1e4
    for _ in range(100):
        mid = math.sqrt(lo * hi)
        if abs(transfer(mid)) > 1.0:
            lo = mid
        else:
            hi = mid
    phase = cmath.phase(transfer(math.sqrt(lo * hi)))  # in (-pi, pi]
    # the loops here lag by 90..360 deg: unwrap into (-360, 0]
    if phase > 0.0:
        phase -= 2.0 * math.pi
    return 180.0 + math.degrees(phase)


def _plant(lag_s: float, delay_s: float, order: int):  # type: ignore[no-untyped-def]
    def p(w: float) -> complex:
        s = 1j * w
        return cmath.exp(-s * delay_s) / (s**order * (lag_s * s + 1.0))

    return p


def _transversal_loop(bandwidth_hz: float, damping: float, plant):  # type: ignore[no-untyped-def]
    """Open loop of the transversal PD (kp = w², kd = 2 ζ w) on ``plant``."""
    w = 2.0 * math.pi * bandwidth_hz
    return lambda om: (w * w + 2.0 * damping * w * 1j * om) * plant(om)


def _tangential_loop(kd_t: float, plant):  # type: ignore[no-untyped-def]
    """Open loop of the tangential P (``kd_t``, 1/s) on ``plant``."""
    return lambda om: kd_t * plant(om)


def _largest(margin_deg: float, loop_at, lo: float, hi: float) -> float:  # type: ignore[no-untyped-def]
    """Largest parameter in [lo, hi] whose loop keeps the margin (margin falls with it)."""
    if phase_margin_deg(loop_at(hi)) >= margin_deg:
        return hi
    if phase_margin_deg(loop_at(lo)) < margin_deg:
        return lo
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if phase_margin_deg(loop_at(mid)) >= margin_deg:
            lo = mid
        else:
            hi = mid
    return lo


# Below this phase margin (either loop) on a typical multicopter, `fly` warns before it connects
# (paper gains: -177 deg without compensation, -25 deg with it; `gains: auto` keeps 30 deg).
WARN_MARGIN_DEG = 15.0


def margins_deg(gains: Gains, model: VehicleModel, compensated: bool) -> tuple[float, float]:
    """(transversal, tangential) phase margins (deg) of ``gains`` on ``model``'s horizontal inner
    loop: the lag always in the loop, the delay too unless ``compensated`` (the compensator then
    predicts it). A negative margin is a loop that oscillates (the law's limits bound it into a
    limit cycle)."""
    lag = max(model.accel_lag_xy_s, model.accel_lag_z_s)
    r = UNMODELLED_DELAY_SHARE * model.accel_delay_s if compensated else model.accel_delay_s
    return (
        phase_margin_deg(_transversal_loop(gains.transversal_bandwidth_hz, gains.transversal_damping, _plant(lag, r, 2))),
        phase_margin_deg(_tangential_loop(gains.tangential_kd, _plant(lag, r, 1))),
    )


def real_vehicle_warning(gains: Gains, model: VehicleModel, compensated: bool) -> str | None:
    """One line saying why these gains will not fly a real multicopter well, or None.

    Judged on ``model`` when it has a lag or delay (an identified vehicle), else on
    :meth:`VehicleModel.typical` (lag 0.1 s, delay 0.1 s): no real autopilot's inner loop is the
    ideal one the paper assumes."""
    ideal = model.accel_lag_xy_s == 0.0 and model.accel_lag_z_s == 0.0 and model.accel_delay_s == 0.0
    judged = VehicleModel.typical() if ideal else model
    transversal, tangential = margins_deg(gains, judged, compensated)
    if min(transversal, tangential) >= WARN_MARGIN_DEG:
        return None
    on = (f"a typical PX4/ArduPilot inner loop (lag {judged.accel_lag_xy_s:g} s, delay {judged.accel_delay_s:g} s; "
          "the config's vehicle: section is the paper's ideal one, which no real multicopter has)"
          if ideal else f"the config's vehicle model (lag {model.accel_lag_xy_s:g} s, delay {model.accel_delay_s:g} s)")  # fmt: skip
    return (f"gains (transversal {gains.transversal_bandwidth_hz:g} Hz, tangential {gains.tangential_bandwidth_hz:g} Hz) "
            f"leave {transversal:.0f} / {tangential:.0f} deg of phase margin on {on}, "
            f"{'with' if compensated else 'without'} the inner-loop compensation: on a real vehicle expect a limit cycle or "
            "an envelope breach (they suit an ideal inner loop such as sitl-mock --vehicle fast). For a real vehicle use "
            "--config px4-sih / arducopter, or gains: auto with a vehicle: section from pf-offboard identify")  # fmt: skip


def gains_for_vehicle(
    model: VehicleModel, phase_margin_deg_min: float = 30.0, tangential_phase_margin_deg_min: float = 40.0
) -> Gains:
    """Transversal gains for ``model`` with at least ``phase_margin_deg_min``, the tangential (speed)
    loop's with at least ``tangential_phase_margin_deg_min``.

    Horizontal dynamics (the slower axes) set both loops: the path turns in every direction.
    """
    for name, value in (("phase_margin_deg", phase_margin_deg_min), ("tangential_phase_margin_deg", tangential_phase_margin_deg_min)):
        if not (math.isfinite(value) and 10.0 <= value <= 80.0):
            raise InputError(name, f"must be in [10, 80], got {value!r}")
    lag = max(model.accel_lag_xy_s, model.accel_lag_z_s)
    return _gains_for(lag, UNMODELLED_DELAY_SHARE * model.accel_delay_s, float(phase_margin_deg_min), float(tangential_phase_margin_deg_min))


# A pure function of four numbers (a few thousand loop evaluations, ~20 ms): every PathFollower and
# every config with gains: auto asks it, mostly for the same typical vehicle, so it is remembered.
@functools.lru_cache(maxsize=256)
def _gains_for(lag: float, r: float, phase_margin_deg_min: float, tangential_phase_margin_deg_min: float) -> Gains:
    pos_plant = _plant(lag, r, 2)
    vel_plant = _plant(lag, r, 1)
    z = TRANSVERSAL_DAMPING

    def transversal(f_hz: float):  # type: ignore[no-untyped-def]
        return _transversal_loop(f_hz, z, pos_plant)

    def tangential(f_hz: float):  # type: ignore[no-untyped-def]
        return _tangential_loop(2.0 * TANGENTIAL_DAMPING * 2.0 * math.pi * f_hz, vel_plant)

    f_tr = _largest(phase_margin_deg_min, transversal, 0.05, PAPER.transversal_bandwidth_hz)
    # The speed loop has its own margin, not the transversal bandwidth as a cap: a real EKF's
    # velocity error is mostly below 0.7 Hz (docs/sitl-mock-dynamics.md, the estimate's spectrum),
    # where a faster speed loop rejects it. On the real PX4 SIH (five laps from the same start),
    # 1.47 Hz flew 5.0 cm/s RMS against 5.7-6.0 at the transversal 0.93 Hz, at the same
    # cross-track (docs/controller.md, a faster speed loop). A wider margin than
    # the transversal loops' keeps its sensitivity peak, where the loop amplifies the estimate's
    # 1-2 Hz noise, moderate.
    f_tg = _largest(tangential_phase_margin_deg_min, tangential, 0.05, PAPER.tangential_bandwidth_hz)
    if f_tr >= PAPER.transversal_bandwidth_hz and f_tg >= PAPER.tangential_bandwidth_hz:
        return PAPER  # an ideal inner loop: the paper's gains and dampings
    return Gains(round(f_tr, 3), z, round(f_tg, 3), TANGENTIAL_DAMPING)
