"""``pf-offboard sim``: in-process flights of the app's pipeline against the mock autopilot.

See :mod:`pf_offboard.sim.flight` (the loop) and :mod:`pf_offboard.sim.cli` (the command).
"""

from pf_offboard.sim.flight import SimFlight, SimResult, SimSpec, simulate

__all__ = ["SimFlight", "SimResult", "SimSpec", "simulate"]
