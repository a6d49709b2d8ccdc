""":class:`pf_offboard.control.adaptive.ResponseIdentifier` for N flights sampled at the same
instants: the same candidate bank, the same update order and the same adoption rule, each
candidate's state an array over the flights (one Python loop over the candidates, as the scalar's).

Built from the scalar identifier (its bank and initial candidate), whose module constants it
reads, so a change of those reaches both engines; a change of its *code* needs the mirrored edit
here (tests/sim/batch/ compare whole flights with the identification on).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pf_offboard.control import adaptive as A

Arr = NDArray[np.float64]
V = tuple[Arr, Arr, Arr]


class BatchIdentifier:
    """The bank of (lag, dead time) models per flight. ``active``: the adopted candidate per flight
    (-1: none yet, the scalar's None)."""

    def __init__(self, scalar: Any, n: int) -> None:
        self.gain = scalar.gain
        self.delays = scalar.delays
        self.lags = scalar.lags
        self.initial_index = scalar.initial_index
        self.max_delay_s = scalar.max_delay_s
        self.barred = np.ones(len(self.delays) * len(self.lags), dtype=bool)  # never adopted (scalar.allowed)
        self.barred[list(scalar.allowed)] = False
        self.n = n
        nl = len(self.lags)
        k = len(self.delays) * nl
        self.cand_lag = np.array([self.lags[i % nl] for i in range(k)])
        self.cand_delay = np.array([self.delays[i // nl] for i in range(k)])
        self.reset()

    def reset(self) -> None:
        n, k = self.n, len(self.delays) * len(self.lags)
        self._a = [[np.zeros(n), np.zeros(n)] for _ in range(k)]
        self._v = [[np.zeros(n), np.zeros(n)] for _ in range(k)]
        self._d = [[np.zeros(n), np.zeros(n)] for _ in range(k)]
        self._drag = [np.zeros(n) for _ in range(k)]
        self.score = np.zeros((k, n))
        self._t: float | None = None
        self.data_s = 0.0
        self.active = np.full(n, -1, dtype=np.int64)

    @property
    def drag_1_s(self) -> Arr:
        """The active candidate's drag per flight (NaN where none is adopted: the scalar's None)."""
        drag = np.array(self._drag)
        rows = np.arange(self.n)
        return np.where(self.active >= 0, drag[np.maximum(self.active, 0), rows], math.nan)

    def update(self, time_s: float, velocity: V, pieces: Callable[[float, float, float], list[tuple[float, V | None]]]) -> tuple[NDArray[np.bool_], Arr, Arr] | None:  # fmt: skip
        """:meth:`ResponseIdentifier.update`: (adopted now per flight, its lag, its delay), or None
        when no flight can adopt at this step."""
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
        w = A.OBSERVER_RAD_S
        l1, l2 = 2.0 * w * dt, w * w * dt
        c = min(1.0, dt / A.SCORE_TIME_S)
        g = self.gain
        score = self.score
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
                        u = g * sp[ax] if sp is not None else g * 0.0
                        mean_a = u + (a[ax] - u) * m
                        a[ax] = u + (a[ax] - u) * alpha
                        v[ax] = v[ax] + h * (mean_a + d[ax] - cd * velocity[ax])
                ex, ey = vx - v[0], vy - v[1]
                cd = cd - A.DRAG_RATE * dt * (ex * vx + ey * vy)
                self._drag[k] = np.where(cd < 0.0, 0.0, np.where(cd > A.MAX_DRAG_1_S, A.MAX_DRAG_1_S, cd))
                v[0] = v[0] + l1 * ex
                v[1] = v[1] + l1 * ey
                d[0] = d[0] + l2 * ex
                d[1] = d[1] + l2 * ey
                score[k] = score[k] + c * (ex * ex + ey * ey - score[k])
        self.data_s += dt
        if self.data_s < A.MIN_DATA_S:
            return None
        best = np.argmin(np.where(self.barred[:, None], np.inf, score), axis=0)  # the first of equal scores, as min(allowed, key=)
        rows = np.arange(self.n)
        none = self.active < 0
        current = np.where(none, self.initial_index, self.active)
        ratio = np.where(none, A.ADOPT_RATIO, A.SWITCH_RATIO)
        adopt = (best != current) & (score[best, rows] < ratio * score[current, rows])
        self.active = np.where(adopt, best, self.active)
        return adopt, self.cand_lag[best], self.cand_delay[best]
