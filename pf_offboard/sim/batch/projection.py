"""Warm-started closest-point projection for N flights (mirrors
:class:`pf_offboard.path.projection.Projector` step by step: the same safeguarded Newton, the same
window, the same periodic global check). The rare global searches (first call, a jump, a lost
path) run the scalar projector's own search per flight."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pf_offboard.path.projection import _ACCEPT, Projector
from pf_offboard.sim.batch.geometry import BatchPath

Arr = NDArray[np.float64]


class BatchProjector:
    """N independent :class:`~pf_offboard.path.projection.Projector` states on one path."""

    def __init__(self, path: Any, n: int, bpath: BatchPath | None = None) -> None:
        self.scalar = Projector(path)  # its parameters, samples and global search
        sc = self.scalar
        self.bpath = bpath if bpath is not None else BatchPath(path)
        self.n = n
        self.jump_m = sc.jump_m
        self.window_m = sc.window_m
        self.check_every = sc.check_every
        self.reinit_margin_m = sc.reinit_margin_m
        self._closed = sc._closed
        self._lam_max = sc._lam_max
        self.reset()

    def reset(self, mask: NDArray[np.bool_] | None = None) -> None:
        """Forget the warm start (of the flights in ``mask``; all by default)."""
        if mask is None:
            mask = np.ones(self.n, dtype=bool)
            self._lam = np.zeros(self.n)
            self._y = np.zeros((3, self.n))
            self._count = np.zeros(self.n, dtype=np.int64)
            self._dlam = np.zeros(self.n)
            self._valid = np.zeros(self.n, dtype=bool)
            self.distance_m = np.full(self.n, math.nan)
            return
        self._valid[mask] = False
        self._count[mask] = 0
        self._dlam[mask] = 0.0
        self.distance_m[mask] = math.nan

    # ------------------------------------------------------------------ internals
    def _ev(self, lam: Arr) -> tuple[Arr, ...]:
        return self.bpath.eval2_floats(np.mod(lam, self._lam_max) if self._closed else lam)

    def _newton(self, lam: Arr, lo: Arr, hi: Arr, x: Arr, y: Arr, z: Arr) -> tuple[Arr, Arr]:
        """``Projector._newton`` for every row."""
        lam = lam.copy()
        s = self._ev(lam)
        rx, ry, rz = s[0] - x, s[1] - y, s[2] - z
        d2 = rx * rx + ry * ry + rz * rz
        s = [a.copy() for a in s]
        act = np.arange(len(lam))
        for _ in range(20):
            if not len(act):
                break
            l0 = lam[act]
            ax, ay, az = s[3][act], s[4][act], s[5][act]
            qx0, qy0, qz0 = rx[act], ry[act], rz[act]
            g = ax * qx0 + ay * qy0 + az * qz0
            sp2 = ax * ax + ay * ay + az * az
            hess = sp2 + s[6][act] * qx0 + s[7][act] * qy0 + s[8][act] * qz0
            newton = hess > 0.1 * sp2
            new = np.where(newton, l0 - g / hess, l0 - g / sp2)
            lo_a, hi_a = lo[act], hi[act]
            new = np.where(new < lo_a, lo_a, np.where(new > hi_a, hi_a, new))
            step = new - l0
            zero = step == 0.0
            accept = ~zero & newton & (-_ACCEPT < step) & (step < _ACCEPT)
            lam[act[accept]] = new[accept]
            search = ~zero & ~accept
            idx = act[search]
            new = new[search]
            base = lam[idx]
            d2b = d2[idx]
            # halving line search: at most 40 evaluations; rows that find no descent are done
            found = np.zeros(len(idx), dtype=bool)
            res_s: list[Arr] = [np.zeros(len(idx)) for _ in range(9)]
            res_q = [np.zeros(len(idx)) for _ in range(3)]
            res_e = np.zeros(len(idx))
            res_new = np.zeros(len(idx))
            pend = np.arange(len(idx))
            for _ in range(40):
                if not len(pend):
                    break
                nw = new[pend]
                s2 = self._ev(nw)
                qx, qy, qz = s2[0] - x[idx[pend]], s2[1] - y[idx[pend]], s2[2] - z[idx[pend]]
                e2 = qx * qx + qy * qy + qz * qz
                db = d2b[pend]
                ok = e2 <= db + 1e-13 * (db + 1e-9)
                okp = pend[ok]
                found[okp] = True
                for k in range(9):
                    res_s[k][okp] = s2[k][ok]
                res_q[0][okp], res_q[1][okp], res_q[2][okp] = qx[ok], qy[ok], qz[ok]
                res_e[okp] = e2[ok]
                res_new[okp] = nw[ok]
                pend = pend[~ok]
                new[pend] = 0.5 * (base[pend] + new[pend])
            upd = idx[found]
            lam[upd] = res_new[found]
            for k in range(9):
                s[k][upd] = res_s[k][found]
            rx[upd], ry[upd], rz[upd] = res_q[0][found], res_q[1][found], res_q[2][found]
            d2[upd] = res_e[found]
            act = upd
        return lam, d2

    def _global(self, rows: NDArray[np.intp], x: Arr, y: Arr, z: Arr, lam: Arr, d2: Arr) -> None:
        for i in rows.tolist():
            lam[i], d2[i] = self.scalar._global(float(x[i]), float(y[i]), float(z[i]))

    # ------------------------------------------------------------------ public
    def seed(self, lam: Arr, x: Arr, y: Arr, z: Arr, nx: Arr, ny: Arr, nz: Arr) -> None:
        """``Projector.seed`` for every flight: the next :meth:`update` of (x, y, z) searches around
        ``lam`` (the closest points of the nearby (nx, ny, nz)) moved along the tangent."""
        with np.errstate(all="ignore"):
            s = self._ev(lam)
            d1x, d1y, d1z = s[3], s[4], s[5]
            sp2 = d1x * d1x + d1y * d1y + d1z * d1z
            shift = np.where(sp2 > 0.0, ((x - nx) * d1x + (y - ny) * d1y + (z - nz) * d1z) / np.where(sp2 > 0.0, sp2, 1.0), 0.0)
        start = lam + shift
        if not self._closed:
            start = np.minimum(np.maximum(start, 0.0), self._lam_max)
        self._lam = np.asarray(start, dtype=float)
        self._y = np.array((x, y, z), dtype=float)
        self._dlam = np.zeros(self.n)
        self._count = np.zeros(self.n, dtype=np.int64)
        self._valid[:] = True

    def update(self, x: Arr, y: Arr, z: Arr) -> Arr:
        """``Projector.update`` for every flight: lambda* of positions (x, y, z) (ENU, m)."""
        with np.errstate(all="ignore"):
            return self._update(x, y, z)

    def _update(self, x: Arr, y: Arr, z: Arr) -> Arr:
        n = self.n
        lx, ly, lz = self._y
        jump = (x - lx) ** 2 + (y - ly) ** 2 + (z - lz) ** 2 > self.jump_m * self.jump_m
        glob = ~self._valid | jump
        lam = np.zeros(n)
        d2 = np.zeros(n)
        prev = self._lam.copy()
        gi = np.flatnonzero(glob)
        self._global(gi, x, y, z, lam, d2)
        self._count[gi] = 0
        prev[gi] = lam[gi]
        li = np.flatnonzero(~glob)
        if len(li):
            w = self.window_m
            p = prev[li]
            lo, hi = p - w, p + w
            if not self._closed:
                lo = np.maximum(lo, 0.0)
                hi = np.minimum(hi, self._lam_max)
            start = p + self._dlam[li]
            start = np.where(start < lo, lo, np.where(start > hi, hi, start))
            ll, dd = self._newton(start, lo, hi, x[li], y[li], z[li])
            lam[li], d2[li] = ll, dd
            self._count[li] += 1
            if self.check_every:
                chk = li[self._count[li] >= self.check_every]
                if len(chk):
                    self._count[chk] = 0
                    coarse = self.scalar._coarse
                    dx = coarse[None, :, 0] - x[chk, None]
                    dy = coarse[None, :, 1] - y[chk, None]
                    dz = coarse[None, :, 2] - z[chk, None]
                    g = np.sqrt((dx * dx + dy * dy + dz * dz).min(axis=1))
                    dl = np.sqrt(d2[chk])
                    lost = chk[(dl > g + self.reinit_margin_m) & (dl > 2.0 * g)]
                    self._global(lost, x, y, z, lam, d2)
                    prev[lost] = lam[lost]
        self._dlam = lam - prev
        if self._closed:
            out = ~((lam >= 0.0) & (lam < self._lam_max))
            if out.any():
                wl = np.mod(lam[out], self._lam_max)
                lam[out] = np.where(wl >= self._lam_max, 0.0, wl)
        self._lam = lam
        self._y = np.array((x, y, z), dtype=float)
        self._valid[:] = True
        self.distance_m = np.sqrt(d2)
        return lam.copy()
