"""The sensor: its noise model and the camera profiles that parametrise it (models layer).

Every stage uses these two foundations: decoding, merging, calibration and the simulator.
They import only the foundations (errors, io, shared helpers), never a stage.

* :func:`expose`, :func:`calibrated_observation`, :class:`Observation`, :func:`iso_maps`,
  :func:`fixed_pattern`, :class:`FixedPattern`, :func:`fixed_pattern_correction`: the noise
  model (exposure, calibrated observations; :mod:`lfproc.sensor._model`);
* :class:`CameraProfile`, :class:`IsoFigures`, :func:`load_profile`, :func:`save_profile`,
  :data:`SHIPPED_PROFILES`: camera profiles (bias, read noise and gain per ISO, dark current,
  full well) and the profiles lfproc ships (:mod:`lfproc.sensor._profile`; measured by
  :func:`lfproc.calib.calibrate`).

Formerly ``lfproc.camera.sensor`` and ``lfproc.calib.profile``; both old paths still work.
"""

from ._model import (FixedPattern, Observation, calibrated_observation, expose, fixed_pattern,
                     fixed_pattern_correction, iso_maps)
from ._profile import (SHIPPED_PROFILES, CameraProfile, IsoFigures, describe_profile, is_profile_file, load_profile,
                       paper_gain_dn_per_e, save_profile)

__all__ = [
    "expose", "calibrated_observation", "Observation", "iso_maps", "fixed_pattern", "FixedPattern",
    "fixed_pattern_correction",
    "CameraProfile", "IsoFigures", "load_profile", "save_profile", "describe_profile", "is_profile_file",
    "paper_gain_dn_per_e", "SHIPPED_PROFILES",
]
