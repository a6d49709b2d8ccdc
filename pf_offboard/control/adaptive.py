"""Online identification of the inner loop's response (lag, dead time, gain, drag) for the compensator.

The default :class:`~pf_offboard.control.types.VehicleModel` is a guess (lag 0.1 s, delay 0.1 s):
PX4 SIH answers after about 0.24 s, a simulator's ideal attitude loop after 0.01 s, a ``rates``
output adds the caller's own attitude loop (0.25 s). A predictor built on the wrong dead time acts
on the state at the wrong instant and leaves centimetres of error that no gain removes. This bank
of models scores candidate (lag, delay) pairs against the measured horizontal velocity, each with
its own slow disturbance observer (so that a constant drag or wind is absorbed, not the dynamic
mismatch), and names the one that explains the flight best. The compensator (on by default, with
the typical model only) gives it the model's lag and the dead times up to the model's.

A longer dead time than the guess comes with the joint bank: the model's lag with the longer dead
times, each candidate's horizontal gain and drag fitted together by least squares on filtered
signals (exact on a known system). Its shortest dead time that explains the flight decisively
better than the current model, settled, is adopted with its gain and drag (docs/controller.md,
Identifying the inner loop in flight).

Bank, per candidate ``k`` and horizontal axis: ``a_f' = (gain a_sp(t - delay_k) - a_f) / lag_k``,
``v_k' = a_f + d_k + l1 (v - v_k)``, ``d_k' = l2 (v - v_k)``; score = low-passed ``|v - v_k|^2``.
Joint bank: ``F[dv/dt] = g F[a_f] - c F[v] + d`` per axis (F a first-order filter), (g, c, d)
by exponentially forgetting least squares; score = its mean squared residual.
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
# The joint bank (longer dead times, gain and drag fitted): per candidate a least-squares fit of
# F[dv/dt] = gain F[a] - drag F[v] + d (per axis; a: the candidate's lagged, delayed setpoint, unit
# gain; F: a first-order filter of FIT_FILTER_S, so that no velocity is differentiated raw) over an
# exponential memory of FIT_MEMORY_S, with a weak prior (FIT_PRIOR, (m/s^2)^2 s) towards the
# model's gain and no drag where the flight does not excite them; score: its mean squared residual
FIT_FILTER_S = 0.25
FIT_MEMORY_S = 8.0
FIT_WARMUP_S = 4.0 * FIT_FILTER_S
FIT_PRIOR = 0.001
MIN_GAIN, MAX_GAIN = 0.5, 1.5
# A longer dead time than the initial one (a slower loop than the guess, PX4 SIH's 0.24 s) is
# adopted only when settled: this much fitted flight, a score below LONGER_RATIO of the initial
# model's (with its own gain and drag), the setpoints' RMS at least MIN_EXCITATION_M_S2 over the
# memory, the best candidate (or one a delay step beside it) best for SETTLE_S, and its gain and
# drag within these spreads meanwhile
LONGER_MIN_DATA_S = 6.0
LONGER_RATIO = 0.75
MIN_EXCITATION_M_S2 = 0.7
# A joint fit is followed (its gain and drag flown as they move) only while the vehicle moves at
# least this fast (RMS over the fit's memory): hovering, the setpoints' noise-driven jitter still
# passes MIN_EXCITATION_M_S2 (the mock's px4-sih: 1.2-1.7 m/s^2 RMS) but fits no drag
MIN_FIT_SPEED_M_S = 0.5
SETTLE_S = 2.0
SETTLE_GAIN_SPREAD = 0.05
SETTLE_DRAG_SPREAD_1_S = 0.25


@dataclass(frozen=True)
class IdentifiedModel:
    """What the identifier adopted in flight: the horizontal response's first-order lag and dead
    time, its linear drag then (the compensator keeps following the estimate) and when (the
    controller's clock, s); its horizontal gain, and the vertical gain and drag (a joint model's
    fit; else the model's)."""

    lag_s: float
    delay_s: float
    drag_1_s: float
    adopted_at_s: float
    gain_xy: float = 1.0
    gain_z: float = 1.0
    drag_z_1_s: float = 0.0


class _JointFit:
    """The joint bank's least-squares fits (see FIT_*) for one axis group (``axes``: 2 horizontal
    axes sharing a gain and drag, or 1 vertical): shared filtered velocity sums and, per
    candidate, its filtered setpoint's sums."""

    def __init__(self, n: int, gain0: float, axes: int = 2, prior: float = 0.0) -> None:
        self.n, self.gain0, self.axes, self.prior = n, float(gain0), axes, float(prior)
        self.reset()

    def reset(self) -> None:
        n, na = self.n, self.axes
        self._uf = [[0.0] * na for _ in range(n)]  # F[a] per candidate and axis
        self._vf: list[float] | None = None  # F[v] per axis (None: not started)
        self._af = [0.0] * na  # F[dv/dt] per axis
        self.filtered_s = 0.0
        self._v_prev = [0.0] * na
        self.w = 0.0  # the memory's weight (s)
        self._sv = [0.0] * na  # sum of -F[v] per axis (the drag's regressor)
        self._sy = [0.0] * na  # sum of F[dv/dt] per axis
        self._svv = self._syv = self._syy = 0.0  # the axes summed
        self._su = [[0.0] * na for _ in range(n)]
        self._suu = [0.0] * n
        self._suv = [0.0] * n
        self._syu = [0.0] * n
        self.gain = [self.gain0] * n
        self.drag = [0.0] * n
        self.score = [0.0] * n

    def update(self, dt: float, velocity: Sequence[float], means: list[tuple[float, ...]]) -> None:
        """One step of ``dt`` s: ``velocity`` (the group's axes) measured at its end,
        ``means[k]``: candidate k's lagged setpoint averaged over the step (unit gain)."""
        na = self.axes
        if self._vf is None:
            self._vf, self._v_prev = [velocity[i] for i in range(na)], [velocity[i] for i in range(na)]
            for k, m in enumerate(means):
                self._uf[k] = [m[i] for i in range(na)]
            return
        f = 1.0 - math.exp(-dt / FIT_FILTER_S)
        beta = math.exp(-dt / FIT_MEMORY_S)
        vf, af, vp = self._vf, self._af, self._v_prev
        for i in range(na):  # F of the step's means: velocity (trapezoid), acceleration (its change)
            vf[i] += f * (0.5 * (velocity[i] + vp[i]) - vf[i])
            af[i] += f * ((velocity[i] - vp[i]) / dt - af[i])
            vp[i] = velocity[i]
        for k, m in enumerate(means):
            uf = self._uf[k]
            for i in range(na):
                uf[i] += f * (m[i] - uf[i])
        self.filtered_s += dt
        if self.filtered_s < FIT_WARMUP_S:
            return  # the filters' start (their states began unrelated) is not fitted
        y, pv = af, [-x for x in vf]  # F[dv/dt] and the drag's regressor -F[v]
        self.w = beta * self.w + dt
        w = self.w
        sv, sy = self._sv, self._sy
        svv = syv = syy = 0.0
        for i in range(na):
            sv[i] = beta * sv[i] + dt * pv[i]
            sy[i] = beta * sy[i] + dt * y[i]
            svv += pv[i] * pv[i]
            syv += y[i] * pv[i]
            syy += y[i] * y[i]
        self._svv = beta * self._svv + dt * svv
        self._syv = beta * self._syv + dt * syv
        self._syy = beta * self._syy + dt * syy
        # the drag's and the disturbances' part of the normal equations (shared): Schur complements
        # the sums below add in the order sum() would (0 + the first term is exact)
        s_vv = s_yv = s_yy = 0.0
        for i in range(na):
            s_vv += sv[i] * sv[i]
            s_yv += sy[i] * sv[i]
            s_yy += sy[i] * sy[i]
        a22 = self._svv - s_vv / w
        r2 = self._syv - s_yv / w
        yy0 = self._syy - s_yy / w
        g0, rho = self.gain0, self.prior
        s_uu_k, s_uv_k, s_yu_k = self._suu, self._suv, self._syu
        for k in range(self.n):
            uf, su = self._uf[k], self._su[k]
            suu = suv = syu = 0.0
            for i in range(na):
                su[i] = beta * su[i] + dt * uf[i]
                suu += uf[i] * uf[i]
                suv += uf[i] * pv[i]
                syu += y[i] * uf[i]
            s_uu_k[k] = beta * s_uu_k[k] + dt * suu
            s_uv_k[k] = beta * s_uv_k[k] + dt * suv
            s_yu_k[k] = beta * s_yu_k[k] + dt * syu
            s_uu = s_uv = s_yu = 0.0
            for i in range(na):
                s_uu += su[i] * su[i]
                s_uv += su[i] * sv[i]
                s_yu += sy[i] * su[i]
            a11 = s_uu_k[k] - s_uu / w
            a12 = s_uv_k[k] - s_uv / w
            r1 = s_yu_k[k] - s_yu / w
            # (gain, drag) with the prior rho (gain0, 0), then bounded
            b11, b22, c1 = a11 + rho, a22 + rho, r1 + rho * g0
            det = b11 * b22 - a12 * a12
            if not det > 1e-12 * (b11 * b22 + 1e-12):  # nothing excited yet: the model's gain, no drag
                self.gain[k], self.drag[k], self.score[k] = g0, 0.0, 0.0
                continue
            g, cd = (c1 * b22 - a12 * r2) / det, (b11 * r2 - a12 * c1) / det
            g = MIN_GAIN if g < MIN_GAIN else (MAX_GAIN if g > MAX_GAIN else g)
            cd = 0.0 if cd < 0.0 else (MAX_DRAG_1_S if cd > MAX_DRAG_1_S else cd)
            self.gain[k], self.drag[k] = g, cd
            ss = yy0 - 2.0 * (g * r1 + cd * r2) + g * g * a11 + 2.0 * g * cd * a12 + cd * cd * a22
            self.score[k] = max(ss, 0.0) / w


class ResponseIdentifier:
    """A bank of first-order-lag + dead-time models of the horizontal acceleration response, each
    with its own drag fitted in flight; beside it the joint bank (longer dead times), whose gain and
    drag are fitted by least squares."""

    def __init__(self, gain_xy: float = 1.0, delays_s: Sequence[float] = DELAYS_S, lags_s: Sequence[float] = LAGS_S,
                 initial: tuple[float, float] = (0.1, 0.1), min_long_lag_delay_s: float = 0.0,
                 max_long_lag_response_s: float = math.inf, longer_delays_s: Sequence[float] = ()) -> None:  # fmt: skip
        """``initial``: the (lag, delay) the compensator starts with (a candidate is added for it):
        another candidate is adopted only when it explains the flight clearly better
        (ADOPT_RATIO of its score). A candidate whose lag is longer than the initial one is adopted
        only with a delay of at least ``min_long_lag_delay_s`` and a lag + delay of at most
        ``max_long_lag_response_s`` (the others are scored all the same).

        ``longer_delays_s``: the joint bank, the initial lag with these dead times (those longer
        than the initial one) beside the initial candidate, each with its gain and drag fitted
        (FIT_*). While nothing else is adopted, its best is adopted once settled and decisively
        better than the initial one (LONGER_*, SETTLE_*): the compensator then flies its dead
        time, gain and drag (and the gain and drag for the vertical axis: :attr:`vertical`)."""
        self.gain = gain_xy
        self.delays = tuple(sorted({float(d) for d in delays_s} | {float(initial[1])}))
        self.lags = tuple(sorted({float(x) for x in lags_s} | {float(initial[0])}))
        lag0, delay0 = float(initial[0]), float(initial[1])
        self.longer_delays_s = tuple(sorted({float(d) for d in longer_delays_s if float(d) > delay0}))
        nl = len(self.lags)
        self.n_bank = len(self.delays) * nl
        # candidate k: the bank's (delay-major) first, then the joint bank's (its first: the initial)
        self._cand = [(self.lags[k % nl], self.delays[k // nl]) for k in range(self.n_bank)]
        if self.longer_delays_s:
            self._cand += [(lag0, d) for d in (delay0, *self.longer_delays_s)]
        self.joint = tuple(range(self.n_bank, len(self._cand)))
        self.joint_initial = self.n_bank if self.joint else -1
        self._fit = _JointFit(len(self.joint), gain_xy, prior=FIT_PRIOR)
        self.initial_index = self.delays.index(delay0) * nl + self.lags.index(lag0)
        self.max_delay_s = max(d for _, d in self._cand)
        floor, ceiling = float(min_long_lag_delay_s) - 1e-9, float(max_long_lag_response_s) + 1e-9
        self.allowed = tuple(k for k in range(self.n_bank)  # the bank's candidates that may be adopted
                             if self.lags[k % nl] <= lag0
                             or floor <= self.delays[k // nl] <= ceiling - self.lags[k % nl])  # fmt: skip
        self.rejected: frozenset[int] = frozenset()  # candidates the rollback guard undid: never adopted again
        self.reset()

    def reset(self) -> None:
        n = self.n_bank
        self._a = [[0.0, 0.0] for _ in range(n)]
        self._v = [[0.0, 0.0] for _ in range(n)]
        self._d = [[0.0, 0.0] for _ in range(n)]
        self._drag = [0.0] * n
        self.score = [0.0] * n
        self._decays: dict[float, list[tuple[float, float]]] = {}  # step length -> per lag (decay, mean factor)
        self._aj = [[0.0, 0.0] for _ in self.joint]  # the joint candidates' lagged setpoints (unit gain)
        self._fit.reset()
        self.power = 0.0  # low-passed |horizontal setpoint|^2 ((m/s^2)^2)
        self.speed_power = 0.0  # low-passed |horizontal velocity|^2 ((m/s)^2)
        self._t: float | None = None
        self.data_s = 0.0
        self.active: int | None = None
        # the settling of the joint bank's best: (index, since s, gain min/max, drag min/max)
        self._settle: tuple[int, float, float, float, float, float] | None = None

    def reject(self, k: int, previous: int | None) -> None:
        """The rollback guard undid candidate ``k``'s adoption: it is never adopted again (its
        score and fit go on) and ``previous`` (the candidate active before it; None: the initial
        model) is the active one again."""
        self.rejected = self.rejected | {k}
        self.allowed = tuple(j for j in self.allowed if j != k)
        self.active, self._settle = previous, None

    def candidate(self, k: int) -> tuple[float, float]:
        """(lag s, delay s) of candidate ``k``."""
        return self._cand[k]

    def fit(self, k: int) -> tuple[float, float, float, float]:
        """(lag s, delay s, gain, drag 1/s) of candidate ``k`` as fitted so far."""
        lag, delay = self._cand[k]
        if k >= self.n_bank:
            j = k - self.n_bank
            return lag, delay, self._fit.gain[j], self._fit.drag[j]
        return lag, delay, self.gain, self._drag[k]

    @property
    def vertical(self) -> tuple[float, float] | None:
        """The vertical (gain, drag 1/s) to fly with the active joint candidate: its horizontal
        ones (a multicopter's thrust scale and linear drag are common to its axes: SIH's drag is
        isotropic, configs/px4-sih.yaml's identified gains are 0.885 / 0.887; a vertical fit of
        its own at the horizontal dead time was biased, 0.55-0.78, where the vertical response is
        faster); None unless a joint candidate is active."""
        if self.active is None or self.active < self.n_bank:
            return None
        _, _, g, c = self.fit(self.active)
        return g, c

    def joint_score(self, k: int) -> float:
        """Candidate ``k``'s (a joint one) mean squared residual ((m/s^2)^2)."""
        return self._fit.score[k - self.n_bank]

    @property
    def excited(self) -> bool:
        """Whether the setpoints' RMS over the fit's memory reaches MIN_EXCITATION_M_S2."""
        return self.power >= MIN_EXCITATION_M_S2 * MIN_EXCITATION_M_S2

    @property
    def moving(self) -> bool:
        """Whether the horizontal speed's RMS over the fit's memory reaches MIN_FIT_SPEED_M_S: a
        joint fit's drag needs it, and without it (a hover) the fits drift to their prior."""
        return self.speed_power >= MIN_FIT_SPEED_M_S * MIN_FIT_SPEED_M_S

    @property
    def drag_1_s(self) -> float | None:
        """The active candidate's horizontal linear drag (1/s), None before one is adopted."""
        return None if self.active is None else self.fit(self.active)[3]

    @property
    def gain_xy(self) -> float | None:
        """The active candidate's horizontal gain (the model's unless it is a joint one), None
        before one is adopted."""
        return None if self.active is None else self.fit(self.active)[2]

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
        lags, decays = self.lags, self._decays
        if len(decays) > 256:  # the step lengths met so far (a steady rate meets a few): bounded
            decays.clear()
        all_a, all_v, all_d, drag, score = self._a, self._v, self._d, self._drag, self.score
        rate = DRAG_RATE * dt
        for i, delay in enumerate(self.delays):
            # the pieces' (h, u_x, u_y) and, per lag, (exp(-h/lag), (lag/h)(1 - exp(-h/lag)))
            segs = [(h, g * sp[0], g * sp[1]) for h, sp in pieces(t_prev, time_s, delay) if h > 0.0]
            consts = []
            for h, _, _ in segs:
                cs = decays.get(h)
                if cs is None:
                    cs = decays[h] = [(a_, (lag / h) * (1.0 - a_)) for lag in lags for a_ in (math.exp(-h / lag),)]
                consts.append(cs)
            k = i * nl
            for j in range(nl):
                a, v, d = all_a[k], all_v[k], all_d[k]
                cd = drag[k]
                a0, a1, v0, v1 = a[0], a[1], v[0], v[1]
                d0, d1 = d[0], d[1]
                for (h, u0, u1), cs in zip(segs, consts):
                    alpha, m = cs[j]
                    mean_a = u0 + (a0 - u0) * m
                    a0 = u0 + (a0 - u0) * alpha
                    v0 += h * (mean_a + d0 - cd * vx)
                    mean_a = u1 + (a1 - u1) * m
                    a1 = u1 + (a1 - u1) * alpha
                    v1 += h * (mean_a + d1 - cd * vy)
                a[0], a[1] = a0, a1
                ex, ey = vx - v0, vy - v1
                cd -= rate * (ex * vx + ey * vy)
                drag[k] = 0.0 if cd < 0.0 else (MAX_DRAG_1_S if cd > MAX_DRAG_1_S else cd)
                v[0], v[1] = v0 + l1 * ex, v1 + l1 * ey
                d[0], d[1] = d0 + l2 * ex, d1 + l2 * ey
                score[k] += c * (ex * ex + ey * ey - score[k])
                k += 1
        if self.joint:
            self._joint_update(t_prev, time_s, velocity, pieces)
        self.speed_power += min(1.0, dt / FIT_MEMORY_S) * (vx * vx + vy * vy - self.speed_power)
        self.data_s += dt
        if self.data_s < MIN_DATA_S:
            return None
        if self.active is not None and self.active >= self.n_bank:
            return self._joint(time_s)  # a joint model only ever gives way to a longer one
        current = self.initial_index if self.active is None else self.active
        best = min(self.allowed, key=self.score.__getitem__, default=current)
        ratio = ADOPT_RATIO if self.active is None else SWITCH_RATIO
        if best != current and self.score[best] < ratio * self.score[current]:
            self.active = best
            self._settle = None
            return self.candidate(best)
        return self._joint(time_s) if self.active is None and self.joint else None

    def _joint_update(self, t_prev: float, time_s: float, velocity: Vec,
                      pieces: Callable[[float, float, float], list[tuple[float, Vec]]]) -> None:  # fmt: skip
        """The joint bank's step: each candidate's lagged setpoint over the step, then the fits."""
        dt = time_s - t_prev
        now = pieces(t_prev, time_s, 0.0)  # the setpoints' power (the excitation), undelayed
        p = sum(h * (sp[0] * sp[0] + sp[1] * sp[1]) for h, sp in now) / dt
        self.power += min(1.0, dt / FIT_MEMORY_S) * (p - self.power)
        means: list[tuple[float, float]] = []
        segs_of: dict[float, list[tuple[float, Vec]]] = {}
        for j, k in enumerate(self.joint):
            lag, delay = self._cand[k]
            if delay not in segs_of:
                segs_of[delay] = pieces(t_prev, time_s, delay)
            a = self._aj[j]
            rx = ry = 0.0
            for h, sp in segs_of[delay]:
                if h <= 0.0:
                    continue
                alpha = math.exp(-h / lag)
                m = (lag / h) * (1.0 - alpha)
                ux, uy = sp[0], sp[1]
                rx += h * (ux + (a[0] - ux) * m)
                ry += h * (uy + (a[1] - uy) * m)
                a[0] = ux + (a[0] - ux) * alpha
                a[1] = uy + (a[1] - uy) * alpha
            means.append((rx / dt, ry / dt))
        self._fit.update(dt, velocity, means)

    def _joint(self, time_s: float) -> tuple[float, float] | None:
        """Adopt the joint bank's shortest dead time that is settled and decisively better than
        the current model (the initial one or the adopted joint one) with its own gain and drag
        (LONGER_*, SETTLE_*)."""
        fit = self._fit
        base = 0 if self.active is None else self.active - self.n_bank
        # the shortest dead time that explains the flight decisively better: a longer one trades
        # off against the lag (which the joint bank does not vary) and comes with more drag, whose
        # inversion takes damping away (real PX4 SIH: 0.16 s and 1.0 1/s adopted flew 10 cm where
        # 0.13 s and 0.85-0.9 1/s was decisive too); a still longer one may follow, decisively
        # better than that
        bar = LONGER_RATIO * fit.score[base]
        rejected = self.rejected
        j = next((i for i, x in enumerate(fit.score) if i > base and x < bar and self.joint[i] not in rejected), base)
        if j == base:
            self._settle = None
            return None
        best = self.joint[j]
        g, cd = fit.gain[j], fit.drag[j]
        s = self._settle
        if s is None or abs(s[0] - best) > 1:  # a new best (not a delay step beside the last)
            s = (best, time_s, g, g, cd, cd)
        else:
            s = (best, s[1], min(s[2], g), max(s[3], g), min(s[4], cd), max(s[5], cd))
            if s[3] - s[2] > SETTLE_GAIN_SPREAD or s[5] - s[4] > SETTLE_DRAG_SPREAD_1_S:
                s = (best, time_s, g, g, cd, cd)  # still moving: settling starts over
        self._settle = s
        if self.data_s < LONGER_MIN_DATA_S or time_s - s[1] < SETTLE_S:
            return None
        if not self.excited:
            return None
        self.active, self._settle = best, None
        return self.candidate(best)
