"""The public API of every package: the names of its ``__all__`` (like kornia's API-surface test).

A change to a package's ``__all__`` fails here, so additions and removals are deliberate:
update the list in the same commit (and, for removals, keep the old name working for a release).
Every listed name must exist, and ``from package import *`` must give exactly these names.
"""

from __future__ import annotations

import importlib

import pytest

API = {
    "lfproc": [
        "LfprocError", "LightField", "__version__", "evaluate", "load_capture", "read_image", "read_lightfield",
        "reconstruct", "reconstruct_gmm", "simulate_capture", "write_image", "write_lightfield",
    ],
    "lfproc.io": [
        "IMAGE_SUFFIXES", "exr_parts", "parse_view_name", "read_image", "read_lightfield", "srgb_decode",
        "srgb_encode", "view_name", "write_image", "write_lightfield",
    ],
    "lfproc.sensor": [
        "CameraProfile", "FixedPattern", "IsoFigures", "Observation", "SHIPPED_PROFILES",
        "calibrated_observation", "describe_profile", "expose", "fixed_pattern", "fixed_pattern_correction",
        "is_profile_file", "iso_maps", "load_profile", "paper_gain_dn_per_e", "save_profile",
    ],
    "lfproc.lytro": [
        "DEMOSAIC_METHODS", "LensletGrid", "LytroCapture", "build_white_db", "decode_capture", "describe_lytro",
        "estimate_grid", "extract_lfp", "is_lfp", "load_white_db", "make_virtual_illum", "read_caldata",
        "read_capture", "read_lfp", "score_decode",
    ],
    "lfproc.hdr": [
        "BRACKET_SUFFIXES", "CAMERA_RESPONSES", "MERGE_METHODS", "camera_response", "hat_weight",
        "merge_debevec", "merge_files", "merge_lightfields", "merge_ml", "merge_ml_codes8",
        "merge_with_variances", "read_bracket", "read_exif_exposure", "recover_response",
        "simulate_ldr_bracket", "write_response",
    ],
    "lfproc.synth": [
        "Layer", "SCENES", "check_scene", "render_layers", "scene_layers", "scene_names", "synthesize",
    ],
    "lfproc.metrics": [
        "ALIGN_MODES", "EMITTER_SHARE_DOMINATES", "PU21_LUMA", "PU21_L_MAX", "PU21_L_MIN", "PU21_PARAMETERS",
        "PU21_PSNR_PEAK", "PU21_VARIANTS", "ZERO_STOPS", "align_result", "error_stops", "evaluate", "evaluation_mask",
        "hdr_figures", "log_luminance_error", "log_psnr", "mean_relative_error", "metric_luminance", "psnr",
        "pu21_decode", "pu21_encode", "pu21_psnr", "pu21_ssim", "pu2_encode", "pu2_psnr",
    ],
    "lfproc.refocus": [
        "check_slopes", "focal_stack", "refocus",
    ],
    "lfproc.camera": [
        "BASELINES", "Capture", "CaptureDesign", "DEFAULT_ISOS", "ISO_PATTERNS", "MASK_KINDS", "MASK_TRANSMITTANCES", "MaskCode",
        "NOISE_PROFILES", "ProjectionOperator", "build_operator", "capture_from_raw", "describe_capture",
        "is_capture_file", "iso_pattern", "load_capture", "make_mask", "noise_floor", "observations",
        "simulate_capture", "simulate_file",
    ],
    "lfproc.dictionary": [
        "Dictionary", "KsvdResult", "PRESETS", "Preset", "SHIPPED", "TrainingSizes", "approximate", "batch_omp",
        "dct_dictionary", "evaluate_dictionary", "get_preset", "is_dictionary_file", "ksvd", "load_dictionary",
        "save_dictionary", "train_dictionary", "training_patches",
    ],
    "lfproc.recon": [
        "DEFAULTS", "MERGES", "OVERLAPS", "PAPER", "PatchModel", "ReconstructionSettings", "SCALES", "SOLVERS",
        "VARIANCES",
        "gmm_fits", "load_patch_model", "merge_reconstructions", "patch_count", "reconstruct", "reconstruct_gmm",
        "reconstruct_per_shot", "reexpose", "split_shots", "train_patch_model",
    ],
    "lfproc.preview": [
        "CAPTURE_PREVIEW_KINDS", "PREVIEWS", "PREVIEW_SUFFIXES", "SHEET_MAX_PIXELS", "TONEMAPS",
        "clipped_fraction", "display_transform", "epi_stretch", "preview_kinds", "register_preview",
        "reinhard_parameters", "render_atoms", "render_capture_preview", "render_error_map", "render_preview",
        "sheet_tile_size", "tonemap", "write_capture_preview", "write_error_map", "write_preview",
    ],
    "lfproc.dataset": [
        "EXPOSURE_FILES", "MANIFEST_FIELDS", "SCENE_OUTPUTS", "Scene", "build_dataset", "find_scenes",
        "process_scene", "read_exposure_file", "read_manifest",
    ],
    "lfproc.bench": [
        "COLUMNS", "Cell", "MERGES", "METHODS", "PRESETS", "claims", "get_preset", "grid_cells",
        "merge_reconstructions", "reconstruct_per_shot", "reexpose", "run_bench", "split_shots", "write_report",
    ],
    "lfproc.calib": [
        "CalibrationResult", "calibrate", "find_calibration_input", "simulate_frames", "write_report",
    ],
    "lfproc.errors": [
        "CalibrationError", "ChecksumError", "ConvergenceWarning", "DependencyError", "FileFormatError",
        "InputError", "LfpFormatError", "LfprocError", "LfprocWarning", "MissingFileError", "NoWhiteImageError",
        "OutputExistsError", "ProfileError", "SATURATION_WARNING_FRACTION", "SaturationWarning", "ShapeError",
        "UnsafeFileError", "ViewCountWarning", "cli_interface", "option_name",
    ],
    "lfproc.lightfield": [
        "LightField", "REC709_LUMA", "UNITS", "clean_nonfinite", "luminance",
    ],
}


@pytest.mark.parametrize("package", sorted(API))
def test_public_names(package):
    module = importlib.import_module(package)
    assert sorted(module.__all__) == API[package]
    assert len(set(module.__all__)) == len(module.__all__), "a name is listed twice"
    missing = [name for name in module.__all__ if not hasattr(module, name)]
    assert not missing


@pytest.mark.parametrize("package", sorted(API))
def test_star_import_gives_the_public_names(package):
    namespace: dict = {}
    exec(f"from {package} import *", namespace)  # noqa: S102
    assert sorted(k for k in namespace if k != "__builtins__") == API[package]
