"""Camera calibration: measure a camera profile from bias, dark and flat frames (a stage).

* :func:`calibrate`, :class:`CalibrationResult`, :func:`find_calibration_input`: the measurement
  (:mod:`lfproc.calib.calibrate`);
* :func:`simulate_frames`: simulated calibration frames of a known profile;
* :func:`write_report`: the calibration report (tables and plots).

The profile type and the shipped profiles are :mod:`lfproc.sensor` (:class:`CameraProfile`,
:func:`load_profile`...); their former names here still resolve. Installed as ``lfproc.calib``
(the folder stays at the top level of the repository; a source checkout maps it too, see
:mod:`lfproc._layout`).
"""

from lfproc import sensor as _sensor

from .calibrate import CalibrationResult, calibrate, find_calibration_input
from .report import write_report
from .simulate_frames import simulate_frames

__all__ = ["calibrate", "CalibrationResult", "find_calibration_input", "simulate_frames", "write_report"]

_FORMER = ("SHIPPED_PROFILES", "CameraProfile", "IsoFigures", "load_profile", "paper_gain_dn_per_e", "save_profile")


def __getattr__(name):  # former exports: the profile type, now in lfproc.sensor
    if name in _FORMER:
        return getattr(_sensor, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
