"""Reference path: quintic spline, arclength, moving frames, closest-point projection (issue 2).

See docs/paths.md.
"""

from pf_offboard.path.path import FrameDerivs, Path, PathPoint
from pf_offboard.path.projection import Projector

__all__ = ["FrameDerivs", "Path", "PathPoint", "Projector"]
