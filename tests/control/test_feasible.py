"""ThrustSet.line_intervals (many lines at once) equals the scalar line_interval bit for bit,
including the degenerate lines (horizontal, zero direction, inside the cone's direction)."""

from __future__ import annotations

import math

import numpy as np

from pf_offboard.control.feasible import ThrustSet


def _lines(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    f0 = rng.normal(0.0, 8.0, (n, 3)) + np.array([0.0, 0.0, 9.81])
    m = rng.normal(0.0, 1.0, (n, 3))
    k = n // 8
    m[:k, 2] = 0.0  # horizontal lines
    m[k : 2 * k] = 0.0  # no direction
    m[2 * k : 3 * k] = np.column_stack([0.05 * m[2 * k : 3 * k, 0], 0.05 * m[2 * k : 3 * k, 1], np.abs(m[2 * k : 3 * k, 2]) + 1.0])  # inside the cone
    m[3 * k : 4 * k, 2] *= -1.0
    m[4 * k : 5 * k] = np.column_stack([np.ones(k), np.zeros(k), np.full(k, 1.0 / math.tan(math.radians(35.0)))])  # along the cone
    f0[5 * k : 6 * k] = np.array([0.0, 0.0, 9.81])
    return f0, m


def test_line_intervals_equal_the_scalar() -> None:
    rng = np.random.default_rng(3)
    for ts in (ThrustSet(2.0, 20.0, math.tan(math.radians(35.0))), ThrustSet(0.0, 15.0, 1.0)):
        f0, m = _lines(rng, 4000)
        lo, hi, empty = ts.line_intervals(tuple(f0.T), tuple(m.T))
        kinds = set()
        for i in range(len(f0)):
            iv = ts.line_interval(tuple(f0[i]), tuple(m[i]))
            assert (iv is None) == bool(empty[i]), i
            if iv is not None:
                assert (lo[i], hi[i]) == iv, i
                kinds.add((math.isinf(iv[0]), math.isinf(iv[1])))
        assert 0 < int(empty.sum()) < len(f0) and (False, False) in kinds and len(kinds) >= 2
