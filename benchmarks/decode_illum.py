"""Benchmark: decode a full-size (7728 x 5368) virtual Illum capture, lfproc beside PlenoptiCam.

Renders a textured synthetic light field (the ``layers`` scene: sky with a sun about 500 times
brighter than the rest, buildings, objects) through the virtual Illum (``--sensor full``), builds
the white-image database, then decodes the 0 EV capture in a fresh subprocess (so its peak
memory is the decoder's own) and reports wall time, peak resident memory (``ru_maxrss``) and
linear PSNR against ``truth.exr`` as :mod:`lfproc.lytro.score` defines it: the truth values the
capture clipped (at or above the level that fills the ADC at full transmission) left out, every
other sample scored, peak = the 99.9th percentile of the scored truth (the sun's maximum would
inflate the figure by several dB), 4-pixel border excluded; centre view and all 25 views.

Usage::

    python benchmarks/decode_illum.py [--work DIR] [--threads 2] [--demosaic opencv-ea]

``--work`` keeps the rendered capture between runs (rendering takes minutes).

PlenoptiCam (PyPI ``plenopticam``, GPL-3.0; never a dependency of lfproc) decodes the same
capture when ``$PLENOPTICAM_PYTHON`` is an interpreter that has it, through
``benchmarks/_plenopticam_driver.py`` in a subprocess (``--no-plenopticam`` skips it). Its
pinned ``pyinstaller==4.10`` does not install on Python 3.11, so install it without
dependencies in a throw-away venv::

    python -m venv /work/venv-plenopticam
    /work/venv-plenopticam/bin/pip install --no-deps plenopticam==0.9.3
    /work/venv-plenopticam/bin/pip install "numpy<2" "scipy<1.12" colour-demosaicing colour \
        color-matcher==0.4.0 color-space-converter imageio docutils Pillow requests depthy certifi \
        "scikit-image<0.23" tifffile==2022.4.8
    PLENOPTICAM_PYTHON=/work/venv-plenopticam/bin/python python benchmarks/decode_illum.py --work W

One change to its input, for its calibration only: PlenoptiCam's centroid finder looks for LoG
peaks and sees two in each flat-topped micro image of the virtual Illum's white image, then
misjudges the lenslet pitch and fails (``Geometric MLA arrangement not recognized``). Its
calibrator therefore gets the white image blurred by a Gaussian of sigma 2 px
(``--plenopticam-calibration-blur``); its devignetting gets the white image as it is. Its views
are normalised by PlenoptiCam (file white balance, percentile scaling) and spaced 1/pitch of a
micro image apart instead of lfproc's 1/16, so only its centre view is compared: registered to the
truth's centre view (phase correlation, sub-pixel), then scored like lfproc's after a
least-squares gain per colour channel (reported) over the samples both cover; a second figure
fits a gain and an offset per channel (PlenoptiCam's ``vp_img_linear`` is not zero for black).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DECODE_CHILD = r"""
import json, os, resource, sys, time
import cv2
cv2.setNumThreads(int(os.environ.get("LFPROC_BENCH_THREADS", "2")))
from lfproc.lytro.decode import decode_capture
t = time.perf_counter()
lf = decode_capture(sys.argv[1], white_db=sys.argv[2], demosaic_method=sys.argv[3])
dt = time.perf_counter() - t
import numpy as np
np.save(sys.argv[4], lf.data)
np.save(sys.argv[4].replace(".npy", "_var.npy"), lf.variance)
print(json.dumps({"decode_s": dt, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "shape": list(lf.shape), "white": lf.attrs["white_image"]}))
"""


def run_plenopticam(capture: Path, caldata: Path, out: Path, *, env: dict, blur_px: float) -> dict | str:
    """Run ``_plenopticam_driver.py`` under ``$PLENOPTICAM_PYTHON``.

    Returns the driver's JSON report (decode and calibration times, its peak memory), or one line
    saying why PlenoptiCam did not run or failed.
    """
    python = os.environ.get("PLENOPTICAM_PYTHON")
    if not python or not Path(python).is_file():
        return (f"not run: no interpreter at {python!r} (set PLENOPTICAM_PYTHON to a Python with plenopticam; "
                "see the module documentation)")
    driver = Path(__file__).with_name("_plenopticam_driver.py")
    t = time.perf_counter()
    res = subprocess.run([python, str(driver), str(capture), str(caldata), str(out),
                          "--calibration-blur-px", str(blur_px)],
                         env=dict(env, PYTHONWARNINGS="ignore", MPLBACKEND="Agg"),
                         capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t
    lines = res.stdout.strip().splitlines()
    try:
        rep = json.loads(lines[-1])
    except (IndexError, json.JSONDecodeError):
        tail = (res.stderr.strip().splitlines() or ["no output"])[-1]
        return f"failed: driver exited {res.returncode}: {tail}"
    if "error" in rep:
        return f"failed: {rep['error']}"
    rep["wall_s"] = wall
    rep["views"] = str(out)
    return rep


def _regions(data, holes, truth, clip: float, near_px: float = 5.0) -> dict:
    """PSNR [centre view, all views] within ``near_px`` of a clipped truth sample and farther away
    (on the peak of all scored samples), and with borders of 0 and 12 px; for the decode and for
    the decode with its unusable samples set to 0."""
    import numpy as np
    from scipy import ndimage

    from lfproc.lytro.score import decode_psnr, score_decode

    h, w = min(data.shape[2], truth.shape[2]), min(data.shape[3], truth.shape[3])
    clipped = (truth[:, :, :h, :w] >= clip).any(axis=(0, 1, 4))
    near = ndimage.distance_transform_edt(~clipped) <= near_px
    out = {"near_fraction": float(near.mean())}
    for name, d in (("decode", data), ("unusable_as_0", holes)):
        row = {}
        for region, m in (("near", near), ("away", ~near)):
            vals = []
            for sel in ((slice(2, 3), slice(2, 3)), (slice(None), slice(None))):
                a, b = d[sel], truth[sel]
                peak = decode_psnr(a, b, clip=clip)["peak"]
                mask = np.broadcast_to(m[4:h - 4, 4:w - 4][None, None, :, :, None],
                                       a[:, :, 4:h - 4, 4:w - 4].shape)
                vals.append(round(decode_psnr(a, b, clip=clip, mask=mask, peak=peak)["psnr_db"], 2))
            row[region] = vals
        for border in (0, 12):
            sc = score_decode(d, truth, clip=clip, border=border)
            row[f"border_{border}"] = [round(sc["psnr_centre_db"], 2), round(sc["psnr_all_views_db"], 2)]
        out[name] = row
    return out


def _old_psnr(data, var, truth, border: int = 4) -> float:
    """The figure this benchmark used to print: decoder-flagged samples left out, peak = largest truth
    value (the sun). Kept to show how much it inflated the result."""
    import numpy as np

    from lfproc.lytro.decode import UNUSABLE_VARIANCE

    h, w = min(data.shape[2], truth.shape[2]), min(data.shape[3], truth.shape[3])
    sl = (slice(None), slice(None), slice(border, h - border), slice(border, w - border))
    ok = var[sl] < UNUSABLE_VARIANCE
    a, b = data[sl][ok], truth[sl][ok]
    return float(10 * np.log10(float(b.max()) ** 2 / float(np.mean((a - b) ** 2))))


def score_foreign_centre_view(views, truth, *, clip: float, border: int = 4) -> dict:
    """Score another decoder's centre view against the truth's (see the module documentation).

    The view (one row per lenslet row and square pixels, as lfproc's, but possibly a few rows and
    columns fewer) is placed on a canvas of the truth's size, registered by phase correlation of
    log luminance (OpenCV), shifted (bilinear), and scored on the samples inside it, the border and
    below ``clip``: after a least-squares gain per colour channel (``psnr_centre_db``), and after a
    gain and an offset per channel (``psnr_centre_gain_offset_db``).
    """
    import cv2
    import numpy as np

    from lfproc.lytro.score import decode_psnr

    v = np.asarray(views, dtype=np.float32)
    view = np.maximum(np.nan_to_num(v[v.shape[0] // 2, v.shape[1] // 2]), 0)
    ref = np.asarray(truth[truth.shape[0] // 2, truth.shape[1] // 2], dtype=np.float32)
    h, w = ref.shape[:2]
    vh, vw = min(h, view.shape[0]), min(w, view.shape[1])
    canvas = np.zeros_like(ref)
    canvas[:vh, :vw] = view[:vh, :vw]
    covered = np.zeros((h, w), np.float32)
    covered[:vh, :vw] = 1

    def logl(x):
        y = x @ np.array([0.2126, 0.7152, 0.0722], np.float32)
        y = np.log(np.maximum(y, 1e-4 * max(float(np.percentile(y, 99)), 1e-12)))
        return (y - y.mean()).astype(np.float32)

    win = cv2.createHanningWindow((w, h), cv2.CV_32F)
    (dx, dy), response = cv2.phaseCorrelate(logl(ref), logl(canvas), win)
    shift = np.float32([[1, 0, -dx], [0, 1, -dy]])
    moved = cv2.warpAffine(canvas, shift, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                           borderValue=0)
    inside = cv2.warpAffine(covered, shift, (w, h), flags=cv2.INTER_NEAREST) > 0.5
    ok = inside[..., None] & (ref < clip)
    mask = np.broadcast_to(inside[border:h - border, border:w - border, None], (h - 2 * border, w - 2 * border, 3))
    out: dict = {"plenopticam_views_shape": list(v.shape),
                 "registration_shift_px": [round(float(dx), 3), round(float(dy), 3)],
                 "registration_response": round(float(response), 3)}
    for name, with_offset in (("", False), ("_gain_offset", True)):
        fitted = np.empty_like(moved)
        params = []
        for c in range(3):
            x = moved[..., c][ok[..., c]].astype(np.float64)
            y = ref[..., c][ok[..., c]].astype(np.float64)
            a = np.stack([x, np.ones_like(x)], axis=1) if with_offset else x[:, None]
            coef = np.linalg.lstsq(a, y, rcond=None)[0]
            fitted[..., c] = moved[..., c] * coef[0] + (coef[1] if with_offset else 0.0)
            params.append([float(k) for k in coef])
        s = decode_psnr(fitted[None, None], ref[None, None], clip=clip, border=border, mask=mask[None, None])
        out[f"psnr_centre{name}_db"] = s["psnr_db"]
        out[f"fit{name or '_gain'}_per_channel"] = params
    out["scored_fraction"] = s["scored_fraction"]
    out["mask"] = mask
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, help="folder to keep the rendered capture and database")
    ap.add_argument("--threads", type=int, default=2, help="threads for numpy/OpenCV (default 2)")
    ap.add_argument("--demosaic", default="opencv-ea", choices=("opencv-ea", "malvar2004", "bilinear"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-plenopticam", action="store_true", help="do not try PlenoptiCam")
    ap.add_argument("--plenopticam-calibration-blur", type=float, default=2.0, metavar="SIGMA_PX",
                    help="Gaussian blur of the white image given to PlenoptiCam's calibration only (default 2)")
    args = ap.parse_args(argv)
    env = dict(os.environ, OMP_NUM_THREADS=str(args.threads), OPENBLAS_NUM_THREADS=str(args.threads),
               MKL_NUM_THREADS=str(args.threads), LFPROC_BENCH_THREADS=str(args.threads), LFPROC_PROGRESS="0")
    os.environ.update({k: env[k] for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")})
    import numpy as np

    from lfproc import __version__, read_lightfield
    from lfproc.lytro.decode import UNUSABLE_VARIANCE
    from lfproc.lytro.score import clip_level, decode_psnr, score_decode
    from lfproc.lytro.virtual import illum_grid, make_virtual_illum, output_shape, SENSOR_SIZES
    from lfproc.lytro.whites import build_white_db
    from lfproc.synth import synthesize

    work = args.work or Path(tempfile.mkdtemp(prefix="lfproc-bench-illum-"))
    work.mkdir(parents=True, exist_ok=True)
    cam, db = work / "cam", work / "db"
    report = {"benchmark": "decode_illum", "lfproc_version": __version__, "threads": args.threads,
              "demosaic": args.demosaic, "seed": args.seed}
    if not (cam / "truth.json").is_file():
        size = output_shape(illum_grid(SENSOR_SIZES["full"], random_state=0))
        lf = synthesize("layers", size=size, views=5, baseline_px=0.5, random_state=args.seed)
        t = time.perf_counter()
        make_virtual_illum(lf, cam, sensor="full", exposures_ev=[0], random_state=args.seed, force=True)
        report["render_s"] = time.perf_counter() - t
    info = json.loads((cam / "truth.json").read_text())
    if not (db / "whites.json").is_file():
        t = time.perf_counter()
        build_white_db(cam / info["caldata"], db, force=True)
        report["whites_s"] = time.perf_counter() - t
    out = work / "decoded.npy"
    res = subprocess.run([sys.executable, "-c", DECODE_CHILD, str(cam / info["truth_capture"]), str(db),
                          args.demosaic, str(out)], env=env, capture_output=True, text=True, check=False)
    if res.returncode:
        print(res.stderr, file=sys.stderr)
        return 1
    report.update(json.loads(res.stdout.strip().splitlines()[-1]))
    data, var = np.load(out), np.load(str(out).replace(".npy", "_var.npy"))
    truth = read_lightfield(cam / "truth.exr").data
    clip = clip_level(info)
    scores = score_decode(data, truth, clip=clip)
    report.update({k: scores[k] for k in ("psnr_centre_db", "psnr_all_views_db", "peak", "clip_level",
                                          "scored_fraction")})
    report["usable_fraction"] = float((var < UNUSABLE_VARIANCE).mean())
    holes = np.where(var < UNUSABLE_VARIANCE, data, 0.0)
    report["psnr_unusable_as_0_db"] = {k: round(v, 2) for k, v in score_decode(holes, truth, clip=clip).items()
                                       if k in ("psnr_centre_db", "psnr_all_views_db")}
    report["psnr_old_scoring_db"] = _old_psnr(data, var, truth)
    report["regions"] = _regions(data, holes, truth, clip)
    report["target"] = {"decode_s": 20, "peak_rss_mb": 4096}
    if args.no_plenopticam:
        report["plenopticam"] = "skipped (--no-plenopticam)"
    else:
        rep = run_plenopticam(cam / info["truth_capture"], cam / info["caldata"], work / "plenopticam_views.npy",
                              env=env, blur_px=args.plenopticam_calibration_blur)
        if isinstance(rep, dict):
            rep.update(score_foreign_centre_view(np.load(work / "plenopticam_views.npy"), truth, clip=clip))
            mask = rep.pop("mask")
            c = data.shape[0] // 2
            h, w = truth.shape[2:4]
            mine = np.zeros_like(truth[c:c + 1, c:c + 1])
            hh, ww = min(h, data.shape[2]), min(w, data.shape[3])
            mine[..., :hh, :ww, :] = data[c:c + 1, c:c + 1, :hh, :ww]
            report["psnr_centre_db_on_plenopticam_samples"] = decode_psnr(
                mine, truth[c:c + 1, c:c + 1], clip=clip, mask=mask[None, None])["psnr_db"]
        report["plenopticam"] = rep
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
