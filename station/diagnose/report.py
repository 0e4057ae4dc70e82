"""Pictures of a diagnosis: PNG files and an index page in a report directory."""
from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from station.diagnose.core import PRIOR_QUANTITIES
from station.core.errors import UserError

VARIABLE_LABEL = {
    "rate_squared": "rotation rate squared (deg/s)^2",
    "temperature": "segment temperature (deg C)",
    "gravity_along_axis": "commanded gravity along the residual's axis (g)",
    "signed_rate": "signed rotation rate (deg/s)",
    "rate_change": "rate change across the segment (deg/s)",
}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _variable(name: str, diagnosis, labels) -> np.ndarray:
    s = diagnosis.result.model.s
    rot = {r.name: r for r in s.rotations}
    stat = {st.name: st for st in s.statics}
    out = np.full(len(labels), np.nan)
    for i, (seg, kind, quantity, axis) in enumerate(labels):
        r, st = rot.get(seg), stat.get(seg)
        if name == "rate_squared":
            out[i] = r.rate_dps ** 2 if r else 0.0
        elif name == "signed_rate" and r:
            out[i] = r.rate_dps
        elif name == "rate_change" and r:
            out[i] = float(np.linalg.norm(r.gyro_end - r.gyro_start))
        elif name == "temperature":
            seg_ = r or st
            out[i] = seg_.temp_c if seg_ is not None and seg_.temp_c is not None else np.nan
        elif name == "gravity_along_axis" and st is not None and st.up_body is not None and axis in "xyz":
            out[i] = st.up_body["xyz".index(axis)]
    return out


def _segments_figure(plt, path, panels):
    """panels: list of (title, diagnosis); bars of the RMS whitened residual per segment."""
    fig, axes = plt.subplots(len(panels), 1, figsize=(11, 2.8 * len(panels)), squeeze=False)
    for ax, (title, d) in zip(axes[:, 0], panels):
        names = [s.name for s in d.segments]
        rms = [s.rms for s in d.segments]
        colours = ["tab:blue" if s.kind == "static" else "tab:orange" for s in d.segments]
        ax.bar(range(len(names)), rms, color=colours)
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_yscale("log")
        ax.set_xticks(range(len(names)), names, rotation=90, fontsize=7)
        ax.set_ylabel("RMS residual / noise")
        ax.set_title(f"{title}: reduced chi2 {d.reduced_chi2:.3g} (blue static, orange rotation)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _candidate_figure(plt, path, diagnosis, cand):
    labels = diagnosis.labels
    r = diagnosis.result.model.residuals(diagnosis.result.x)
    data = np.array([q not in PRIOR_QUANTITIES
                     for _, _, q, _ in labels])
    pred = -cand.signature_rows
    var_name = cand.signature_variable
    var = _variable(var_name, diagnosis, labels)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    a1.scatter(pred[data], r[data], s=6)
    lim = np.nanmax(np.abs(np.concatenate([pred[data], r[data]]))) or 1.0
    a1.plot([-lim, lim], [-lim, lim], "k--", lw=0.8)
    a1.set_xlabel(f"change {cand.effect} would make (one step), sigma")
    a1.set_ylabel("residual, sigma")
    a1.set_title(f"{cand.effect}: predicted chi2 drop {cand.predicted_chi2_drop:.3g}")
    ok = data & np.isfinite(var)
    a2.scatter(var[ok], r[ok], s=6)
    a2.set_xlabel(VARIABLE_LABEL.get(var_name, var_name))
    a2.set_ylabel("residual, sigma")
    a2.set_title("residual against its signature variable")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_report(directory, first, steps, final, summary_lines) -> Path:
    """Write PNGs and index.html; return the index path."""
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"{directory}: cannot create the report directory: {e.strerror}") from None
    plt = _pyplot()
    figures = []
    panels = [("as fitted", first)] + [(f"after adding {s.added}", s.after) for s in steps]
    _segments_figure(plt, directory / "residuals_per_segment.png", panels)
    figures.append(("residuals_per_segment.png", "RMS whitened residual per segment, before and "
                    "after each added effect (1 = the noise level)"))
    for cand in first.candidates[:3]:
        if cand.signature_rows is None:
            continue
        name = f"candidate_{cand.effect}.png"
        _candidate_figure(plt, directory / name, first, cand)
        figures.append((name, f"{cand.effect}: residuals against the change it would make, and "
                              f"against its signature variable"))
    items = "\n".join(f"<h3>{html.escape(cap)}</h3><img src='{html.escape(f)}' style='max-width:100%'>"
                      for f, cap in figures)
    text = "<br>".join(html.escape(line) for line in summary_lines)
    index = directory / "index.html"
    index.write_text(f"<!doctype html><html><head><meta charset='utf-8'><title>station diagnosis"
                     f"</title></head><body><h1>station diagnosis</h1><p>{text}</p>{items}"
                     f"</body></html>\n")
    return index
