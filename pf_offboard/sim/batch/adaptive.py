""":class:`pf_offboard.control.adaptive.ResponseIdentifier` for N flights sampled at the same
instants: one scalar identifier per flight (the same code, so nothing to keep in step), fed its
flight's velocity and its flight's column of the recorded setpoints. The setpoint history's
pieces are computed once per candidate delay for all flights and sliced per flight.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pf_offboard.control.adaptive import ResponseIdentifier

Arr = NDArray[np.float64]
V = tuple[Arr, Arr, Arr]
Vec = tuple[float, float, float]
_ZERO: Vec = (0.0, 0.0, 0.0)  # no setpoint recorded yet (the batch compensator's None)


class BatchIdentifier:
    """The bank of (lag, dead time) models per flight: ``flights[i]`` is flight ``i``'s own
    :class:`ResponseIdentifier` (a copy of the scalar one). ``active``: the adopted candidate per
    flight (-1: none yet, the scalar's None)."""

    def __init__(self, scalar: ResponseIdentifier, n: int) -> None:
        self.n = n
        self.flights = [copy.deepcopy(scalar) for _ in range(n)]
        self.reset()

    def reset(self) -> None:
        for ident in self.flights:
            ident.reset()

    @property
    def active(self) -> NDArray[np.int64]:
        return np.array([-1 if f.active is None else f.active for f in self.flights], dtype=np.int64)

    @property
    def moving(self) -> NDArray[np.bool_]:
        """:attr:`ResponseIdentifier.moving` per flight."""
        return np.array([f.moving for f in self.flights], dtype=bool)

    @property
    def drag_1_s(self) -> Arr:
        """The active candidate's drag per flight (NaN where none is adopted: the scalar's None)."""
        return np.array([math.nan if (d := f.drag_1_s) is None else d for f in self.flights])

    @property
    def gain_xy(self) -> Arr:
        """The active candidate's horizontal gain per flight (NaN where none is adopted)."""
        return np.array([math.nan if (g := f.gain_xy) is None else g for f in self.flights])

    @property
    def vertical(self) -> tuple[Arr, Arr]:
        """The active joint candidate's vertical (gain, drag 1/s) per flight (NaN where none is)."""
        zs = [f.vertical for f in self.flights]
        return (np.array([math.nan if z is None else z[0] for z in zs]),
                np.array([math.nan if z is None else z[1] for z in zs]))  # fmt: skip

    def update(self, time_s: float, velocity: V, pieces: Callable[[float, float, float], list[tuple[float, V | None]]]) -> tuple[NDArray[np.bool_], Arr, Arr] | None:  # fmt: skip
        """:meth:`ResponseIdentifier.update` per flight: (adopted now per flight, its lag, its
        delay; NaN where none was adopted), or None when no flight adopted at this step."""
        shared: dict[float, list[tuple[float, list[list[float]] | None]]] = {}

        def segments(t0: float, t1: float, delay: float) -> list[tuple[float, list[list[float]] | None]]:
            if delay not in shared:  # once per delay for all flights, the setpoints as lists per axis
                shared[delay] = [(h, None if sp is None else [np.asarray(c, dtype=float).tolist() for c in sp])
                                 for h, sp in pieces(t0, t1, delay)]  # fmt: skip
            return shared[delay]

        found: list[tuple[float, float] | None] = []
        vx, vy, vz = (np.asarray(c, dtype=float).tolist() for c in velocity)
        for i, ident in enumerate(self.flights):

            def own(t0: float, t1: float, delay: float, i: int = i) -> list[tuple[float, Vec]]:
                return [(h, _ZERO if sp is None else (sp[0][i], sp[1][i], sp[2][i]))
                        for h, sp in segments(t0, t1, delay)]  # fmt: skip

            found.append(ident.update(time_s, (vx[i], vy[i], vz[i]), own))
        if all(f is None for f in found):
            return None
        adopt = np.array([f is not None for f in found])
        lag = np.array([math.nan if f is None else f[0] for f in found])
        delay = np.array([math.nan if f is None else f[1] for f in found])
        return adopt, lag, delay
