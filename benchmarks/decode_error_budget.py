"""Where the decoding error comes from: replace one stage of the decoder at a time with its ideal.

A textured synthetic scene (``layers``) goes through the virtual Illum's forward model (lenslet
grid, vignetting, Bayer GRBG, 10-bit sensor with photon and read noise) on a sensor crop, and is
decoded by lfproc's pipeline (:func:`lfproc.lytro.decode.decode_lenslet`). Then each stage is
swapped for its ideal, alone and cumulatively:

* ``grid``: the true lenslet grid instead of the one estimated from the white image;
* ``noise``: noiseless, unquantised capture and white image (photon, read and quantisation noise
  removed; clipping kept);
* ``white``: devignetting by the exact transmission instead of the (noisy) white image;
* ``demosaic``: every colour at every sensor pixel (three renderings without a colour filter
  array) instead of demosaicing the Bayer mosaic;
* ``resample``: the slices scored at the lenslets' own positions against the truth there
  (:func:`lfproc.lytro.virtual._spatial_samples`), i.e. without the hexagonal-to-square resampling;

and the decoder itself with the samples it flags as unusable (next to clipped pixels, off the
sensor) set to 0 instead of inpainted from their usable neighbours.

What stays when all are ideal is the slicing itself (bilinear sampling of the sensor image at
each view's position, which mixes neighbouring views) and the forward model's own sampling.
Scores follow :mod:`lfproc.lytro.score` (99.9th-percentile peak, clipped truth left out,
4-pixel border), centre view and all 25 views, over all scored samples and split (on the same
peak) into those within 5 px of a clipped truth sample (``near``: next to the sun, where the
sensor pixels that record a sample also see the clipped highlight through neighbouring views
and pixels) and the rest (``away``); the border's share is shown by scoring with borders of 0,
4 and 12 pixels.

Usage::

    python benchmarks/decode_error_budget.py [--size 1800 2400] [--seed 0] [--demosaic opencv-ea]
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np


def _render(size, seed):
    from lfproc.sensor import load_profile
    from lfproc.lytro.virtual import (NORMALIZED_RESPONSES, Optics, _fit_views, illum_grid, output_shape,
                                      render_irradiance, vignetting)
    from lfproc.synth import synthesize

    prof = load_profile("illum")
    figs = prof.iso_figures(100)
    grid = illum_grid(size, zoom_step=0, focus_step=800, random_state=seed)
    rows, cols = output_shape(grid)
    lf = synthesize("layers", size=(rows, cols), views=5, baseline_px=0.5, random_state=seed)
    views = _fit_views(lf.data, (rows, cols))
    fw = float(prof.full_well_e)
    t, t_w = 0.01, 0.008
    white_scale = 0.85 * fw / t_w
    scale = 0.7 * fw / (t * float(np.percentile(views, 99.5)))
    factor = scale * t / (white_scale * t_w)
    optics = Optics()
    vig = vignetting(grid, optics=optics)
    irr = {pat: render_irradiance(views, grid, scale_e_per_s=scale, optics=optics, cfa_pattern=pat)
           for pat in ("GRBG", "RRRR", "GGGG", "BBBB")}
    return {"grid": grid, "views": views, "truth": views * np.float32(factor), "vig": vig, "irr": irr, "t": t,
            "t_w": t_w, "white_scale": white_scale, "scale": scale, "prof": prof, "gain": figs.gain_dn_per_e,
            "resp": np.asarray(NORMALIZED_RESPONSES, np.float32), "factor": factor}


def _levels(electrons, r, *, noise, rng):
    """Electrons -> levels-normalised values ``(raw - black) / (white - black)`` (clipped)."""
    from lfproc.sensor import expose

    prof = r["prof"]
    span = prof.white_level_dn - prof.black_level_dn
    if noise:
        t = 1.0
        dn = expose(electrons.astype(np.float64) / t, exposure_s=t, iso=100, profile=prof, random_state=rng)
        return (dn.astype(np.float32) - np.float32(prof.black_level_dn)) / np.float32(span)
    sat = min(float(prof.full_well_e), span / r["gain"])
    return (np.minimum(electrons, sat) * r["gain"] / span).astype(np.float32)


NEAR = 5  # px: samples this close to a clipped one are scored separately


def _channel_map(h, w, pattern="GRBG"):
    from lfproc.lytro.decode import _channel_map

    return _channel_map(pattern, (h, w))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", nargs=2, type=int, default=(1800, 2400), metavar=("H", "W"), help="sensor crop")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--demosaic", default="opencv-ea", choices=("opencv-ea", "malvar2004", "bilinear"))
    args = ap.parse_args(argv)

    from lfproc.lytro.decode import _sample_views, decode_lenslet, demosaic, hex_to_square
    from lfproc.lytro.grid import estimate_grid
    from lfproc.lytro.score import BORDER_PX, decode_psnr
    from lfproc.lytro.virtual import VIEW_STEP_DIVISOR, _spatial_samples, white_irradiance

    t0 = time.perf_counter()
    r = _render(tuple(args.size), args.seed)
    grid_true = r["grid"]
    h, w = grid_true.image_size
    rng = np.random.default_rng(args.seed)
    cmap = _channel_map(h, w)
    white_e = white_irradiance(grid_true, scale_e_per_s=r["white_scale"]) * r["t_w"]
    cap_e = {k: v * r["t"] for k, v in r["irr"].items()}
    sat_e = min(float(r["prof"].full_well_e), (r["prof"].white_level_dn - r["prof"].black_level_dn) / r["gain"])
    clip = sat_e / (r["white_scale"] * r["t_w"])
    noisy = {"cap": _levels(cap_e["GRBG"], r, noise=True, rng=rng), "white": _levels(white_e, r, noise=True, rng=rng)}
    clean = {"cap": _levels(cap_e["GRBG"], r, noise=False, rng=rng), "white": _levels(white_e, r, noise=False, rng=rng)}
    span = r["prof"].white_level_dn - r["prof"].black_level_dn
    grid_est = estimate_grid(noisy["white"] * span + r["prof"].black_level_dn)
    truth = r["truth"]
    truth_lenslets = _spatial_samples(r["views"], grid_true) * np.float32(r["factor"])
    # the exact transmission the decoder divides by (levels units, neutral colour)
    exact_white = (r["vig"] * r["white_scale"] * r["t_w"] * r["gain"] / span).astype(np.float32)
    render_s = time.perf_counter() - t0

    def decode(ideal: set[str]):
        grid = grid_true if "grid" in ideal else grid_est
        src = clean if "noise" in ideal else noisy
        lin = src["cap"]
        if "white" in ideal:
            wht = exact_white
        else:
            wht = src["white"] / r["resp"][cmap]
        usable = wht >= 0.05
        if "demosaic" in ideal:
            planes = [_levels(cap_e[p], r, noise="noise" not in ideal, rng=rng) for p in ("RRRR", "GGGG", "BBBB")]
            rgb = np.stack([np.where(usable, p / np.maximum(wht, 0.05), 0) for p in planes], axis=-1)
            rgb = np.maximum(rgb, 0).astype(np.float32)
        else:
            devig = np.maximum(np.where(usable, lin / np.maximum(wht, 0.05), 0.0), 0).astype(np.float32)
            rgb = demosaic(devig, cfa_pattern="GRBG", method=args.demosaic)
        step = grid.spacing_x_px / VIEW_STEP_DIVISOR
        samples = _sample_views(rgb, grid, 5, step)
        if "resample" in ideal:
            return samples, truth_lenslets
        return hex_to_square(samples, grid), truth

    # distance of every output pixel from the nearest clipped truth sample (any view, any colour)
    from scipy import ndimage

    from lfproc.lytro.virtual import lenslet_spatial_positions

    clipped = (truth >= clip).any(axis=(0, 1, 4))
    dist = ndimage.distance_transform_edt(~clipped)
    jr, kc = lenslet_spatial_positions(grid_true)
    dist_lenslets = dist[np.clip(jr.astype(int), 0, dist.shape[0] - 1),
                         np.clip(np.rint(kc).astype(int), 0, dist.shape[1] - 1)]

    def score(pair, border=BORDER_PX):
        """PSNR (centre view, all views) over all scored samples, those within NEAR px of a clipped
        sample and those farther away."""
        d, t = pair
        dd = dist if t.shape[2:4] == dist.shape else dist_lenslets
        h2, w2 = min(d.shape[2], t.shape[2]), min(d.shape[3], t.shape[3])
        near = (dd[border:h2 - border, border:w2 - border] <= NEAR)[None, None, :, :, None]
        out = {}
        for name, m in (("all", None), ("near", near), ("away", ~near)):
            out[name] = []
            for sel in ((slice(2, 3), slice(2, 3)), (slice(None), slice(None))):
                mm = None if m is None else np.broadcast_to(m, d[sel][:, :, border:h2 - border,
                                                                      border:w2 - border].shape)
                peak = decode_psnr(d[sel], t[sel], clip=clip, border=border)["peak"]
                try:
                    out[name].append(round(decode_psnr(d[sel], t[sel], clip=clip, border=border, mask=mm,
                                                       peak=peak)["psnr_db"], 2))
                except Exception:  # noqa: BLE001 - a region can be empty (no clipped sample in the crop)
                    out[name].append(None)
        return out

    report = {"benchmark": "decode_error_budget", "size": list(args.size), "seed": args.seed,
              "demosaic": args.demosaic, "clip_level": clip, "render_s": round(render_s, 1),
              "columns": f"PSNR dB [centre view, all 25 views] over all scored samples, those within {NEAR} px "
                         "of a clipped truth sample (near) and the rest (away)"}
    # the decoder itself (hot pixels, unusable samples set to 0) on the noisy capture
    span_dn = lambda x: x * span + r["prof"].black_level_dn  # noqa: E731
    res = decode_lenslet(np.rint(span_dn(noisy["cap"])).astype(np.uint16),
                         np.rint(span_dn(noisy["white"])).astype(np.uint16), grid_est,
                         black_level=r["prof"].black_level_dn, white_level=r["prof"].white_level_dn,
                         cfa_pattern="GRBG", white_responses=tuple(r["resp"]), demosaic_method=args.demosaic)
    res0 = decode_lenslet(np.rint(span_dn(noisy["cap"])).astype(np.uint16),
                          np.rint(span_dn(noisy["white"])).astype(np.uint16), grid_est,
                          black_level=r["prof"].black_level_dn, white_level=r["prof"].white_level_dn,
                          cfa_pattern="GRBG", white_responses=tuple(r["resp"]), demosaic_method=args.demosaic,
                          fill=False)
    report["decoder, unusable samples 0"] = score((res0["data"], truth))
    report["decoder"] = {"border 4": score((res["data"], truth)), "border 0": score((res["data"], truth), 0)["all"],
                         "border 12": score((res["data"], truth), 12)["all"],
                         "usable fraction": round(float((res["weight"] > 0).mean()), 4),
                         "near fraction": round(float((dist <= NEAR).mean()), 4)}
    base = decode(set())
    report["pipeline (no hot pixels, no inpainting)"] = score(base)
    stages = ("grid", "noise", "white", "demosaic", "resample")
    report["one stage ideal"] = {s: score(decode({s})) for s in stages}
    cumulative, ideal = {}, set()
    for s in stages:
        ideal.add(s)
        cumulative["+" + s] = score(decode(set(ideal)))
    report["cumulative ideal"] = cumulative
    report["all ideal, border 0 / 12"] = [score(decode(ideal), 0)["all"], score(decode(ideal), 12)["all"]]
    report["total_s"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
