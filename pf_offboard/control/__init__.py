"""Path-following control: exact transverse coordinates, TFL law with limits, feed-forward (issue 2),
and the attitude → body-rate law for rates-mode users (issue 8).

See docs/controller.md.
"""

from pf_offboard.control.attitude import (
    DEFAULT_ATTITUDE_TIME_CONSTANT_S,
    AttitudeRateLaw,
    AttitudeRates,
    AttitudeTracker,
)
from pf_offboard.control.follower import PathFollower, evaluate_terms
from pf_offboard.control.select import controller_from_config
from pf_offboard.control.tracker import TrajectoryTracker
from pf_offboard.control.transverse import ExactTerms, exact_terms
from pf_offboard.control.types import (
    GRAVITY_M_S2,
    Command,
    Compensation,
    Gains,
    Limits,
    Saturation,
    TransverseState,
    VehicleModel,
    YawSpec,
)

__all__ = [
    "DEFAULT_ATTITUDE_TIME_CONSTANT_S",
    "AttitudeRateLaw",
    "AttitudeRates",
    "AttitudeTracker",
    "GRAVITY_M_S2",
    "Command",
    "Compensation",
    "ExactTerms",
    "Gains",
    "Limits",
    "PathFollower",
    "Saturation",
    "TrajectoryTracker",
    "TransverseState",
    "VehicleModel",
    "YawSpec",
    "controller_from_config",
    "evaluate_terms",
    "exact_terms",
]
