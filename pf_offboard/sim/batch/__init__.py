"""Batched flight engine: the controller and the mock's dynamics for N flights at once, as NumPy
arrays (one row per flight).

Every function here mirrors one function of the scalar code, under the same name and with the
same operations in the same order, so that a flight gives the same numbers whichever engine runs
it (tests compare against the scalar code at run time). The scalar code stays the reference and
the one that flies:

- :mod:`.geometry` — the spline, arclength and moving frame (``pf_offboard.path``) at N parameters;
- :mod:`.projection` — :class:`BatchProjector` (``pf_offboard.path.projection.Projector``);
- :mod:`.law` — exact transverse terms, the thrust set and the control law
  (``pf_offboard.control.transverse`` / ``feasible`` / ``law``);
- :mod:`.follower` — :class:`BatchFollower` (``pf_offboard.control.follower.PathFollower``, its
  inner-loop compensator);
- :mod:`.adaptive` — :class:`~.adaptive.BatchIdentifier` (``pf_offboard.control.adaptive.ResponseIdentifier``:
  the inner loop identified in flight, each flight adopting on its own);
- :mod:`.dynamics` — :class:`BatchSimulator` (``sitl_mock.dynamics.Simulator``);
- :mod:`.flight` — sweep flights (``pf_offboard.sim.flight.SimFlight`` with the mock autopilot's
  PX4 handling, the app's estimator and encoder, the sweep's judge) → the scalar engine's rows;
- :mod:`.ardupilot` — the mock's ArduPilot GUIDED handling per flight (its own objects) over the
  batched dynamics.

Vectors are tuples of three ``(N,)`` arrays ``(x, y, z)``: the scalar code's float expressions
translate one to one.
"""

from pf_offboard.sim.batch.follower import BatchCommand, BatchFollower
from pf_offboard.sim.batch.projection import BatchProjector

__all__ = ["BatchCommand", "BatchFollower", "BatchProjector"]
