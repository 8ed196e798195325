"""Calibration report: PNG plots (matplotlib, Agg backend) and a Markdown summary.

Files written (atomically, as one folder; every plot names the ISOs as the profile stores
them, e.g. ``ISO 100`` for an EMVA 1288 data set):

* ``photon_transfer.png``: temporal noise (DN, log) against signal above dark (DN, log) per
  ISO, with the fitted shot-noise line ``sqrt(K * signal)``;
* ``dark_level.png`` and ``dark_variance.png``: dark level and dark temporal variance against
  exposure time with their fitted lines (the dark current);
* ``read_noise_vs_iso.png``: read noise (DN and e-) against ISO with the fitted
  ``sqrt(K^2 sigma_pre^2 + sigma_post^2)`` (only with two ISOs or more);
* ``snr.png``: the EMVA 1288 SNR curve (measured, the linear model and the ideal ``sqrt(mu_e)``);
* ``linearity.png``: signal against photons (or exposure time) with the EMVA line over 5-95 % of
  saturation and the deviation in percent (when the light varies over at least three levels);
* ``prnu_dsnu_histograms.png``: histograms of the master bias frames (DSNU, e-) and of the flat
  field (PRNU, %) (when the profile has them);
* ``summary.md``: tables of every ISO's profile figures and EMVA 1288 figures, the read-noise
  model and the unknowns; ``figures.json``: every figure.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from lfproc._version import __version__
from lfproc.io._atomic import atomic_dir

from .calibrate import CalibrationResult
from lfproc.calib.emva import SIGMA2_Q
from lfproc._shared.deps import require

__all__ = ["write_report", "summary_markdown", "SUMMARY_COLUMNS", "PROFILE_COLUMNS", "EMVA_COLUMNS", "format_value"]

#: The figures stored in the camera profile (``lfproc profile show`` prints the same values).
PROFILE_COLUMNS = (
    ("gain_dn_per_e", "gain (DN/e-)"),
    ("read_noise_dn", "read noise (DN)"),
    ("read_noise_e", "read noise (e-)"),
    ("black_level_dn", "black (DN)"),
    ("dsnu_e", "DSNU (e-)"),
    ("prnu", "PRNU"),
    ("dark_current_e_per_s", "dark current (e-/s)"),
    ("dark_current_var_e_per_s", "dark current, var. (e-/s)"),
    ("saturation_dn", "saturation (DN)"),
    ("full_well_e", "full well (e-)"),
    ("hot_pixels", "hot pixels"),
)
#: EMVA 1288 figures (Release 4 "Linear"); the saturation capacity is taken at the variance
#: maximum, below the saturation code where over-exposed frames pile up.
EMVA_COLUMNS = (
    ("quantum_efficiency", "QE eta"),
    ("responsivity_dn_per_photon", "responsivity R (DN/p)"),
    ("temporal_dark_noise_dn", "sigma_y.dark (DN)"),
    ("saturation_mean_dn", "mu_y.sat, mean at the variance max. (DN)"),
    ("saturation_capacity_emva_e", "sat. capacity mu_e.sat (e-)"),
    ("absolute_sensitivity_threshold_e", "abs. sensitivity mu_e.min (e-)"),
    ("snr_max_db", "SNR max (dB)"),
    ("dynamic_range_emva_db", "DR (dB)"),
    ("linearity_error_min_percent", "linearity error min (%)"),
    ("linearity_error_max_percent", "linearity error max (%)"),
)
SUMMARY_COLUMNS = PROFILE_COLUMNS + EMVA_COLUMNS


def format_value(value) -> str:
    """A figure for tables: ``unknown`` for None, 5 significant digits for floats."""
    if value is None:
        return "unknown"
    if isinstance(value, float):
        return f"{value:.5g}"
    return str(value)


_fmt = format_value


def _table(result: CalibrationResult, columns) -> list[str]:
    isos = list(result.figures)
    lines = ["| figure | " + " | ".join(result.iso_label(k) for k in isos) + " |", "|---|" + "---|" * len(isos)]
    for key, label in columns:
        lines.append(f"| {label} | " + " | ".join(_fmt(result.figures[k].get(key)) for k in isos) + " |")
    return lines


def summary_markdown(result: CalibrationResult) -> str:
    """The Markdown summary: the profile's figures and the EMVA 1288 figures (one column per ISO),
    read-noise model, unknowns, notes."""
    profile = result.profile
    sensor = "monochrome" if profile.is_mono else f"Bayer {profile.cfa_pattern}"
    lines = [f"# Calibration of `{profile.name}`", "",
             f"lfproc {__version__}; input: {result.source.get('input')}; method: {result.source.get('method')}; "
             f"sensor: {sensor}, {profile.adc_bits} bit", "",
             "## Profile figures", ""]
    lines += _table(result, PROFILE_COLUMNS)
    lines += ["", "## EMVA 1288 figures", ""]
    lines += _table(result, EMVA_COLUMNS)
    m = result.read_noise_model
    lines += ["", "## Read noise across ISOs", ""]
    if m.get("sigma_pre_e") is not None:
        lines.append(f"`read_noise_dn^2 = gain^2 * sigma_pre^2 + sigma_post^2`: sigma_pre = {m['sigma_pre_e']:.4g} e-, "
                     f"sigma_post = {m['sigma_post_dn']:.4g} DN ({m['n_isos']} ISOs).")
    else:
        lines.append(f"Not determined: {m.get('unknown')}.")
    if result.unknown:
        lines += ["", "## Unknown figures", ""] + [f"- `{k}`: {v}" for k, v in sorted(result.unknown.items())]
    if result.notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in result.notes]
    return "\n".join(lines) + "\n"


def _figure(Figure):
    # constrained layout keeps the axis labels inside the picture (they were cut off before)
    return Figure(figsize=(6.4, 4.8), layout="constrained")


def _save(fig, folder: Path, name: str, written: list[str]) -> None:
    """Write the figure, its title also in the PNG's ``Title`` text chunk."""
    title = fig._suptitle.get_text() if fig._suptitle is not None else fig.axes[0].get_title()
    fig.savefig(folder / name, dpi=100, metadata={"Title": title, "Software": f"lfproc {__version__}"})
    written.append(name)


def _photon_transfer(result, Figure, folder, written) -> None:
    fig = _figure(Figure)
    ax = fig.add_subplot()
    for key, c in result.curves.items():
        s = np.asarray(c["flat_signal_dn"], float)
        v = np.asarray(c["flat_var_dn2"], float)
        ok = (s > 0) & (v > 0)
        if ok.any():
            line = ax.loglog(s[ok], np.sqrt(v[ok]), "o", ms=4, label=result.iso_label(key))[0]
            if c.get("gain_dn_per_e"):
                xs = np.geomspace(s[ok].min(), s[ok].max(), 50)
                ax.loglog(xs, np.sqrt(c["gain_dn_per_e"] * xs), "-", color=line.get_color(), lw=1)
    ax.set_xlabel("signal above dark (DN)")
    ax.set_ylabel("temporal noise, dark removed (DN)")
    ax.set_title("Photon transfer (lines: shot noise of the fitted gain)")
    ax.grid(True, which="both", alpha=0.3)
    if ax.has_data():
        ax.legend(fontsize=8)
    _save(fig, folder, "photon_transfer.png", written)


def _dark(result, Figure, folder, written) -> None:
    for fname, xkey, ykey, skey, ylabel, icept, title in (
        ("dark_level.png", "dark_exposure_s", "dark_mean_dn", "dark_mean_slope_dn_per_s", "dark level (DN)",
         "black_level_dn", "Dark level against exposure time (lines: fits; slope = dark current)"),
        ("dark_variance.png", "dark_var_exposure_s", "dark_var_dn2", "dark_var_slope_dn2_per_s",
         "dark temporal variance (DN$^2$)", "read_var_dn2",
         "Dark temporal variance against exposure time (lines: fits)"),
    ):
        fig = _figure(Figure)
        ax = fig.add_subplot()
        for key, c in result.curves.items():
            t = np.asarray(c[xkey], float)
            y = np.asarray(c[ykey], float)
            if t.size:
                line = ax.plot(t, y, "o", ms=4, label=result.iso_label(key))[0]
                if c.get(skey) is not None and c.get(icept) is not None:
                    xs = np.linspace(0, t.max(), 20)
                    ax.plot(xs, c[icept] + c[skey] * xs, "-", color=line.get_color(), lw=1)
        ax.set_xlabel("exposure time (s)")
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=10)
        ax.grid(True, alpha=0.3)
        if ax.has_data():
            ax.legend(fontsize=8)
        _save(fig, folder, fname, written)


def _read_noise(result, Figure, folder, written) -> None:
    pts = [(k, f) for k, f in result.figures.items() if f.get("read_noise_dn") is not None]
    numeric = [(float(result.iso(k)), f) for k, f in pts if result.iso(k) is not None]
    if len(numeric) < 2:  # one ISO: a single point, no curve (its figures are in summary.md)
        return
    fig = _figure(Figure)
    ax = fig.add_subplot()
    iso = np.array([k for k, _ in numeric])
    ax.loglog(iso, [f["read_noise_dn"] for _, f in numeric], "o-", label="read noise (DN)")
    e = [(k, f["read_noise_e"]) for k, f in numeric if f.get("read_noise_e")]
    if e:
        ax.loglog([k for k, _ in e], [v for _, v in e], "s-", label="read noise (e-)")
    m = result.read_noise_model
    gains = [(k, f["gain_dn_per_e"]) for k, f in numeric if f.get("gain_dn_per_e")]
    if m.get("sigma_pre_e") is not None and gains:
        ks = np.array([g for _, g in gains])
        model = np.sqrt(ks**2 * m["sigma_pre_e"] ** 2 + m["sigma_post_dn"] ** 2)
        ax.loglog([k for k, _ in gains], model, "--", label="model sqrt(K^2 s_pre^2 + s_post^2) (DN)")
    ax.legend(fontsize=8)
    ax.set_xlabel("ISO")
    ax.set_ylabel("read noise (DN or e-)")
    ax.set_title("Read noise against ISO")
    ax.grid(True, which="both", alpha=0.3)
    _save(fig, folder, "read_noise_vs_iso.png", written)


def _snr(result, Figure, folder, written) -> None:
    """EMVA 1288 SNR curve: measured SNR against the signal in electrons, with the linear model
    ``mu_e / sqrt(sigma_d^2 + sigma_q^2 / K^2 + mu_e)`` and the ideal ``sqrt(mu_e)``."""
    fig = _figure(Figure)
    ax = fig.add_subplot()
    top = 0.0
    for key, c in result.curves.items():
        K = c.get("gain_dn_per_e")
        if not K:
            continue
        y = np.asarray(c["flat_signal_dn"], float)
        v = np.asarray(c["flat_var_dn2"], float) + (c.get("read_var_dn2") or 0.0)
        ok = (y > 0) & (v > 0)
        if ok.any():  # past the variance maximum the pixels saturate: no SNR there
            ok &= y <= y[ok][np.argmax(np.asarray(c["flat_var_dn2"], float)[ok])]
        if not ok.any():
            continue
        mu_e = y[ok] / K
        line = ax.loglog(mu_e, y[ok] / np.sqrt(v[ok]), "o", ms=4, label=f"{result.iso_label(key)} measured")[0]
        xs = np.geomspace(max(mu_e.min() / 2, 0.1), mu_e.max(), 100)
        rn = c.get("read_noise_e") or 0.0
        ax.loglog(xs, xs / np.sqrt(rn**2 + SIGMA2_Q / K**2 + xs), "-", color=line.get_color(), lw=1,
                  label=f"{result.iso_label(key)} model")
        top = max(top, mu_e.max())
    if not ax.has_data():
        return
    xs = np.geomspace(0.1, top, 100)
    ax.loglog(xs, np.sqrt(xs), ":", color="0.4", lw=1, label="ideal sqrt(mu_e)")
    ax.set_xlabel("signal above dark, mu_e (e-)")
    ax.set_ylabel("signal-to-noise ratio")
    ax.set_title("SNR curve (EMVA 1288)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    _save(fig, folder, "snr.png", written)


def _linearity(result, Figure, folder, written) -> None:
    """EMVA 1288 linearity: mean signal against the light (photons when the data give them, else
    exposure time) with a 1/y-weighted line over 5-95 % of saturation, and the deviation in %."""
    fig = _figure(Figure)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    xlabel = None
    for key, c in result.curves.items():
        y = np.asarray(c["flat_signal_dn"], float)
        photons = np.asarray(c.get("flat_photons") or [], float)
        if photons.size == y.size and (photons > 0).all():
            x, xl = photons, "photons per pixel, mu_p"
        else:
            x, xl = np.asarray(c.get("flat_exposure_s") or [], float), "exposure time (s)"
        if x.size != y.size or np.unique(x).size < 3:
            continue  # the light did not vary through exposure: no linearity from this ISO
        clipped = np.asarray(c.get("flat_clipped_fraction") or np.zeros(y.size), float) > 1e-4
        sat = y[~clipped].max() if (~clipped).any() else y.max()
        fit = (y >= 0.05 * sat) & (y <= 0.95 * sat) & ~clipped
        if fit.sum() < 2:
            continue
        a, b = np.polyfit(x[fit], y[fit], 1, w=1.0 / y[fit])
        line = top.plot(x, y, "o", ms=4, label=result.iso_label(key))[0]
        xs = np.linspace(0, x.max(), 50)
        top.plot(xs, a * xs + b, "-", color=line.get_color(), lw=1)
        dev = 100.0 * (y[fit] - (a * x[fit] + b)) / (a * x[fit] + b)
        bottom.plot(x[fit], dev, "o-", ms=4, color=line.get_color())
        xlabel = xl if xlabel in (None, xl) else "photons or exposure time"
    if xlabel is None:
        return
    top.set_ylabel("signal above dark (DN)")
    top.grid(True, alpha=0.3)
    top.legend(fontsize=8)
    bottom.axhline(0, color="0.5", lw=0.8)
    bottom.set_ylabel("deviation (%)")
    bottom.set_xlabel(xlabel)
    bottom.grid(True, alpha=0.3)
    fig.suptitle("Linearity (EMVA 1288: line fitted over 5-95 % of saturation)", fontsize=11)
    _save(fig, folder, "linearity.png", written)


def _histograms(result, Figure, folder, written) -> None:
    """DSNU and PRNU histograms (EMVA 1288): the master bias frames less their mean, in e-, and
    the flat-field map less 1, in %; log counts so that the tails (hot and dead pixels) show."""
    profile = result.profile
    bias = {iso: frame for iso, frame in (profile.bias_frames or {}).items()}
    flat = profile.flat_field
    if not bias and flat is None:
        return
    fig = _figure(Figure)
    ax_d, ax_p = fig.subplots(1, 2)
    for iso, frame in sorted(bias.items()):
        K = profile.isos[iso].gain_dn_per_e if iso in profile.isos else None
        values = frame.astype(np.float64) - float(np.median(frame))
        unit = "DN"
        if K:
            values, unit = values / K, "e-"
        bins = int(min(100, max(10, np.unique(values).size // 2)))  # no empty bins between averaged codes
        ax_d.hist(values.ravel(), bins=bins, histtype="step", log=True, label=f"ISO {iso}")
        ax_d.set_xlabel(f"master bias less its median ({unit})")
    if bias:
        ax_d.set_ylabel("pixels")
        ax_d.set_title(f"DSNU (profile: {profile.dsnu_e:.3g} e-)", fontsize=10)
        ax_d.legend(fontsize=7)
        ax_d.grid(True, alpha=0.3)
    else:
        ax_d.set_axis_off()
    if flat is not None:
        ax_p.hist(100.0 * (flat.astype(np.float64).ravel() - 1.0), bins=100, histtype="step", log=True, color="C3")
        ax_p.set_xlabel("flat field less 1 (%)")
        ax_p.set_ylabel("pixels")
        ax_p.set_title(f"PRNU (profile: {100 * profile.prnu:.3g} %)", fontsize=10)
        ax_p.grid(True, alpha=0.3)
    else:
        ax_p.set_axis_off()
    fig.suptitle("Fixed-pattern histograms (EMVA 1288 DSNU and PRNU)", fontsize=11)
    _save(fig, folder, "prnu_dsnu_histograms.png", written)


def _plots(result: CalibrationResult, folder: Path) -> list[str]:
    require("matplotlib", purpose="the calibration report's plots")
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    written: list[str] = []
    _photon_transfer(result, Figure, folder, written)
    _dark(result, Figure, folder, written)
    _read_noise(result, Figure, folder, written)
    _snr(result, Figure, folder, written)
    _linearity(result, Figure, folder, written)
    _histograms(result, Figure, folder, written)
    return written


def write_report(result: CalibrationResult, out_dir: str | os.PathLike, *, force: bool = False) -> list[Path]:
    """Write the calibration report folder (see the module documentation).

    Parameters
    ----------
    result : CalibrationResult
        What :func:`lfproc.calib.calibrate` measured.
    out_dir : str or os.PathLike
        The report folder, written atomically.
    force : bool, default False
        Replace an existing folder.

    Returns
    -------
    list of Path
        The files written: the plots the figures allow, ``summary.md`` and ``figures.json``.

    Raises
    ------
    lfproc.errors.OutputExistsError
        ``out_dir`` exists and ``force`` is false.
    """
    out_dir = Path(out_dir)
    with atomic_dir(out_dir, force=force) as tmp:
        names = _plots(result, tmp)
        (tmp / "summary.md").write_text(summary_markdown(result))
        (tmp / "figures.json").write_text(json.dumps(result.to_json(), indent=1, default=float))
        names += ["summary.md", "figures.json"]
    return [out_dir / n for n in names]
