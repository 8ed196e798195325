"""The paper's coded multi-ISO camera: simulated and imported captures (the simulate stage,
and the model the reconstruction inverts).

* :func:`simulate_capture`, :func:`simulate_file`: coded multi-ISO captures of an HDR light field
  (:mod:`~lfproc.camera.simulate`);
* :class:`Capture`, :func:`load_capture`, :func:`is_capture_file`, :func:`describe_capture`,
  :func:`observations`: capture files and their calibrated observations
  (:mod:`~lfproc.camera.capture`); :func:`capture_from_raw`: captures from a real camera's raw files;
* :func:`make_mask`, :class:`MaskCode`, :func:`build_operator`, :class:`ProjectionOperator`:
  mask codes, the Bayer CFA and the projection operator ``Phi`` (:mod:`~lfproc.camera.projection`);
* :func:`iso_pattern`: per-pixel ISO layouts (:mod:`~lfproc.camera.iso`).

The sensor's noise model and camera profiles are :mod:`lfproc.sensor` (a lower layer; the old
path ``lfproc.camera.sensor`` still works). Previews of captures are
:func:`lfproc.preview.render_capture_preview` (presentation).

Imports go one way: ``projection``, ``iso`` <- ``capture`` <- ``simulate``.
"""

from .capture import (Capture, capture_from_raw, describe_capture, is_capture_file, load_capture, noise_floor,
                      observations)
from .iso import DEFAULT_ISOS, ISO_PATTERNS, iso_pattern
from .projection import MASK_KINDS, MASK_TRANSMITTANCES, MaskCode, ProjectionOperator, build_operator, make_mask
from .simulate import BASELINES, NOISE_PROFILES, CaptureDesign, simulate_capture, simulate_file

__all__ = [
    "simulate_capture", "CaptureDesign", "simulate_file", "BASELINES", "NOISE_PROFILES",
    "Capture", "load_capture", "is_capture_file", "describe_capture", "observations", "noise_floor", "capture_from_raw",
    "MASK_KINDS", "MASK_TRANSMITTANCES", "MaskCode", "make_mask", "ProjectionOperator", "build_operator",
    "ISO_PATTERNS", "DEFAULT_ISOS", "iso_pattern",
]
