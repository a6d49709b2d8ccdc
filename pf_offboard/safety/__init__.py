"""Flight safety: the envelope monitor between the controller and the link (docs/app.md, "Safety").

Pure: state samples and setpoints in, verdicts out. The flight's supervisor (:mod:`pf_offboard.app.supervisor`)
only wires it to the link and acts on its verdicts.
"""

from pf_offboard.safety.envelope import (
    ACTIONS,
    SHAPES,
    Breach,
    EnvelopeMonitor,
    Fence,
    SafetyConfig,
    Verdict,
    VehicleSample,
    check_path,
    fence_for_path,
    takeoff_height_in_fence,
    tilt_rad,
)

__all__ = [
    "ACTIONS", "SHAPES", "Breach", "EnvelopeMonitor", "Fence", "SafetyConfig", "Verdict", "VehicleSample",
    "check_path", "fence_for_path", "takeoff_height_in_fence", "tilt_rad",
]
