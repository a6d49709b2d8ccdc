"""Closest-point projection lambda* = argmin_lambda |y - sigma(lambda)| (eq. 7), warm-started.

Initialisation (first call, after :meth:`Projector.reset`, after a position jump, or when a cheap
periodic global check finds the tracked local minimum clearly worse than the global one): brute
force over the path sampled every <= 5 cm (one vectorised numpy pass), every candidate local
minimum refined by bounded Newton. Otherwise: safeguarded Newton on
``f(lam) = <sigma'(lam), sigma(lam) - y>`` started at the previous lambda* and confined to a small
window around it, so a self-intersection (two branches at the same distance) can never make it
switch branches. O(1) per call after initialisation.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from pf_offboard.errors import InputError
from pf_offboard.path.path import Path

# Newton steps (parameter, ~m) smaller than this are accepted without another evaluation: the
# remaining error is ~step^2 * |f''/f'|, i.e. < 1e-16 here.
_ACCEPT = 1e-8


class Projector:
    """Stateful lambda* tracker for one path.

    ``jump_m``: a position change larger than this between calls re-initialises (global search).
    ``window_m``: the warm-started search stays within +-window_m of the previous lambda*; it must
    be well below the parameter distance between the branches at any self-intersection.
    ``check_every``: every this many calls a coarse global check runs (0 disables it); if the
    tracked point is farther than ``reinit_margin_m`` beyond the global closest sample and twice as
    far, the projector re-initialises (it had lost the path, e.g. far outside the tube).
    """

    def __init__(
        self,
        path: Path,
        *,
        jump_m: float = 1.0,
        window_m: float = 0.5,
        check_every: int = 128,
        reinit_margin_m: float = 1.0,
    ) -> None:
        for name, value in (("jump_m", jump_m), ("window_m", window_m), ("reinit_margin_m", reinit_margin_m)):
            if not (math.isfinite(value) and value > 0.0):
                raise InputError(f"projector.{name}", f"must be a positive number of metres, got {value!r}")
        if check_every < 0:
            raise InputError("projector.check_every", f"must be >= 0 (0 disables the check), got {check_every!r}")
        self.path = path
        self.jump_m = float(jump_m)
        self.window_m = float(window_m)
        self.check_every = int(check_every)
        self.reinit_margin_m = float(reinit_margin_m)
        grid = path._grid
        if path.closed:
            grid = grid[:-1]  # lam_max is lam = 0 again
        self._grid = grid
        self._grid_list = grid.tolist()
        self._samples = path._spline.eval_vectorised(grid, 0)
        self._h = float(np.max(np.diff(path._grid)))
        # Every 4th sample (<= 20 cm apart) for the periodic check: its distance is within
        # 10 cm of the true one, far inside reinit_margin_m.
        self._coarse = self._samples[::4].copy()
        self._eval2 = path._spline.eval2_floats
        self._closed = path.closed
        self._lam_max = path.lam_max
        self.n_global = 0  # how many global (re-)initialisations so far
        self.reset()

    def reset(self) -> None:
        """Forget the warm start: the next :meth:`update` runs the global search."""
        self._lam: float | None = None
        self._y: tuple[float, float, float] | None = None
        self._count = 0
        self._dlam = 0.0
        self.distance_m = math.nan

    @property
    def lam(self) -> float | None:
        """Last lambda* (None before the first update)."""
        return self._lam

    # ------------------------------------------------------------------ internals
    def _newton(self, lam: float, lo: float, hi: float, x: float, y: float, z: float) -> tuple[float, float]:
        """Minimise |sigma - p|^2 / 2 over [lo, hi] from lam (unwrapped parameter).

        Returns (lam, squared distance). Newton where the second derivative is safely positive, else
        a gradient step; steps are confined to [lo, hi] and must not increase the distance (halving).
        A Newton step below ``_ACCEPT`` is taken without re-evaluating: the error after it is of
        order step^2, far below rounding.
        """
        ev = self._eval2
        closed = self._closed
        lmax = self._lam_max
        s = ev(lam % lmax if closed else lam)
        rx, ry, rz = s[0] - x, s[1] - y, s[2] - z
        d2 = rx * rx + ry * ry + rz * rz
        for _ in range(20):
            ax, ay, az = s[3], s[4], s[5]
            g = ax * rx + ay * ry + az * rz
            sp2 = ax * ax + ay * ay + az * az
            hess = sp2 + s[6] * rx + s[7] * ry + s[8] * rz
            newton = hess > 0.1 * sp2
            new = lam - g / hess if newton else lam - g / sp2
            if new < lo:
                new = lo
            elif new > hi:
                new = hi
            step = new - lam
            if step == 0.0:
                break
            if newton and -_ACCEPT < step < _ACCEPT:
                lam = new
                break
            for _ in range(40):
                s2 = ev(new % lmax if closed else new)
                qx, qy, qz = s2[0] - x, s2[1] - y, s2[2] - z
                e2 = qx * qx + qy * qy + qz * qz
                if e2 <= d2 + 1e-13 * (d2 + 1e-9):
                    break
                new = 0.5 * (lam + new)
            else:
                break  # no descent found at all: lam is (numerically) the minimum
            lam, s, rx, ry, rz, d2 = new, s2, qx, qy, qz, e2
        return lam, d2

    def _global(self, x: float, y: float, z: float) -> tuple[float, float]:
        d = self._samples - np.array((x, y, z))
        d2 = np.einsum("ij,ij->i", d, d)
        dmin = float(np.sqrt(d2.min()))
        # Every sampled local minimum that could hide the true minimum (sampling error < h).
        thresh = (dmin + self._h) ** 2
        n = len(d2)
        if self._closed:
            prev, nxt = np.roll(d2, 1), np.roll(d2, -1)
        else:
            prev = np.concatenate([[np.inf], d2[:-1]])
            nxt = np.concatenate([d2[1:], [np.inf]])
        cand = np.flatnonzero((d2 <= prev) & (d2 <= nxt) & (d2 <= thresh))
        best_lam, best_d2 = 0.0, math.inf
        grid = self._grid_list
        for k in cand.tolist():
            lam0 = grid[k]
            lo = grid[k - 1] if k > 0 else (grid[-1] - self._lam_max if self._closed else 0.0)
            hi = grid[k + 1] if k + 1 < n else (self._lam_max if self._closed else grid[k])
            lam, dd = self._newton(lam0, lo, hi, x, y, z)
            if dd < best_d2:
                best_lam, best_d2 = lam, dd
        self.n_global += 1
        return best_lam, best_d2

    # ------------------------------------------------------------------ public
    def seed(self, lam: float, position_enu_m: ArrayLike, near_enu_m: ArrayLike) -> None:
        """Warm-start the next :meth:`update` (of ``position_enu_m``) from another projection: ``lam``,
        the closest point of the nearby ``near_enu_m`` (m, ENU), moved along the path's tangent by
        the first-order share of ``position_enu_m - near_enu_m``. The next update then searches
        around it on the same branch, never globally: two projections of points a fraction of a
        metre apart (a measured state and its prediction) stay on one branch, also where two
        branches are closer than the points' distance to them (a tight helix's turns)."""
        q = position_enu_m.tolist() if isinstance(position_enu_m, np.ndarray) else position_enu_m
        n = near_enu_m.tolist() if isinstance(near_enu_m, np.ndarray) else near_enu_m
        x, y, z = float(q[0]), float(q[1]), float(q[2])
        if not (math.isfinite(lam) and all(math.isfinite(float(c)) for c in (*q, *n))):
            raise InputError("position_enu_m", f"not finite: {[x, y, z]} (seed {lam!r})")
        s = self._eval2(lam % self._lam_max if self._closed else lam)
        d1 = (s[3], s[4], s[5])
        sp2 = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2]
        shift = ((x - float(n[0])) * d1[0] + (y - float(n[1])) * d1[1] + (z - float(n[2])) * d1[2]) / sp2 if sp2 > 0.0 else 0.0
        start = lam + shift
        if not self._closed:
            start = min(max(start, 0.0), self._lam_max)
        self._lam = start
        self._y = (x, y, z)
        self._dlam = 0.0
        self._count = 0

    def update(self, position_enu_m: ArrayLike) -> float:
        """lambda* for the position (m, ENU); warm-started from the previous call."""
        p = position_enu_m.tolist() if isinstance(position_enu_m, np.ndarray) else position_enu_m
        x, y, z = float(p[0]), float(p[1]), float(p[2])
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            raise InputError("position_enu_m", f"not finite: {[x, y, z]}")
        prev = self._lam
        last = self._y
        if prev is None or last is None or (
            (x - last[0]) ** 2 + (y - last[1]) ** 2 + (z - last[2]) ** 2 > self.jump_m * self.jump_m
        ):
            lam, d2 = self._global(x, y, z)
            self._count = 0
            prev = lam
        else:
            w = self.window_m
            lo, hi = prev - w, prev + w
            if not self._closed:
                lo = max(lo, 0.0)
                hi = min(hi, self._lam_max)
            # Start from a constant-rate prediction (the vehicle moves smoothly): one Newton
            # evaluation fewer than starting at prev; the window stays centred on prev.
            start = prev + self._dlam
            if start < lo:
                start = lo
            elif start > hi:
                start = hi
            lam, d2 = self._newton(start, lo, hi, x, y, z)
            self._count += 1
            if self.check_every and self._count >= self.check_every:
                self._count = 0
                d = self._coarse - np.array((x, y, z))
                g = math.sqrt(float(np.einsum("ij,ij->i", d, d).min()))
                dl = math.sqrt(d2)
                if dl > g + self.reinit_margin_m and dl > 2.0 * g:
                    lam, d2 = self._global(x, y, z)
                    prev = lam
        self._dlam = lam - prev  # unwrapped increment (0 after a global search)
        if self._closed and not 0.0 <= lam < self._lam_max:
            lam %= self._lam_max
            if lam >= self._lam_max:
                lam = 0.0
        self._lam = lam
        self._y = (x, y, z)
        self.distance_m = math.sqrt(d2)
        return lam
