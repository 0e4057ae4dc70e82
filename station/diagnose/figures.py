"""The figures, drawn from plain numbers (so that another process can draw them): the report's
residuals per segment and candidate effects, the Allan deviation with its fitted noise terms,
and the drift of a calibration's parameters over time (matplotlib).  SVG or PNG by the file
name's suffix (``figure_format``): the report's figures are SVG, text left as text (a third less
CPU than PNG: no glyphs rasterised, no pixels compressed; sharp at any zoom), the command-line
plots PNG unless their file name ends in .svg.

What a figure costs is mostly matplotlib's text machinery, not the data (docs/performance.md,
"Diagnose and the report"), so the figures here avoid its expensive defaults: titles at a fixed
height (``TITLE_Y``: an automatic title measures every tick label of the axis below it), log
axes labelled 1-2-5 (τ: decades) in plain numbers without minor ticks (``plain_log_axis``:
mathtext powers of ten are parsed per label), at most six ticks on a linear axis
(``few_ticks``: each tick is a dozen artists), legends in a named corner (``"best"`` tests every
place against every line), fixed margins instead of ``tight_layout``, and a fast PNG
compression level.
"""
from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.core import units

COLOURS = {"x": "tab:red", "y": "tab:green", "z": "tab:blue"}
SCALE_UNITS = ("1", "raw/(m/s^2)", "raw/(deg/s)")
TITLE_Y = 1.0          # an axes title's height in axes coordinates, fixed (see above)
PNG_COMPRESSION = 1    # zlib level: 1 encodes in a third of the time of 6 for ~10 % more bytes
MOST_NAMES = 60        # segment names under a panel at most: more, rotated at 7 pt, are a black band


def _short(name: str, most: int = 32) -> str:
    """A segment name as a tick label: at most ``most`` characters, its start and its end (names
    that share a long prefix differ at the end; the page's tables have them whole)."""
    if len(name) <= most:
        return name
    tail = (most - 1) // 2
    return name[:most - 1 - tail] + "…" + name[-tail:]


def pyplot():
    import warnings

    import matplotlib

    # a glyph the font lacks (a segment named in CJK): an SVG's text is drawn by the viewer's
    # fonts, and a PNG's box is the only thing to say; not a warning on the user's terminal
    warnings.filterwarnings("ignore", r"Glyph \d+ .*missing from", UserWarning)

    matplotlib.use("Agg")
    # SVG: text as text (the viewer's font), and the same bytes on every run (fixed element ids);
    # no text is a formula: a segment named "$\foo$" was parsed as mathtext (and crashed it)
    matplotlib.rcParams.update({"svg.fonttype": "none", "svg.hashsalt": "station", "text.parse_math": False})
    import matplotlib.pyplot as plt

    return plt


def figure_format(name) -> str:
    """"svg" for a file name ending in .svg, else "png"."""
    return "svg" if str(name).lower().endswith(".svg") else "png"


def save(fig, path=None, fmt: str | None = None) -> bytes:
    """The figure's bytes in ``fmt`` ("svg" or "png"; by default from ``path``'s suffix, PNG
    without one); also written to ``path`` when given."""
    if path is not None:
        from station.core.user_files import output_path

        output_path(path, "the figure")
    plt = pyplot()
    buf = io.BytesIO()
    if (fmt or figure_format(path or "")) == "svg":
        fig.savefig(buf, format="svg", metadata={"Date": None})      # no date: the same bytes
    else:
        fig.savefig(buf, format="png", dpi=90, pil_kwargs={"compress_level": PNG_COMPRESSION})
    plt.close(fig)
    data = buf.getvalue()
    if path is not None:
        Path(path).write_bytes(data)
    return data


def plain_log_axis(axis, subs=(1.0, 2.0, 5.0)) -> None:
    """A log axis labelled at ``subs`` (1, 2 and 5; (1,): the decades) times powers of ten in
    plain numbers, no minor ticks."""
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullLocator

    axis.set_major_locator(LogLocator(subs=subs))
    axis.set_major_formatter(FormatStrFormatter("%g"))
    axis.set_minor_locator(NullLocator())


def few_ticks(*axes, most: int = 5) -> None:
    """At most ``most`` + 1 labelled ticks on each linear axis of ``axes`` (matplotlib's default
    is up to ten on an axis this wide: every tick is a dozen artists to create, measure and
    draw); log axes are left as they are (plain_log_axis)."""
    from matplotlib.ticker import MaxNLocator

    for ax in axes:
        for axis in (ax.xaxis, ax.yaxis):
            if axis.get_scale() == "linear":
                axis.set_major_locator(MaxNLocator(most, steps=[1, 2, 2.5, 5, 10]))


@dataclass
class SegmentPanel:
    title: str
    reduced_chi2: float
    names: list              # segment names, in capture order
    kinds: list              # "static" or "rotation"
    rms: list                # RMS whitened residual per segment (1 = the noise level)


@dataclass
class SegmentsFigure:
    """The residual per segment of the model as fitted and after each added effect."""
    panels: list             # SegmentPanel


@dataclass
class CandidateFigure:
    """A candidate effect: the residuals against the change it would make (one Gauss-Newton
    step), and against its signature variable; in units of each residual's sigma."""
    effect: str
    predicted_chi2_drop: float
    change: np.ndarray
    residual: np.ndarray
    variable_label: str
    variable: np.ndarray
    variable_residual: np.ndarray


def draw(specs: dict) -> dict:
    """{file name: bytes} of {file name: SegmentsFigure, CandidateFigure or a NoiseResult}, each
    in the format of its name (figure_format)."""
    from station.estimate.noise import NoiseResult

    drawers = {SegmentsFigure: segments_figure, CandidateFigure: candidate_figure, NoiseResult: allan_figure}
    return {name: drawers[type(spec)](spec, fmt=figure_format(name)) for name, spec in specs.items()}


def segments_figure(spec: SegmentsFigure, path=None, fmt: str | None = None) -> bytes:
    """Bars of the RMS whitened residual per segment, every panel on the same (log) y axis so
    that the fall after each added effect shows; the segment names under the last panel when
    every panel has the same segments (one fit of one capture: they do), else under each (every
    segment's up to MOST_NAMES, every k-th beyond, said under the axis).  The
    bars of a panel are one collection (``bar`` makes an artist per bar) and a panel without
    names has no x ticks (each is a dozen artists)."""
    from matplotlib.collections import PolyCollection
    from matplotlib.ticker import NullLocator

    plt = pyplot()
    panels = [SegmentPanel(p.title, p.reduced_chi2, [_short(name) for name in p.names], p.kinds, p.rms)
              for p in spec.panels]
    shared = all(p.names == panels[0].names for p in panels)
    # heights in inches from the text they hold: 0.35 in above the first panel for its title;
    # under a panel with names, the rotated names (7 pt: under 0.06 in a character); between
    # panels, a title (and the names when they are not shared)
    longest = max((len(name) for p in panels for name in p.names), default=8)
    top, plot = 0.35, 1.6
    bottom = max(0.95, 0.3 + 0.06 * longest) + (0.2 if any(len(p.names) > MOST_NAMES for p in panels) else 0.0)
    gap = 0.45 if shared else bottom + 0.15
    height = top + bottom + plot * len(panels) + gap * (len(panels) - 1)
    fig, axes = plt.subplots(len(panels), 1, figsize=(11, height), squeeze=False, sharey=True)
    fig.subplots_adjust(left=0.065, right=0.99, top=1.0 - top / height, bottom=bottom / height,
                        hspace=gap / plot)
    values = [v for p in panels for v in p.rms if v > 0]
    lo = min(min(values, default=1.0), 0.5) / 1.5
    hi = max(max(values, default=1.0), 2.0) * 1.5
    for k, (ax, p) in enumerate(zip(axes[:, 0], panels)):
        colours = ["tab:blue" if kind == "static" else "tab:orange" for kind in p.kinds]
        # a bar from below the axis to its value (a zero or missing value: no bar)
        bars = [[(i - 0.4, lo / 10), (i - 0.4, h), (i + 0.4, h), (i + 0.4, lo / 10)]
                for i, v in enumerate(p.rms) for h in [v if np.isfinite(v) and v > 0 else lo / 10]]
        ax.add_collection(PolyCollection(bars, facecolors=colours, edgecolors="none"))
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_yscale("log")
        ax.set_ylim(lo, hi)
        ax.set_xlim(-0.6, len(p.names) - 0.4)
        plain_log_axis(ax.yaxis)
        if not shared or k == len(panels) - 1:
            # every segment named up to MOST_NAMES; beyond, every step-th (in capture order)
            step = -(-len(p.names) // MOST_NAMES)
            named = range(0, len(p.names), max(step, 1))
            ax.set_xticks(list(named), [p.names[i] for i in named], rotation=90, fontsize=7)
            if step > 1:
                ax.set_xlabel(f"{len(p.names)} segments in capture order, one named every {step}", fontsize=8)
        else:
            ax.xaxis.set_major_locator(NullLocator())
        ax.set_ylabel("RMS residual / noise")
        ax.set_title(f"{p.title}: reduced χ² {p.reduced_chi2:.3g} (blue static, orange rotation; "
                     "dashed: the noise level)", fontsize=9, y=TITLE_Y)
    return save(fig, path, fmt)


def candidate_figure(spec: CandidateFigure, path=None, fmt: str | None = None) -> bytes:
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    fig.subplots_adjust(left=0.065, right=0.975, bottom=0.13, top=0.92, wspace=0.22)
    a1.scatter(spec.change, spec.residual, s=6)
    lim = np.nanmax(np.abs(np.concatenate([spec.change, spec.residual]))) if len(spec.change) else 0.0
    lim = lim or 1.0
    a1.plot([-lim, lim], [-lim, lim], "k--", lw=0.8)
    a1.set_xlabel(f"change {spec.effect} would make (one step), sigma")
    a1.set_ylabel("residual, sigma")
    a1.set_title(f"{spec.effect}: predicted chi2 drop {spec.predicted_chi2_drop:.3g}", y=TITLE_Y)
    a2.scatter(spec.variable, spec.variable_residual, s=6)
    a2.set_xlabel(spec.variable_label)
    a2.set_ylabel("residual, sigma")
    a2.set_title("residual against its signature variable", y=TITLE_Y)
    few_ticks(a1, a2)
    return save(fig, path, fmt)


def allan_figure(result, path=None, fmt: str | None = None) -> bytes:
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
        plain_log_axis(ax.xaxis, subs=(1.0,))     # τ spans decades (the tick labels: 20 % of the figure)
        plain_log_axis(ax.yaxis)
        ax.grid(True, alpha=0.3)
        # the curves fall from the upper left: the upper right is free unless a random walk rises
        ax.legend(title="axis (band: 68 % interval)", fontsize=8, title_fontsize=8, loc="upper right")
    fig.suptitle("overlapping Allan deviation; dashed: white noise (slope −1/2), dotted: bias "
                 "instability (0.664 B), dash-dot: random walk (slope +1/2)", fontsize=9)
    return save(fig, path, fmt)


DRIFT_MARKS = {"passes": ("o", "C0", "passes"), "fails": ("X", "C3", "fails / not converged"),
               "other": ("s", "0.55", "untested / noise overestimated / not stated")}


def drift_status(verdict: str) -> str:
    """The drift plot's class of a calibration's verdict (history's words)."""
    word = (verdict or "").split(":")[0].strip()
    return "passes" if word == "passes" else "fails" if word in ("fails", "not converged") else "other"


def drift_figure(rows, path=None, title: str = "", fmt: str | None = None) -> bytes:
    """rows: {parameter: [(date, value, sigma, unit[, status]), ...]}; one small panel per
    parameter with ±1σ error bars against the calibration date.  ``status`` (drift_status):
    failing calibrations drawn as red crosses, untested ones as grey squares, apart from the
    passing ones; a point without a 1σ has no bar and an open marker."""
    import datetime as dt

    from matplotlib.dates import AutoDateLocator
    from matplotlib.ticker import MaxNLocator

    plt = pyplot()
    names = list(rows)
    ncol = 3
    nrow = max(1, -(-len(names) // ncol))
    # fixed margins in inches (the module's doc: tight_layout measured every tick label of the 21
    # panels twice, and autofmt_xdate once more, ~60 % of the figure's CPU): left of each panel
    # its y tick labels (at most 6 at 7 pt, ~9 characters: ~0.5 in with the ticks), above each
    # its title (8 pt), under the lowest panel of each column the dates rotated by 30 deg (the
    # panels above it show the same dates: their labels left out, as autofmt_xdate did), and
    # the title above them all
    width, height = 12.0, 2.2 * nrow
    left, right, gap_w = 0.75, 0.15, 0.8
    top, bottom, gap_h = (0.75 if title else 0.35), 0.75, 0.45
    fig, axes = plt.subplots(nrow, ncol, figsize=(width, height), squeeze=False)
    panel_w = (width - left - right - (ncol - 1) * gap_w) / ncol
    panel_h = (height - top - bottom - (nrow - 1) * gap_h) / nrow
    fig.subplots_adjust(left=left / width, right=1.0 - right / width, top=1.0 - top / height,
                        bottom=bottom / height, wspace=gap_w / panel_w, hspace=gap_h / panel_h)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    for index, (ax, name) in enumerate(zip(axes.ravel(), names)):
        pts = rows[name]
        when = [dt.datetime.strptime(p[0], "%Y-%m-%dT%H:%M:%SZ") for p in pts]
        vals = np.array([p[1] for p in pts], float)
        sig = np.array([p[2] if p[2] is not None else np.nan for p in pts], float)
        unit = pts[0][3]
        if unit in SCALE_UNITS and vals[0]:       # scale factors: ppm from the first calibration
            vals, sig, unit = (vals / vals[0] - 1.0) * 1e6, sig / vals[0] * 1e6, f"ppm from {pts[0][1]:.6f}"
        status = [p[4] if len(p) > 4 else "passes" for p in pts]
        ax.plot(when, vals, "-", lw=0.6, color="0.7")
        for kind, (marker, colour, _) in DRIFT_MARKS.items():
            k = [i for i, s in enumerate(status) if s == kind]
            if not k:
                continue
            with_sigma = [i for i in k if np.isfinite(sig[i])]
            without = [i for i in k if not np.isfinite(sig[i])]
            if with_sigma:
                ax.errorbar([when[i] for i in with_sigma], vals[with_sigma], yerr=sig[with_sigma], fmt=marker,
                            color=colour, ms=4, lw=0.8, capsize=2)
            if without:
                ax.plot([when[i] for i in without], vals[without], marker, ms=5, mfc="none", color=colour)
        ax.set_title(f"{name} ({unit})", fontsize=8, y=TITLE_Y)
        ax.tick_params(labelsize=7)
        ax.yaxis.set_major_locator(MaxNLocator(5, steps=[1, 2, 2.5, 5, 10]))      # (few_ticks: y only)
        ax.xaxis.set_major_locator(AutoDateLocator(minticks=3, maxticks=6))         # (its dates)
        ax.yaxis.get_major_formatter().set_useOffset(False)
        if index + ncol < len(names):       # a panel of the same column below: its dates there
            ax.tick_params(axis="x", labelbottom=False)
        else:
            ax.tick_params(axis="x", labelrotation=30)
            for label in ax.get_xticklabels():
                label.set_ha("right")
    if title:
        seen = {p[4] if len(p) > 4 else "passes" for pts in rows.values() for p in pts}
        if seen - {"passes"}:
            title += "   (" + "; ".join(f"{m}: {words}" for kind, (m, _, words) in DRIFT_MARKS.items()
                                         if kind in seen) + "; open marker: no 1σ)"
        fig.suptitle(title, fontsize=10, y=1.0 - 0.25 / height, va="top")
    return save(fig, path, fmt)


@dataclass
class FleetRow:
    """One parameter of the fleet figure: each unit's distance from the rest of its lot in σ of
    the lot, which units are outside the lot's spread, and the distance beyond which they are."""
    name: str
    z: list                  # per unit, (x - m) / s; None where not judged
    outside: list            # per unit, bool
    limit: float | None      # in the same σ: t_limit·sqrt(1 + 1/(n-1))


FLEET_INSIDE, FLEET_OUTSIDE = "tab:blue", "tab:red"


def fleet_figure(rows: list, path=None, title: str = "", fmt: str | None = None) -> bytes:
    """Every parameter on one row, every unit a dot at its distance from the rest of the lot in σ
    of the lot; units outside the lot's spread in red, the limit as grey bars."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 0.32 * max(len(rows), 3) + 1.2))
    for k, row in enumerate(rows):
        y = len(rows) - 1 - k
        for z, out in zip(row.z, row.outside):
            if z is not None:
                ax.plot([max(min(z, 12.0), -12.0)], [y], "o", ms=7 if out else 4,
                        color=FLEET_OUTSIDE if out else FLEET_INSIDE, alpha=1.0 if out else 0.6)
        if row.limit is not None:
            for s in (-1, 1):
                ax.plot([s * min(row.limit, 12.0)] * 2, [y - 0.35, y + 0.35], "-", color="0.55", lw=1.2)
    ax.set_yticks(range(len(rows)), [r.name for r in reversed(rows)], fontsize=8)
    ax.set_xlim(-12.5, 12.5)
    ax.set_ylim(-0.7, len(rows) - 0.3)
    ax.axvline(0.0, color="0.8", lw=0.8)
    ax.set_xlabel("distance from the rest of the lot, in σ of the lot (clipped at ±12)", fontsize=8)
    ax.tick_params(axis="x", labelsize=8)
    if title:
        ax.set_title(title, fontsize=9, y=TITLE_Y)
    fig.subplots_adjust(left=0.24, right=0.98, top=1 - 0.45 / fig.get_figheight(),
                        bottom=0.75 / fig.get_figheight())
    return save(fig, path, fmt)
