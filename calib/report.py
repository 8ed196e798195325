"""Calibration report: PNG plots (matplotlib, Agg backend) and a Markdown summary.

Files written (atomically, as one folder):

* ``photon_transfer.png``: temporal noise (DN, log) against signal above dark (DN, log) per
  ISO, with the fitted shot-noise line ``sqrt(K * signal)``;
* ``dark_level.png`` and ``dark_variance.png``: dark level and dark temporal variance against
  exposure time with their fitted lines (the dark current);
* ``read_noise_vs_iso.png``: read noise (DN and e-) against ISO with the fitted
  ``sqrt(K^2 sigma_pre^2 + sigma_post^2)``;
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
    ("saturation_variance_max_dn", "mu_y.sat (DN)"),
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
    lines = ["| figure | " + " | ".join(f"ISO {k}" for k in isos) + " |", "|---|" + "---|" * len(isos)]
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


def _plots(result: CalibrationResult, folder: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    written = []
    # photon transfer
    fig = Figure(figsize=(6, 4.5))
    ax = fig.add_subplot()
    for key, c in result.curves.items():
        s = np.asarray(c["flat_signal_dn"], float)
        v = np.asarray(c["flat_var_dn2"], float)
        ok = (s > 0) & (v > 0)
        if ok.any():
            line = ax.loglog(s[ok], np.sqrt(v[ok]), "o", ms=4, label=f"ISO {key}")[0]
            if c.get("gain_dn_per_e"):
                xs = np.geomspace(s[ok].min(), s[ok].max(), 50)
                ax.loglog(xs, np.sqrt(c["gain_dn_per_e"] * xs), "-", color=line.get_color(), lw=1)
    ax.set_xlabel("signal above dark (DN)")
    ax.set_ylabel("temporal noise, dark removed (DN)")
    ax.set_title("Photon transfer (lines: shot noise of the fitted gain)")
    ax.grid(True, which="both", alpha=0.3)
    if ax.has_data():
        ax.legend(fontsize=8)
    fig.savefig(folder / "photon_transfer.png", dpi=100)
    written.append("photon_transfer.png")
    # dark level / variance
    for fname, xkey, ykey, skey, ylabel, icept in (
        ("dark_level.png", "dark_exposure_s", "dark_mean_dn", "dark_mean_slope_dn_per_s", "dark level (DN)", "black_level_dn"),
        ("dark_variance.png", "dark_var_exposure_s", "dark_var_dn2", "dark_var_slope_dn2_per_s",
         "dark temporal variance (DN^2)", "read_var_dn2"),
    ):
        fig = Figure(figsize=(6, 4.5))
        ax = fig.add_subplot()
        for key, c in result.curves.items():
            t = np.asarray(c[xkey], float)
            y = np.asarray(c[ykey], float)
            if t.size:
                line = ax.plot(t, y, "o", ms=4, label=f"ISO {key}")[0]
                if c.get(skey) is not None and c.get(icept) is not None:
                    xs = np.linspace(0, t.max(), 20)
                    ax.plot(xs, c[icept] + c[skey] * xs, "-", color=line.get_color(), lw=1)
        ax.set_xlabel("exposure time (s)")
        ax.set_ylabel(ylabel)
        ax.set_title("Dark signal against exposure time (lines: fits)")
        ax.grid(True, alpha=0.3)
        if ax.has_data():
            ax.legend(fontsize=8)
        fig.savefig(folder / fname, dpi=100)
        written.append(fname)
    # read noise vs ISO
    fig = Figure(figsize=(6, 4.5))
    ax = fig.add_subplot()
    pts = [(k, f) for k, f in result.figures.items() if f.get("read_noise_dn") is not None]
    numeric = [(float(k), f) for k, f in pts if k.replace(".", "").isdigit()]
    if numeric:
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
    else:
        ax.text(0.5, 0.5, "no read noise per ISO", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("ISO")
    ax.set_ylabel("read noise")
    ax.set_title("Read noise against ISO")
    ax.grid(True, which="both", alpha=0.3)
    fig.savefig(folder / "read_noise_vs_iso.png", dpi=100)
    written.append("read_noise_vs_iso.png")
    return written


def write_report(result: CalibrationResult, out_dir: str | os.PathLike, *, force: bool = False) -> list[Path]:
    """Write the calibration report folder (see the module documentation).

    Returns
    -------
    list of Path
        The files written.
    """
    out_dir = Path(out_dir)
    with atomic_dir(out_dir, force=force) as tmp:
        names = _plots(result, tmp)
        (tmp / "summary.md").write_text(summary_markdown(result))
        (tmp / "figures.json").write_text(json.dumps(result.to_json(), indent=1, default=float))
        names += ["summary.md", "figures.json"]
    return [out_dir / n for n in names]
