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
from .io import atomic_dir, check_output, write_lightfield
from .lightfield import LightField

__all__ = ["run_demo", "DemoConfig", "STAGES"]


@dataclass(frozen=True)
class DemoConfig:
    """Parameters of the demo (all recorded in the report)."""

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
    from .preview import write_preview
    from .synth import synthesize

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
    from .metrics import evaluate

    lf: LightField = ctx.state["scene"]
    rng = np.random.default_rng(ctx.config.seed)
    rows = {}
    for sigma in (0.01, 0.05):
        noisy = lf.replace(data=lf.data * np.clip(1 + sigma * rng.standard_normal(lf.shape), 0, None))
        r = evaluate(noisy, lf, peak_luminance=ctx.config.peak_luminance)
        rows[f"relative_noise_{sigma}"] = {"pu21_psnr_db": round(r["pu21_psnr_db"], 2),
                                            "pu21_ssim": round(r["pu21_ssim"], 4)}
    return rows


def stage_calibrate(ctx: _Context) -> dict[str, Any]:
    """Calibrate a sensor: simulate the bias, dark and flat frames the paper's sensor (at the demo's
    noise level, with a stronger dark current so it is measurable) predicts, then measure gain,
    read noise, dark current and full well per ISO from them and compare with the truth."""
    from dataclasses import replace

    from .calib import load_profile, save_profile
    from .calib.calibrate import calibrate
    from .calib.report import write_report
    from .calib.simulate_frames import expected_figures, simulate_frames

    c = ctx.config
    base = load_profile(f"paper-{c.noise}")
    noisy = base.with_noise(read_noise_e=2.0, dark_current_e_per_s=50.0, name="demo-sensor-truth")
    truth = replace(noisy, isos={iso: f for iso, f in noisy.isos.items() if iso in c.isos})
    manifest = simulate_frames(truth, ctx.path("calibration/frames"), size=(96, 96), seed=c.seed)
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
            "note": note}


def stage_simulate(ctx: _Context) -> dict[str, Any]:
    """Simulate the paper's multi-ISO coded-mask camera (random ISO pattern, random colour mask of
    period 4, Bayer RGGB) from the scene with the calibrated profile (or the paper's sensor), and
    check the calibrated observations T against the noiseless projection of the ground truth."""
    from .capture import observations, write_capture_preview
    from .simulate import capture_summary, simulate_capture

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


#: The stages, in order. Each later capability adds its own.
STAGES: list[tuple[str, Callable[[_Context], dict[str, Any]]]] = [
    ("synthesize", stage_synthesize),
    ("metrics sanity", stage_evaluate_noisy),
    ("calibrate", stage_calibrate),
    ("simulate", stage_simulate),
]


# -- driver ------------------------------------------------------------------------------------

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
    for row in rows:
        figures = "<br>".join(f"{k}: {json.dumps(v)}" for k, v in row["figures"].items())
        files = "<br>".join(f"`{f}`" for f in row["files"])
        lines.append(f"| {row['stage']} | {row['seconds']:.1f} | {figures} | {files} |")
    lines.append("")
    for row in rows:
        lines += [f"## {row['stage']}", "", row["doc"], ""]
        lines += [f"![{f}]({f})" for f in row["files"] if f.endswith(".png")]
        lines.append("")
    return "\n".join(lines)


def run_demo(out_dir: str | os.PathLike = "lfproc-demo", *, config: DemoConfig | None = None, force: bool = False,
             log: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run every stage into ``out_dir``; return the report as a dict.

    ``out_dir`` appears complete or not at all (built in a temporary sibling and renamed);
    an existing ``out_dir`` is only replaced with ``force``.
    """
    from ._util import progress

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
