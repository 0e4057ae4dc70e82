"""What diagnose says beside an alias or a parameter not revealed: the exact `station design
--from` command that proposes the fewest extra segments revealing it (station/design/
sequential.py, docs/design.md "Sequential design")."""
from __future__ import annotations

import shlex

BASE = ("base_triads", "inter_triad")


def command(capture, effects, reveal) -> str:
    """station design --from CAPTURE --add E ... --reveal P1,P2,... -o extension.yaml"""
    adds = "".join(f" --add {shlex.quote(e)}" for e in effects)
    return (f"station design --from {shlex.quote(str(capture))}{adds} --reveal {','.join(reveal)} "
            "-o extension.yaml")


def suggest(diagnosis, capture) -> None:
    """Set ``suggestion`` on every candidate the capture cannot reveal (no parameter it can
    size, or parameters aliased with the model's) and ``design_suggestions`` on the diagnosis
    for the model's own parameters it left not revealed (held by their priors)."""
    model_effects = [e for e in diagnosis.effects if e not in BASE and e != "discovered_terms"]
    for c in diagnosis.candidates:
        blind = list(c.aliased) if c.dof else list(c.names)
        if blind and c.names and not c.advice.startswith("cannot be tested"):
            c.suggestion = command(capture, model_effects + [c.effect], blind)
    lines = []
    hidden = list(getattr(diagnosis.result.model, "unobservable", None) or [])
    if hidden:
        lines.append(f"not revealed by this capture: {', '.join(hidden)}; the fewest segments that reveal them: "
                     f"{command(capture, model_effects, hidden)}")
    diagnosis.design_suggestions = lines
