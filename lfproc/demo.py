"""``lfproc demo``: every stage of the pipeline on an embedded default, with a report.

The demo needs no input: it synthesises an HDR light field and runs each stage that
lfproc has on it, measuring what can be measured against the ground truth. Each stage is
a function ``stage(ctx) -> figures`` that reads and adds to a shared context; the demo
writes everything into one folder atomically (it appears complete, or not at all) with a
Markdown report ``report.md`` and ``report.json`` listing every stage, its figures, time
and files.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ._version import __version__
from .io._atomic import atomic_dir, check_output
from .io import read_lightfield, write_lightfield
from .lightfield import LightField
from ._shared.progress import progress
from .calib.calibrate import calibrate
from .calib.frames import read_frame, read_manifest
from .calib.report import write_report
from .calib.simulate_frames import expected_figures, simulate_frames
from .camera.capture import observations
from .camera.simulate import capture_summary, simulate_capture
from .hdr import merge_lightfields
from .lytro.decode import decode_capture
from .lytro.grid import LensletGrid
from .lytro.score import clip_level, score_decode
from .lytro.virtual import make_virtual_illum
from .lytro.whites import build_white_db
from .metrics import evaluate
from .preview import write_capture_preview, write_preview
from .recon import reconstruct, reconstruct_gmm
from .sensor import load_profile, save_profile
from .synth import synthesize

__all__ = ["run_demo", "DemoConfig", "STAGES"]


@dataclass(frozen=True)
class DemoConfig:
    """Parameters of the demo (all recorded in the report).

    Parameters
    ----------
    scene : str, default "layers"
        Synthetic scene (:func:`lfproc.synth.synthesize`).
    size : tuple of 2 int, default (96, 96)
        View size ``(H, W)`` in pixels.
    views : int, default 5
        Views per angular axis (odd).
    baseline_px : float, default 1.0
        Largest disparity of the scene, pixels per view step.
    seed : int, default 7
        Seed of every random draw (scene, noise, camera, frames).
    exposures_ev : tuple of float, default (-2, -1, 0, 1, 2)
        Exposures of the virtual Lytro Illum bracket, in EV.
    noise : {"none", "low", "medium", "high"}, default "medium"
        Noise level of the sensor (the shipped ``paper-<noise>`` profile).
    isos : tuple of int, default (100, 400, 800, 1600)
        ISO set calibrated and used by the coded capture.
    exposure_s : float, default 0.004
        Exposure time of a coded shot in seconds.
    shots : int, default 2
        Shots of the coded capture.
    peak_luminance : float, default 1000.0
        Display peak in cd/m^2 of the PU21 metrics.
    """

    scene: str = "layers"
    size: tuple[int, int] = (96, 96)
    views: int = 5
    baseline_px: float = 1.0
    seed: int = 7
    exposures_ev: tuple[float, ...] = (-2.0, -1.0, 0.0, 1.0, 2.0)
    noise: str = "medium"
    isos: tuple[int, ...] = (100, 400, 800, 1600)
    exposure_s: float = 0.004
    shots: int = 2
    peak_luminance: float = 1000.0


@dataclass
class _Context:
    out: Path
    config: DemoConfig
    state: dict[str, Any] = field(default_factory=dict)

    def path(self, name: str) -> Path:
        """Path of an output inside the demo folder (its parent folders are created)."""
        path = self.out / name
        path.parent.mkdir(parents=True, exist_ok=True)
        return path


def _rel(ctx: _Context, p: Path) -> str:
    return os.path.relpath(p, ctx.out)


# -- stages ------------------------------------------------------------------------------------

def stage_synthesize(ctx: _Context) -> dict[str, Any]:
    """Synthesise the HDR scene (exact ground truth) and preview it."""
    c = ctx.config
    lf = synthesize(c.scene, size=c.size, views=c.views, baseline_px=c.baseline_px, random_state=c.seed)
    ctx.state["scene"] = lf
    path = write_lightfield(lf, ctx.path("scene.exr"))
    files = [path]
    for kind in ("centre", "sheet", "epi", "histogram"):
        files.append(write_preview(lf, ctx.path(f"scene_{kind}.png"), kind=kind))
    ctx.state["files"] = files
    positive = lf.luminance()[lf.luminance() > 0]
    return {
        "scene": c.scene,
        "views": list(lf.views),
        "size": list(lf.size),
        "dynamic_range_stops": round(lf.dynamic_range_stops(), 2),
        "min_max_stops": round(float(np.log2(positive.max() / positive.min())), 2),
        "disparity_range_px": [round(float(lf.disparity.min()), 3), round(float(lf.disparity.max()), 3)],
    }


def stage_evaluate_noisy(ctx: _Context) -> dict[str, Any]:
    """Sanity of the metrics: the scene against copies with more and more noise."""
    lf: LightField = ctx.state["scene"]
    rng = np.random.default_rng(ctx.config.seed)
    rows = {}
    for sigma in (0.01, 0.05):
        noisy = lf.replace(data=lf.data * np.clip(1 + sigma * rng.standard_normal(lf.shape), 0, None))
        r = evaluate(noisy, lf, peak_luminance=ctx.config.peak_luminance)
        rows[f"relative_noise_{sigma}"] = {"pu21_psnr_db": round(r["pu21_psnr_db"], 2),
                                            "pu21_ssim": round(r["pu21_ssim"], 4)}
    return rows


def stage_virtual_illum(ctx: _Context) -> dict[str, Any]:
    """Render the scene through the virtual Lytro Illum (hexagonal microlens array, vignetting, Bayer
    GRBG, 10-bit raw with photon and read noise; small sensor crop) as a bracket of 5 exposures 1 EV
    apart, with the camera's calibration data (white images) and the views a perfect decoder returns."""
    c = ctx.config
    info = make_virtual_illum(ctx.state["scene"], ctx.path("illum/camera"), sensor="small",
                              exposures_ev=c.exposures_ev, random_state=c.seed)
    ctx.state["illum"] = info
    return {
        "sensor": info["sensor_size"],
        "serial": info["serial"],
        "exposures_s": [cap["exposure_s"] for cap in info["captures"]],
        "raw_saturated_fraction": [round(cap["saturated_fraction"], 4) for cap in info["captures"]],
        "lenslet_spacing_px": round(info["grid"]["spacing_x_px"], 4),
    }


def stage_whites(ctx: _Context) -> dict[str, Any]:
    """Build the white-image database from the calibration data: drop dark frames, estimate each white
    image's hexagonal lenslet grid; compare the estimates with the grids the camera was made with."""
    info = ctx.state["illum"]
    db = build_white_db(ctx.path("illum/camera") / info["caldata"], ctx.path("illum/whites"))
    ctx.state["white_db"] = ctx.path("illum/whites")
    truth = {w["name"]: LensletGrid.from_dict(w["grid"]) for w in info["white_images"]}
    spacing, rotation, position = [], [], []
    for entry in db.entries:
        true = truth[entry.name]
        spacing.append(abs(entry.grid.spacing_x_px - true.spacing_x_px))
        rotation.append(abs(entry.grid.rotation_rad - true.rotation_rad))
        position.append(entry.grid.position_error_px(true))
    return {
        "white_images": len(db.entries),
        "dark_frames_dropped": len(db.skipped),
        "max_spacing_error_px": float(f"{max(spacing):.2e}"),
        "max_rotation_error_rad": float(f"{max(rotation):.2e}"),
        "max_centre_error_px": round(max(position), 4),
    }


def _decode_scores(decoded: LightField, truth: LightField, info: dict[str, Any]) -> dict[str, float]:
    """Linear PSNR of a decode against the truth (:mod:`lfproc.lytro.score`: the capture's clipped
    truth left out, peak = 99.9th percentile of the rest, 4-pixel border excluded)."""
    s = score_decode(decoded.data, truth.data, clip=clip_level(info))
    return {"psnr_centre_db": round(s["psnr_centre_db"], 2), "psnr_all_views_db": round(s["psnr_all_views_db"], 2)}


def stage_decode(ctx: _Context) -> dict[str, Any]:
    """Decode every capture of the bracket into 5x5 views (levels, devignetting with the selected white
    image, hot pixels, demosaicing, hexagonal-to-square resampling) and score the 0 EV decode against the
    views the camera saw (linear PSNR with the 99.9th percentile of the truth as peak, the samples the
    capture clipped left out, 4-pixel border excluded)."""
    info = ctx.state["illum"]
    camera = ctx.path("illum/camera")
    decoded = []
    for cap in info["captures"]:
        lf = decode_capture(camera / cap["file"], white_db=ctx.state["white_db"])
        write_lightfield(lf, ctx.path(f"illum/decoded/{Path(cap['file']).stem}.exr"))
        decoded.append(lf)
    truth = read_lightfield(camera / "truth.exr")
    reference = decoded[[cap["file"] for cap in info["captures"]].index(info["truth_capture"])]
    ctx.state["decoded"], ctx.state["illum_truth"] = decoded, truth
    return {
        "captures": len(decoded),
        "views": list(reference.views),
        "size": list(reference.size),
        "white_image": reference.attrs.get("white_image"),
        "psnr_0ev_db": _decode_scores(reference, truth, info),
    }


def stage_merge(ctx: _Context) -> dict[str, Any]:
    """Merge the decoded bracket into one HDR light field (noise-aware ML estimator, per view and pixel,
    with variance) and evaluate it against the truth with the HDR metrics (the merge is in units per
    second: it is compared after multiplying by the 0 EV exposure time)."""
    c = ctx.config
    hdr, info = merge_lightfields(ctx.state["decoded"], method="ml", profile="illum")
    write_lightfield(hdr, ctx.path("illum/merged_hdr.exr"))
    write_preview(hdr, ctx.path("illum/merged_histogram.png"), kind="histogram")
    write_preview(hdr, ctx.path("illum/merged_centre.png"), kind="centre")
    truth = ctx.state["illum_truth"]
    t0 = next(cap["exposure_s"] for cap in ctx.state["illum"]["captures"] if cap["exposure_ev"] == 0)
    h, w = (min(a, b) for a, b in zip(hdr.size, truth.size))
    result = hdr.replace(data=hdr.data[:, :, :h, :w] * t0, variance=None, disparity=None, exposure_s=t0)  # per second -> t0
    reference = truth.replace(data=truth.data[:, :, :h, :w], disparity=None, variance=None)
    scores = evaluate(result, reference, peak_luminance=c.peak_luminance)
    single = ctx.state["decoded"][[cap["exposure_ev"] for cap in ctx.state["illum"]["captures"]].index(0)]
    alone = evaluate(single.replace(data=single.data[:, :, :h, :w], variance=None, disparity=None), reference,
                     peak_luminance=c.peak_luminance)

    def median_rel(level: float) -> float:
        sel = reference.data > level * reference.data.max()
        return round(float(np.median(np.abs(result.data[sel] / reference.data[sel] - 1))), 4)

    return {
        "dynamic_range_stops": round(hdr.dynamic_range_stops(), 2),
        "saturated_everywhere_fraction": round(info["saturated_everywhere_fraction"], 5),
        "pu21_psnr_db": round(scores["pu21_psnr_db"], 2),
        "pu21_ssim": round(scores["pu21_ssim"], 4),
        "log_psnr_db": round(scores["log_psnr_db"], 2),
        "pu21_psnr_db_0ev_capture_alone": round(alone["pu21_psnr_db"], 2),
        "median_relative_error_above_10pct_of_peak": median_rel(0.1),
        "median_relative_error_above_1pct_of_peak": median_rel(0.01),
        "note": "relative errors of dark samples follow the decoder's error floor (see the decode stage's "
                "PSNR), which merging more exposures does not remove",
    }


#: Layout of the calibration contact sheet (pixels): tile side, gap, label band above a tile,
#: ISO column on the left, caption band at the top.
SHEET_TILE, SHEET_PAD, SHEET_LABEL, SHEET_HEAD, SHEET_CAPTION = 96, 4, 14, 72, 18


def _frames_contact_sheet(manifest: Path, out: Path) -> Path:
    """One picture of a simulated calibration frame set: a row per ISO, columns bias, each dark
    exposure and each flat level (the first frame of each set), labelled with the set and its mean.

    Every tile has the same display scale (written in the caption): the lowest black code of the
    bias frames is black, the highest code of any frame (the saturation code when a flat clips)
    is white, with a square-root display curve so that darks and dim flats stay visible. A dark
    frame therefore looks dark and a saturated flat white (each tile used to be stretched to its
    own 1st-99th percentile, which made every frame look alike and a saturated flat black)."""
    import cv2

    records, _ = read_manifest(manifest)
    first: dict[tuple, Any] = {}
    for r in records:
        first.setdefault((int(round(r.iso)), r.kind, r.exposure_s), r)
    frames = {key: read_frame(rec.path).data.astype(np.float32) for key, rec in first.items()}
    isos = sorted({k[0] for k in first})
    order = {"bias": 0, "dark": 1, "flat": 2}
    columns = sorted({(k[1], k[2]) for k in first}, key=lambda c: (order.get(c[0], 3), c[1]))
    biases = [float(np.percentile(x, 1)) for k, x in frames.items() if k[1] == "bias"]
    lo = min(biases) if biases else min(float(x.min()) for x in frames.values())
    hi = max(float(x.max()) for x in frames.values())
    span = max(hi - lo, 1e-6)
    tile, pad, label = SHEET_TILE, SHEET_PAD, SHEET_LABEL
    rows = []
    for iso in isos:
        cells = []
        for kind, t in columns:
            cell = np.full((tile + label, tile), 255, np.uint8)
            x = frames.get((iso, kind, t))
            if x is not None:
                img = (np.sqrt(np.clip((x - lo) / span, 0, 1)) * 255).round().astype(np.uint8)
                cell[label:] = cv2.resize(img, (tile, tile), interpolation=cv2.INTER_AREA)
                cv2.rectangle(cell, (0, label), (tile - 1, tile + label - 1), 128, 1)  # a white tile stays visible
                text = (f"{kind} {t:.3g}s" if kind != "bias" else "bias") + f" {x.mean():.0f}"
                if np.mean(x >= hi) >= 0.01:
                    text = f"{kind} {t:.3g}s sat."
                cv2.putText(cell, text, (2, label - 3), cv2.FONT_HERSHEY_PLAIN, 0.7, 0, 1, cv2.LINE_AA)
            cells.append(np.pad(cell, ((0, pad), (0, pad)), constant_values=255))
        head = np.full((tile + label + pad, SHEET_HEAD), 255, np.uint8)
        cv2.putText(head, f"ISO {iso}", (2, (tile + label) // 2), cv2.FONT_HERSHEY_PLAIN, 0.9, 0, 1, cv2.LINE_AA)
        rows.append(np.hstack([head] + cells))
    body = np.vstack(rows)
    caption = np.full((SHEET_CAPTION, body.shape[1]), 255, np.uint8)
    cv2.putText(caption, f"one scale for all tiles: {lo:.0f} DN black, {hi:.0f} DN white (square root); "
                "labels: set, mean DN", (2, SHEET_CAPTION - 5), cv2.FONT_HERSHEY_PLAIN, 0.8, 0, 1, cv2.LINE_AA)
    sheet = np.vstack([caption, body])
    if not cv2.imwrite(str(out), sheet):
        raise OSError(f"{out}: could not write the contact sheet")
    return out


def stage_calibrate(ctx: _Context) -> dict[str, Any]:
    """Calibrate a sensor: simulate the bias, dark and flat frames the paper's sensor (at the demo's
    noise level, with a stronger dark current so it is measurable) predicts, then measure gain,
    read noise, dark current and full well per ISO from them and compare with the truth. The contact
    sheet shows the first frame of each set (a row per ISO); the frames themselves are in
    `calibration/simulated/frames/`."""
    from dataclasses import replace

    c = ctx.config
    base = load_profile(f"paper-{c.noise}")
    noisy = base.with_noise(read_noise_e=2.0, dark_current_e_per_s=50.0, name="demo-sensor-truth")
    truth = replace(noisy, isos={iso: f for iso, f in noisy.isos.items() if iso in c.isos})
    manifest = simulate_frames(truth, ctx.path("calibration/simulated"), size=(96, 96), random_state=c.seed)
    _frames_contact_sheet(manifest, ctx.path("calibration/frames_contact_sheet.png"))
    result = calibrate(manifest, name="demo-sensor")
    profile = result.profile
    save_profile(profile, ctx.path("calibration/profile.json"))
    write_report(result, ctx.path("calibration/report"))
    ctx.state["profile"] = profile
    errors: dict[str, dict[str, float]] = {}
    for iso in c.isos:
        want = expected_figures(truth, iso)
        got = profile.iso_figures(iso)
        errors[str(iso)] = {
            "gain_error_percent": round(100 * (got.gain_dn_per_e / want["gain_dn_per_e"] - 1), 2),
            "read_noise_error_percent": round(100 * (got.read_noise_e / want["read_noise_e"] - 1), 2),
            "dark_current_error_percent": round(100 * (got.dark_current_e_per_s / want["dark_current_e_per_s"] - 1), 2),
            "full_well_error_percent": round(100 * (got.full_well_e / want["saturation_capacity_e"] - 1), 2),
        }
    worst = {k: max(abs(e[k]) for e in errors.values()) for k in next(iter(errors.values()))}
    low = min(c.isos)
    note = (f"read noise at ISO {low} is {expected_figures(truth, low)['read_noise_dn']:.2f} DN, below the "
            "quantisation step (1/sqrt(12) = 0.29 DN rms), so its relative error is the largest")
    return {"frames": sum(1 for _ in manifest.parent.rglob("*.png")), "worst_error_percent": worst, "per_iso": errors,
            "note": note, "contact_sheet": "calibration/frames_contact_sheet.png"}


def stage_simulate(ctx: _Context) -> dict[str, Any]:
    """Simulate the paper's multi-ISO coded-mask camera (random ISO pattern, random colour mask of
    period 4, Bayer RGGB) from the scene with the calibrated profile (or the paper's sensor), and
    check the calibrated observations T against the noiseless projection of the ground truth."""
    c = ctx.config
    lf: LightField = ctx.state["scene"]
    profile = ctx.state.get("profile", f"paper-{c.noise}")
    capture = simulate_capture(lf, profile=profile, iso_pattern_kind="random", isos=c.isos, shots=c.shots,
                               exposure_s=c.exposure_s, mask="random", mask_period=4, random_state=c.seed)
    path = capture.save(ctx.path("capture.capture.npz"))
    write_capture_preview(capture, ctx.path("capture_preview.png"))
    summary = capture_summary(capture)
    # calibrated observations against the truth Phi L (e-/s): relative bias of T, and z-scores
    # with the predicted variance evaluated at the true signal (mean 0 and variance 1 if right)
    expected = capture.operator(dtype=np.float64).forward(lf.data.astype(np.float64) * capture.radiance_scale)
    obs = observations(capture, variance_from="estimate", radiance_estimate=expected)
    valid = obs.weight > 0
    z = (obs.radiance[valid] - expected[valid]) * obs.weight[valid]
    bias = float((obs.radiance[valid] - expected[valid]).sum() / expected[valid].sum())
    ctx.state["capture"] = capture
    return {
        "profile": capture.profile.name,
        "capture_file": path.name,
        "sampling_rate": summary["sampling_rate"],
        "saturated_fraction": round(summary["saturated_fraction"], 4),
        "black_clipped_fraction": round(summary["black_clipped_fraction"], 4),
        "per_iso_saturated_fraction": {k: round(v["saturated_fraction"], 4) for k, v in summary["per_iso"].items()},
        "observation_relative_bias": round(bias, 5),
        "observation_z_mean": round(float(z.mean()), 4),
        "observation_z_variance": round(float(z.var()), 4),
        "valid_measurements": int(valid.sum()),
    }


def stage_reconstruct(ctx: _Context) -> dict[str, Any]:
    """Reconstruct the HDR light field from the coded multi-ISO capture with lfproc's default method
    (disparity-sheared Gaussian patch models, :func:`lfproc.recon.reconstruct_gmm`, as ``lfproc
    reconstruct`` chooses for this periodic mask), evaluate it against the ground truth with the HDR
    metrics, preview its centre view and an epipolar image; and score the paper's method (the
    shipped dictionary, ADMM) on the same capture for comparison."""
    c = ctx.config
    lf: LightField = ctx.state["scene"]
    out = reconstruct_gmm(ctx.state["capture"])  # every CPU: the same output (measured: 50 -> 42 s on 2 cores)
    write_lightfield(out, ctx.path("reconstructed.exr"))
    for kind in ("centre", "epi"):
        write_preview(out, ctx.path(f"reconstructed_{kind}.png"), kind=kind)
    scores = evaluate(out, lf, peak_luminance=c.peak_luminance, scale_tolerance_stops=None)
    paper = evaluate(reconstruct(ctx.state["capture"], "default", threads=1), lf, peak_luminance=c.peak_luminance,
                     scale_tolerance_stops=None)
    rec = out.attrs["reconstruction"]
    return {
        "method": "gmm",
        "patches": rec["patches"],
        "pu21_psnr_db": round(scores["pu21_psnr_db"], 2),
        "pu21_ssim": round(scores["pu21_ssim"], 4),
        "dictionary_pu21_psnr_db": round(paper["pu21_psnr_db"], 2),
        "dictionary_pu21_ssim": round(paper["pu21_ssim"], 4),
    }


#: The stages, in order. Each later capability adds its own.
STAGES: list[tuple[str, Callable[[_Context], dict[str, Any]]]] = [
    ("synthesize", stage_synthesize),
    ("metrics sanity", stage_evaluate_noisy),
    ("virtual Illum", stage_virtual_illum),
    ("white images", stage_whites),
    ("decode", stage_decode),
    ("merge", stage_merge),
    ("calibrate", stage_calibrate),
    ("simulate", stage_simulate),
    ("reconstruct", stage_reconstruct),
]


# -- driver ------------------------------------------------------------------------------------

#: A folder with more files than this is listed in the Markdown report as one line.
_MAX_FILES_LISTED = 8


def _summarise_files(files: list[str]) -> tuple[list[str], list[str]]:
    """The report's file list and its pictures: folders with many files (the raw calibration frames)
    become one ``folder/ (N files)`` entry and their pictures are not embedded."""
    by_folder: dict[str, list[str]] = {}
    for f in files:
        by_folder.setdefault(os.path.dirname(f), []).append(f)
    listed, pictures = [], []
    for folder, names in by_folder.items():
        if len(names) > _MAX_FILES_LISTED:
            kinds = sorted({os.path.splitext(n)[1].lstrip(".").upper() for n in names})
            listed.append(f"{folder}/ ({len(names)} {'/'.join(kinds)} files)")
        else:
            listed += names
            pictures += [n for n in names if n.endswith(".png")]
    return listed, pictures


def _report_markdown(config: DemoConfig, rows: list[dict[str, Any]], total_s: float) -> str:
    lines = [
        "# lfproc demo report",
        "",
        f"lfproc {__version__}; total {total_s:.1f} s. Parameters: "
        + ", ".join(f"`{k}={v}`" for k, v in config.__dict__.items()),
        "",
        "| stage | time (s) | figures | files |",
        "|---|---|---|---|",
    ]
    summaries = [_summarise_files(row["files"]) for row in rows]
    for row, (listed, _) in zip(rows, summaries):
        figures = "<br>".join(f"{k}: {json.dumps(v)}" for k, v in row["figures"].items())
        files = "<br>".join(f"`{f}`" for f in listed)
        lines.append(f"| {row['stage']} | {row['seconds']:.1f} | {figures} | {files} |")
    lines.append("")
    for row, (_, pictures) in zip(rows, summaries):
        lines += [f"## {row['stage']}", "", row["doc"], ""]
        lines += [f"![{f}]({f})" for f in pictures]
        lines.append("")
    return "\n".join(lines)


def run_demo(out_dir: str | os.PathLike = "lfproc-demo", *, config: DemoConfig | None = None, force: bool = False,
             log: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run every stage into ``out_dir``; return the report as a dict.

    ``out_dir`` appears complete or not at all (built in a temporary sibling and renamed);
    an existing ``out_dir`` is only replaced with ``force``. The stages are :data:`STAGES`.

    Parameters
    ----------
    out_dir : str or path-like, default "lfproc-demo"
        The folder to create.
    config : DemoConfig, optional
        The demo's parameters (default: ``DemoConfig()``).
    force : bool, default False
        Replace an existing ``out_dir``.
    log : callable, optional
        Called with one line of text after each stage.

    Returns
    -------
    dict
        ``lfproc_version``, ``config``, ``total_seconds`` and ``stages`` (per stage: ``stage``,
        ``doc``, ``seconds``, ``figures``, ``files``), as written to ``report.json``.

    Raises
    ------
    OutputExistsError
        ``out_dir`` exists and ``force`` is false.
    """
    config = config or DemoConfig()
    out_dir = check_output(out_dir, force=force)
    log = log or (lambda message: None)
    rows = []
    start = time.perf_counter()
    with atomic_dir(out_dir, force=force) as tmp:
        ctx = _Context(out=tmp, config=config)
        bar = progress(STAGES, desc="lfproc demo", total=len(STAGES))
        for name, stage in bar:
            bar.set_postfix_str(name)
            t0 = time.perf_counter()
            before = set(tmp.rglob("*"))
            figures = stage(ctx)
            new = sorted(p for p in set(tmp.rglob("*")) - before if p.is_file())
            rows.append({
                "stage": name,
                "doc": (stage.__doc__ or "").strip(),
                "seconds": time.perf_counter() - t0,
                "figures": figures,
                "files": [_rel(ctx, p) for p in new],
            })
            log(f"{name}: done in {rows[-1]['seconds']:.1f} s")
        total = time.perf_counter() - start
        report = {"lfproc_version": __version__, "config": config.__dict__, "total_seconds": total, "stages": rows}
        (tmp / "report.json").write_text(json.dumps(report, indent=2, default=str))
        (tmp / "report.md").write_text(_report_markdown(config, rows, total))
    return report
