"""System identification of the vehicle + autopilot inner loops (``pf-offboard identify``).

:func:`~pf_offboard.identify.logdata.load_log` reads a flight log into active segments (the only
I/O); :func:`~pf_offboard.identify.fit.identify` fits lag, delay, gain and drag per axis group and
returns an :class:`~pf_offboard.identify.fit.Identification`, whose ``vehicle_model()`` is the
:class:`~pf_offboard.control.VehicleModel` the ``vehicle:`` config section holds.
:mod:`~pf_offboard.identify.excite` flies a bounded excitation through the app's pipeline.
See docs/identify.md.
"""

from pf_offboard.identify.fit import AxisFit, Identification, RateFit, identify, model_fields
from pf_offboard.identify.logdata import LogData, Segment, load_log

__all__ = ["AxisFit", "Identification", "LogData", "RateFit", "Segment", "identify", "load_log", "model_fields"]
