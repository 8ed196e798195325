"""Run PlenoptiCam on one virtual Illum capture (helper for ``benchmarks/decode_illum.py``).

Runs ONLY under an interpreter that has PlenoptiCam (PyPI ``plenopticam``, GPL-3.0) installed,
e.g. a throw-away venv; lfproc never imports PlenoptiCam and does not depend on it.
The steps mirror PlenoptiCam 0.9.x's own ``plenopticam/bin/cli_script.py``: ``LfpReader`` (LFR ->
Bayer), ``CaliFinder`` (white image from the caldata tar, matched by geometry hash),
``LfpCalibrator`` (micro-image centroids from the white image), ``LfpAligner`` (hot pixels,
de-vignetting by the white image, Menon demosaic, resampling), ``LfpExtractor`` (sub-aperture
views). Depth, refocusing, colour equalisation, contrast/saturation automation and auto white
balance are switched off so that ``vp_img_linear`` stays as close to linear as PlenoptiCam allows
(it still applies the file's white-balance gains and a per-image percentile normalisation, so the
caller has to fit a scale/offset before scoring).

Usage::

    PYTHON_WITH_PLENOPTICAM _plenopticam_driver.py CAPTURE.LFR CALDATA.tar OUT.npy [--patch 7] [--pitch-px M]

Prints one JSON line: ``calibrate_s``, ``decode_s`` (read + align + extract), ``peak_rss_mb``,
``shape`` of the saved (V, U, H, W, 3) float32 array, ``notes``; or ``{"error": "..."}``
with exit status 1.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import resource
import shutil
import sys
import tempfile
import time
import traceback


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("plenopticam")
    except Exception:  # noqa: BLE001
        return "unknown"


def _fail(msg: str) -> int:
    print(json.dumps({"error": " ".join(str(msg).split())}))
    return 1


def run(capture: str, caldata: str, out: str, *, patch: int, pitch_px: int | None, cal_blur_px: float) -> dict:
    import numpy as np
    from plenopticam import misc
    from plenopticam.cfg import PlenopticamConfig
    from plenopticam.lfp_aligner import LfpAligner
    from plenopticam.lfp_aligner.cfa_processor import CfaProcessor
    from plenopticam.lfp_calibrator import CaliFinder, LfpCalibrator
    from plenopticam.lfp_extractor import LfpExtractor
    from plenopticam.lfp_reader import LfpReader
    from plenopticam.lfp_reader.lfp_decoder import LfpDecoder
    from plenopticam.misc import safe_get

    notes = []
    # PlenoptiCam writes its outputs next to the LFR: work on copies in a scratch folder.
    work = tempfile.mkdtemp(prefix="plenopticam-")
    lfr = os.path.join(work, os.path.basename(capture))
    tar = os.path.join(work, os.path.basename(caldata))
    shutil.copyfile(capture, lfr)
    shutil.copyfile(caldata, tar)

    cfg = PlenopticamConfig()
    cfg.default_values()
    p = cfg.params
    p[cfg.lfp_path], p[cfg.cal_path] = lfr, tar
    p[cfg.ptc_leng] = patch
    for key, value in ((cfg.opt_prnt, False), (cfg.opt_dpth, False), (cfg.opt_refo, False),
                       (cfg.opt_colo, False), (cfg.opt_cont, False), (cfg.opt_awb_, False),
                       (cfg.opt_sat_, False), (cfg.opt_lier, False), (cfg.opt_arti, False),
                       (cfg.opt_vign, True), (cfg.opt_view, True), (cfg.opt_cali, True)):
        p[key] = value
    sta = misc.PlenopticamStatus()

    def check(stage):
        if sta.error:
            raise RuntimeError(f"PlenoptiCam {stage} failed: {sta.stat_var!r}")

    t0 = time.perf_counter()
    reader = LfpReader(cfg, sta)
    reader.main()
    check("LfpReader")
    lfp_img = reader.lfp_img
    if lfp_img is None:
        raise RuntimeError("PlenoptiCam LfpReader returned no Bayer image for the LFR")
    t_read = time.perf_counter() - t0
    misc.mkdir_p(cfg.exp_path, False)

    t0 = time.perf_counter()
    finder = CaliFinder(cfg, sta)
    try:
        finder.main()
    except AttributeError:
        # CaliFinder._raw2img crashes on a white RAW that decode_raw did not recognise
        if not finder.raw_data or finder.wht_bay is not None:
            raise
    wht = finder.wht_bay
    if wht is None and finder.raw_data:
        # PlenoptiCam's LfpDecoder.decode_raw only knows the two real sensor sizes (7728x5368
        # Illum, 3280x3280 Lytro 1) and silently returns nothing for any other white RAW; for a
        # reduced-size virtual sensor decode it at the capture's size and apply the same
        # white-image gains as CaliFinder._raw2img.
        sta.error = False
        h, w = lfp_img.shape
        if len(finder.raw_data) != w * h * 10 // 8:
            raise RuntimeError(f"white RAW has {len(finder.raw_data)} bytes; expected {w * h * 10 // 8} "
                               f"for the capture's {w}x{h} sensor")
        dec = LfpDecoder(finder.raw_data, cfg, sta)
        dec._img_buf, dec._shape = list(finder.raw_data), [w, h]
        cfg.lfpimg["bit"] = 10
        dec.comp_bayer()
        wht = dec.bay_img
        frame = safe_get(finder._wht_json, "master", "picture", "frameArray")[0]
        awb = safe_get(frame, "frame", "metadata", "devices", "sensor", "normalizedResponses")[0]
        cfa = CfaProcessor(bay_img=wht, cfg=cfg, sta=sta)
        cfa.set_gains([1.0 / awb["b"], 1.0 / awb["r"], 1.0 / awb["gr"], 1.0 / awb["gb"]])
        wht = cfa.apply_awb()
        notes.append(f"white RAW decoded at the capture size {w}x{h} by the driver (PlenoptiCam's "
                     "decode_raw hard-codes the Illum / Lytro-1 sensor sizes)")
    check("CaliFinder")
    if wht is None:
        raise RuntimeError("PlenoptiCam CaliFinder found no white image in the caldata tar "
                           "(no geometry-hash match)")
    wht_cal = wht
    if cal_blur_px > 0:
        # PlenoptiCam's centroid finder (LoG peaks) sees two peaks in each flat-topped virtual micro
        # image and then misjudges the pitch; a Gaussian blur of its calibration input merges them.
        # Only the calibration gets the blurred white image; devignetting (LfpAligner) gets the original.
        from scipy.ndimage import gaussian_filter

        wht_cal = gaussian_filter(np.asarray(wht, dtype=np.float64), cal_blur_px).astype(np.asarray(wht).dtype)
        notes.append(f"white image blurred (Gaussian sigma {cal_blur_px:g} px) for LfpCalibrator only")
    calibrator = LfpCalibrator(wht_cal, cfg, sta)
    if pitch_px is not None:
        # skip PlenoptiCam's scale-space micro-image size estimate (PitchEstimator)
        calibrator._M = pitch_px
        notes.append(f"micro-image size M={pitch_px} px given to LfpCalibrator instead of estimated")
    calibrator.main()
    cfg = calibrator.cfg
    check("LfpCalibrator")
    cfg.load_cal_data()
    t_cal = time.perf_counter() - t0

    t0 = time.perf_counter()
    aligner = LfpAligner(lfp_img, cfg, sta, wht)
    aligner.main()
    check("LfpAligner")
    extractor = LfpExtractor(aligner.lfp_img, cfg=cfg, sta=sta)
    extractor.main()
    check("LfpExtractor")
    vp = np.asarray(extractor.vp_img_linear, dtype=np.float32)
    t_dec = time.perf_counter() - t0 + t_read
    if vp.ndim != 5:
        raise RuntimeError(f"PlenoptiCam returned views of shape {vp.shape}; expected (V, U, H, W, 3)")
    np.save(out, vp)
    shutil.rmtree(work, ignore_errors=True)
    return {"calibrate_s": t_cal, "decode_s": t_dec, "plenopticam_version": _version(),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "shape": list(vp.shape), "patch": patch, "notes": notes}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture")
    ap.add_argument("caldata")
    ap.add_argument("out")
    ap.add_argument("--patch", type=int, default=7, help="PlenoptiCam micro-image patch size (views per side)")
    ap.add_argument("--pitch-px", type=int, default=None,
                    help="micro-image size in pixels for LfpCalibrator (default: PlenoptiCam estimates it)")
    ap.add_argument("--calibration-blur-px", type=float, default=2.0,
                    help="Gaussian sigma (px) of the blur applied to the white image given to LfpCalibrator "
                         "(0: none); devignetting always uses the unblurred white image")
    args = ap.parse_args(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    log = io.StringIO()
    try:
        with contextlib.redirect_stdout(log):
            res = run(args.capture, args.caldata, args.out, patch=args.patch, pitch_px=args.pitch_px,
                      cal_blur_px=args.calibration_blur_px)
    except Exception as exc:  # report PlenoptiCam's own failure as one line
        tail = " | ".join(line.strip() for line in log.getvalue().replace("\r", "\n").splitlines()
                          if line.strip())[-300:]
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        where = f"{os.path.basename(frame.filename)}:{frame.lineno} in {frame.name}"
        return _fail(f"{type(exc).__name__}: {exc} (at {where})" + (f" [PlenoptiCam log: {tail}]" if tail else ""))
    print(json.dumps(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
