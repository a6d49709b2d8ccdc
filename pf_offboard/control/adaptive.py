"""Online identification of the inner loop's response (lag and dead time) for the compensator.

The default :class:`~pf_offboard.control.types.VehicleModel` is a guess (lag 0.1 s, delay 0.1 s):
PX4 SIH answers after about 0.24 s, a simulator's ideal attitude loop after 0.01 s, a ``rates``
output adds the caller's own attitude loop (0.25 s). A predictor built on the wrong dead time acts
on the state at the wrong instant and leaves centimetres of error that no gain removes. This bank
of models scores candidate (lag, delay) pairs against the measured horizontal velocity, each with
its own slow disturbance observer (so that a constant drag or wind is absorbed, not the dynamic
mismatch), and names the one that explains the flight best. The compensator (on by default, with
the typical model only) gives it the model's lag and the dead times up to the model's: it may only
shorten the dead time (docs/controller.md, Identifying the inner loop in flight).

Per candidate ``k`` and horizontal axis: ``a_f' = (gain a_sp(t - delay_k) - a_f) / lag_k``,
``v_k' = a_f + d_k + l1 (v - v_k)``, ``d_k' = l2 (v - v_k)``; score = low-passed ``|v - v_k|^2``.
Pure, I/O-free; the setpoints come from the compensator's history.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

Vec = tuple[float, float, float]

DELAYS_S = (0.0, 0.02, 0.04, 0.06, 0.08, 0.1, 0.13, 0.16, 0.2, 0.25, 0.3)
LAGS_S = (0.01, 0.03, 0.05, 0.075, 0.1, 0.15, 0.2, 0.27, 0.35)
OBSERVER_RAD_S = 1.0  # the candidates' own disturbance observers: slow, bias only
DRAG_RATE = 4.0  # adaptation gain of the candidates' linear drag (1/m^2)
MAX_DRAG_1_S = 3.0
SCORE_TIME_S = 4.0  # the score's memory
MIN_DATA_S = 3.0  # of scored flight before a candidate is adopted
ADOPT_RATIO = 0.8  # the initial model is left only for a candidate with less than this share of its score
SWITCH_RATIO = 0.6  # a candidate replaces the active one when its score is below this share of it


@dataclass(frozen=True)
class IdentifiedModel:
    """What the identifier adopted in flight: the horizontal response's first-order lag and dead
    time, its linear drag then (the compensator keeps following the estimate) and when (the
    controller's clock, s)."""

    lag_s: float
    delay_s: float
    drag_1_s: float
    adopted_at_s: float


class ResponseIdentifier:
    """A bank of first-order-lag + dead-time models of the horizontal acceleration response."""

    def __init__(self, gain_xy: float = 1.0, delays_s: Sequence[float] = DELAYS_S, lags_s: Sequence[float] = LAGS_S,
                 initial: tuple[float, float] = (0.1, 0.1), min_long_lag_delay_s: float = 0.0,
                 max_long_lag_response_s: float = math.inf) -> None:  # fmt: skip
        """``initial``: the (lag, delay) the compensator starts with (a candidate is added for it):
        another candidate is adopted only when it explains the flight clearly better
        (ADOPT_RATIO of its score). A candidate whose lag is longer than the initial one is adopted
        only with a delay of at least ``min_long_lag_delay_s`` and a lag + delay of at most
        ``max_long_lag_response_s`` (the others are scored all the same)."""
        self.gain = gain_xy
        self.delays = tuple(sorted({float(d) for d in delays_s} | {float(initial[1])}))
        self.lags = tuple(sorted({float(x) for x in lags_s} | {float(initial[0])}))
        nl = len(self.lags)
        self.initial_index = self.delays.index(float(initial[1])) * nl + self.lags.index(float(initial[0]))
        self.max_delay_s = max(self.delays)
        lag0, floor, ceiling = float(initial[0]), float(min_long_lag_delay_s) - 1e-9, float(max_long_lag_response_s) + 1e-9
        self.allowed = tuple(k for k in range(len(self.delays) * nl)  # the candidates that may be adopted
                             if self.lags[k % nl] <= lag0
                             or floor <= self.delays[k // nl] <= ceiling - self.lags[k % nl])  # fmt: skip
        self.reset()

    def reset(self) -> None:
        n = len(self.delays) * len(self.lags)
        self._a = [[0.0, 0.0] for _ in range(n)]
        self._v = [[0.0, 0.0] for _ in range(n)]
        self._d = [[0.0, 0.0] for _ in range(n)]
        self._drag = [0.0] * n
        self.score = [0.0] * n
        self._t: float | None = None
        self.data_s = 0.0
        self.active: int | None = None

    def candidate(self, k: int) -> tuple[float, float]:
        """(lag s, delay s) of candidate ``k``."""
        nl = len(self.lags)
        return self.lags[k % nl], self.delays[k // nl]

    @property
    def drag_1_s(self) -> float | None:
        """The active candidate's horizontal linear drag (1/s), None before one is adopted."""
        return None if self.active is None else self._drag[self.active]

    def update(self, time_s: float, velocity: Vec,
               pieces: Callable[[float, float, float], list[tuple[float, Vec]]]) -> tuple[float, float] | None:  # fmt: skip
        """Advance every candidate to ``time_s`` with the setpoints acting then (``pieces(t0, t1,
        delay)``, as the compensator's), correct with the measured ``velocity``; return the (lag,
        delay) to adopt, or None to keep the current model."""
        t_prev, self._t = self._t, time_s
        vx, vy = velocity[0], velocity[1]
        if t_prev is None:
            for v in self._v:
                v[0], v[1] = vx, vy
            return None
        dt = time_s - t_prev
        if dt <= 0.0:
            return None
        nl = len(self.lags)
        w = OBSERVER_RAD_S
        l1, l2 = 2.0 * w * dt, w * w * dt
        c = min(1.0, dt / SCORE_TIME_S)
        g = self.gain
        for i, delay in enumerate(self.delays):
            segs = pieces(t_prev, time_s, delay)
            for j, lag in enumerate(self.lags):
                k = i * nl + j
                a, v, d = self._a[k], self._v[k], self._d[k]
                cd = self._drag[k]
                for h, sp in segs:
                    if h <= 0.0:
                        continue
                    alpha = math.exp(-h / lag)
                    m = (lag / h) * (1.0 - alpha)
                    for ax in (0, 1):
                        u = g * sp[ax]
                        mean_a = u + (a[ax] - u) * m
                        a[ax] = u + (a[ax] - u) * alpha
                        v[ax] += h * (mean_a + d[ax] - cd * velocity[ax])
                ex, ey = vx - v[0], vy - v[1]
                cd -= DRAG_RATE * dt * (ex * vx + ey * vy)
                self._drag[k] = 0.0 if cd < 0.0 else (MAX_DRAG_1_S if cd > MAX_DRAG_1_S else cd)
                v[0] += l1 * ex
                v[1] += l1 * ey
                d[0] += l2 * ex
                d[1] += l2 * ey
                self.score[k] += c * (ex * ex + ey * ey - self.score[k])
        self.data_s += dt
        if self.data_s < MIN_DATA_S:
            return None
        best = min(self.allowed, key=self.score.__getitem__)
        current = self.initial_index if self.active is None else self.active
        ratio = ADOPT_RATIO if self.active is None else SWITCH_RATIO
        if best != current and self.score[best] < ratio * self.score[current]:
            self.active = best
            return self.candidate(best)
        return None
