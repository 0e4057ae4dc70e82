"""A diagnosis as JSON (the schema of docs/diagnose.md): what ``station diagnose --json`` prints
and ``station batch diagnose`` writes per capture."""
from __future__ import annotations

import math


def _num(v):
    return None if v is None or (isinstance(v, float) and not math.isfinite(v)) else v


def to_json(d, steps) -> dict:
    return {
        "chi2": d.chi2, "dof": d.dof, "reduced_chi2": d.reduced_chi2, "p_value": _num(d.p_value),
        "verdict": d.verdict,
        "effects": d.effects,
        "failures": d.failures,
        # a fit that still fails: what was tried, what each explained, what the residuals follow
        "failure_account": list(getattr(d, "account", None) or []),
        "notes": d.notes,
        # the model's parameters the capture left not revealed, with the station design --from command
        "design_suggestions": list(getattr(d, "design_suggestions", None) or []),
        # effects outside the library this capture could not detect at their typical size (unrevealed.py)
        "not_revealed": list(getattr(d, "not_revealed", None) or []),
        # what the scan before the fit found and left out (station/estimate/data_faults.py)
        "data_faults": getattr(getattr(getattr(d.result, "model", None), "s", None), "data_faults", None),
        "terms_outside_library": None if d.proposal is None else {
            "terms": [{"sensor": t.sensor, "axis": "xyz"[t.axis], "regressor": t.regressor.text,
                       "parameter": t.name, "unit": t.unit, "value": v, "sigma": sg, "words": t.words(v, sg)}
                      for t, v, sg in zip(d.proposal.effect.terms, d.proposal.values, d.proposal.sigmas)],
            "chi2_after": d.proposal.chi2_after, "reduced_chi2_after": d.proposal.reduced_after,
            "holdout_before": d.proposal.holdout_before, "holdout_after": d.proposal.holdout_after,
            "kept": d.proposal.kept, "reason": d.proposal.reason,
            "redundant": [{"effect": e, "reason": why} for e, why in d.proposal.redundant]},
        "rejected": [{"effect": r.effect, "reason": r.reason, "actual_chi2_drop": r.actual_drop,
                      "holdout_before": r.holdout_before, "holdout_after": r.holdout_after,
                      "share_of_excess": _num(r.share)} for r in d.rejected],
        "segments": [{"name": s.name, "kind": s.kind, "rms": s.rms, "rms_by_quantity": s.by_quantity}
                     for s in d.segments],
        "candidates": [{
            "effect": c.effect, "significant": c.significant,
            "predicted_chi2_drop": c.predicted_chi2_drop, "dof": c.dof,
            "p_value": c.p_value, "p_value_corrected": c.p_value_corrected, "plausible": c.plausible,
            "parameters": c.names, "units": c.units, "estimate": c.estimate, "sigma": c.sigma,
            "smallest_detectable": [_num(v) for v in c.detectable], "aliased": c.aliased,
            "advice": c.advice, "source": c.source, "overdispersion": c.overdispersion,
            "design_command": getattr(c, "suggestion", "") or None,
            "separate_commands": list(getattr(c, "separations", None) or []),
            "alike": list(getattr(c, "alike", None) or [])}
            for c in d.candidates],
        "steps": [{"added": st.added, "discovered": st.discovered, "instead_of": st.instead_of or None,
                   "predicted_chi2_drop": st.predicted_drop,
                   "actual_chi2_drop": st.actual_drop, "chi2_before": st.before.chi2,
                   "chi2_after": st.after.chi2, "reduced_chi2_after": st.after.reduced_chi2,
                   "holdout_before": st.holdout_before, "holdout_after": st.holdout_after,
                   "share_of_excess": _num(st.share), "caveats": st.caveats,
                   "separate_commands": list(getattr(st, "separations", None) or []),
                   "removed": [{"effect": e, "reason": why} for e, why in st.removed],
                   "estimate": [{"name": n, "value": v, "sigma": sg, "unit": u,
                                 # held by its prior (the capture does not reveal it): not written
                                 "not_revealed": n in set(getattr(st, "not_revealed", None) or ())}
                                for n, v, sg, u in st.estimate]} for st in steps],
    }
