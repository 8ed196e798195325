"""Camera calibration: profiles (bias, read noise and gain per ISO, dark current, full
well) and the code that measures them from bias, dark and flat frames.

Installed as ``lfproc.calib``.
"""

from .profile import SHIPPED_PROFILES, CameraProfile, IsoFigures, load_profile, paper_gain_dn_per_e, save_profile

__all__ = ["SHIPPED_PROFILES", "CameraProfile", "IsoFigures", "load_profile", "paper_gain_dn_per_e", "save_profile"]
