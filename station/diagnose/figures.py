"""Figures shared by the report page and the commands: the Allan deviation with its fitted noise
terms, and the drift of a calibration's parameters over time.  PNG files (matplotlib, Agg).

What a figure costs is mostly matplotlib's text machinery, not the data (docs/performance.md,
"Diagnose and the report"), so the figures here avoid its expensive defaults: titles at a fixed
height (``TITLE_Y``: an automatic title measures every tick label of the axis below it), log
axes labelled 1-2-5 in plain numbers without minor ticks (``plain_log_axis``: mathtext powers of
ten are parsed per label), legends in a named corner (``"best"`` tests every place against every
line), fixed margins instead of ``tight_layout``, and a fast PNG compression level.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from station.core import units

COLOURS = {"x": "tab:red", "y": "tab:green", "z": "tab:blue"}
SCALE_UNITS = ("1", "raw/(m/s^2)", "raw/(deg/s)")
TITLE_Y = 1.0          # an axes title's height in axes coordinates, fixed (see above)
PNG_COMPRESSION = 1    # zlib level: 1 encodes in a third of the time of 6 for ~10 % more bytes


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig, path=None) -> bytes:
    """PNG bytes of a figure; also written to ``path`` when given."""
    plt = pyplot()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, pil_kwargs={"compress_level": PNG_COMPRESSION})
    plt.close(fig)
    data = buf.getvalue()
    if path is not None:
        Path(path).write_bytes(data)
    return data


def plain_log_axis(axis) -> None:
    """A log axis labelled at 1, 2 and 5 times powers of ten in plain numbers, no minor ticks."""
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullLocator

    axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FormatStrFormatter("%g"))
    axis.set_minor_locator(NullLocator())


def allan_figure(result, path=None) -> bytes:
    """Log-log Allan deviation per axis with its 68 % band and the fitted terms: white noise
    (slope -1/2), bias instability (flat, 0.664 B) and random walk (slope +1/2)."""
    from station.estimate.noise import FLICKER_FACTOR

    plt = pyplot()
    fig, panels = plt.subplots(1, 2, figsize=(12, 4.8))
    # fixed margins: tight_layout measures every tick label of the log axes (half the time)
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.11, top=0.87, wspace=0.2)
    for ax, sensor, scale, unit in ((panels[0], "accel", 1.0 / units.UG_MPS2, "µg"),
                                    (panels[1], "gyro", 3600.0, "°/h")):
        for a in (x for x in result.axes if x.sensor == sensor):
            c = COLOURS[a.axis]
            ax.fill_between(a.taus, a.lo * scale, a.hi * scale, color=c, alpha=0.2, lw=0)
            ax.loglog(a.taus, a.adev * scale, color=c, lw=1.4, label=f"{a.axis}")
            ax.loglog(a.taus, a.white / np.sqrt(a.taus) * scale, color=c, ls="--", lw=0.8)
            if a.bias_instability is not None:
                ax.axhline(FLICKER_FACTOR * a.bias_instability * scale, color=c, ls=":", lw=0.8)
                ax.plot([a.bias_instability_tau], [FLICKER_FACTOR * a.bias_instability * scale], "o", color=c)
            if a.random_walk is not None:
                ax.loglog(a.taus, a.random_walk * np.sqrt(a.taus / 3.0) * scale, color=c, ls="-.", lw=0.8)
        rep = {a.axis: a.report() for a in result.axes if a.sensor == sensor}
        if sensor == "accel":
            text = "white " + ", ".join(f"{k} {v['white_noise_ug_rthz']:.3g}" for k, v in rep.items()) + " µg/√Hz"
        else:
            text = "white " + ", ".join(f"{k} {v['white_noise_dph_rthz']:.3g}" for k, v in rep.items()) + " °/h/√Hz"
        ax.set_title(f"{'accelerometers' if sensor == 'accel' else 'gyros'}: {text}", fontsize=9, y=TITLE_Y)
        ax.set_xlabel("averaging time τ (s)")
        ax.set_ylabel(f"Allan deviation ({unit})")
        plain_log_axis(ax.xaxis)
        plain_log_axis(ax.yaxis)
        ax.grid(True, alpha=0.3)
        # the curves fall from the upper left: the upper right is free unless a random walk rises
        ax.legend(title="axis (band: 68 % interval)", fontsize=8, title_fontsize=8, loc="upper right")
    fig.suptitle("overlapping Allan deviation; dashed: white noise (slope −1/2), dotted: bias "
                 "instability (0.664 B), dash-dot: random walk (slope +1/2)", fontsize=9)
    return save(fig, path)


def drift_figure(rows, path=None, title: str = "") -> bytes:
    """rows: {parameter: [(date, value, sigma, unit), ...]}; one small panel per parameter with
    ±1σ error bars against the calibration date."""
    import datetime as dt

    plt = pyplot()
    names = list(rows)
    ncol = 3
    nrow = max(1, -(-len(names) // ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(12, 2.2 * nrow), squeeze=False)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    for ax, name in zip(axes.ravel(), names):
        pts = rows[name]
        when = [dt.datetime.strptime(d, "%Y-%m-%dT%H:%M:%SZ") for d, _, _, _ in pts]
        vals = np.array([v for _, v, _, _ in pts], float)
        sig = np.array([s if s is not None else np.nan for _, _, s, _ in pts], float)
        unit = pts[0][3]
        if unit in SCALE_UNITS and vals[0]:       # scale factors: ppm from the first calibration
            vals, sig, unit = (vals / vals[0] - 1.0) * 1e6, sig / vals[0] * 1e6, f"ppm from {pts[0][1]:.6f}"
        ax.errorbar(when, vals, yerr=np.nan_to_num(sig), fmt="o-", ms=3, lw=0.8, capsize=2)
        ax.set_title(f"{name} ({unit})", fontsize=8, y=TITLE_Y)
        ax.tick_params(labelsize=7)
        ax.yaxis.get_major_formatter().set_useOffset(False)
    fig.autofmt_xdate()
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    return save(fig, path)
