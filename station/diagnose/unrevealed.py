"""What the capture cannot reveal of the effects a warm-up scheme is blind to, said in words
with the `station design --from` command that would reveal them (issue 25's loop, issue 28's
design link).

A fit can pass while a real effect hides in it: a gyro scale that changes with the square of the
temperature, or with the specific force, or gyro axes that tilt with temperature, are invisible
to a scheme that turns each axis at one temperature range and in one attitude (optimal9 over an
8 degC warm-up: the fit passes, the held-out gyro error is 4-10x the clean floor).  The data can
say so honestly: for each such effect (station/model/unlisted.py) not in the model, the score
test at the final fit gives each parameter's 1-sigma from this capture (its Jacobian column
outside the fitted model, with the over-dispersion of a failing fit); a parameter whose 1-sigma
times the detection threshold (DETECT_Z) is above its typical size is not revealed: an effect of
typical size would go undetected.
This is a statement about the capture, not about the sensor: nothing is claimed present.  Where
the score test finds an effect significant, the data do show it and the term search names it.

Why, from the capture: the temperatures of the rotations that turn each gyro axis (an axis turned
at one temperature cannot show a change with temperature) and the mean specific force along the
rotation axis during them (an axis turned in one attitude cannot show a change with the force).
"""
from __future__ import annotations

import shlex
from dataclasses import dataclass

import numpy as np

from station.diagnose.core import ALPHA, POWER_Z, norm_isf, overdispersion, score_test
from station.model.raw_counts import in_capture_units
from station.model.temperature import SQUARED_IN_TEMPERATURE
from station.model.unlisted import UNLISTED

AX = "xyz"
# the size a capture detects (80 % power at the family's level): z of ALPHA over the two tails of
# the unlisted effects' 21 parameters (Bonferroni) plus POWER_Z, rank_candidates' "detectable";
# a parameter is not revealed when an effect of its typical size would go undetected.  With the
# estimator's rule alone (1-sigma above typical) a 20 arcsec/degC gyro tilt sized to +/-8 went
# unsaid and undetected, and its held-out gyro error was 6x the clean floor
DETECT_Z = norm_isf(ALPHA / (2 * sum(len(cls().params) for cls in UNLISTED.values()))) + POWER_Z
TURNS = 0.5          # a rotation turns a gyro axis when its axis is within 60 degrees of it
SPEC = "station.model.unlisted"


def _turning(summaries, i: int) -> list:
    return [r for r in summaries.rotations if abs(float(np.asarray(r.axis_body)[i])) >= TURNS]


def _why_temperature(summaries) -> str:
    """The temperature spans of the rotations that turn each axis, against the capture's."""
    temps = [x.temp_c for x in [*summaries.statics, *summaries.rotations] if x.temp_c is not None]
    if not temps:
        return "the capture has no temperature"
    spans = []
    for i in range(3):
        t = [r.temp_c for r in _turning(summaries, i) if r.temp_c is not None]
        spans.append(f"{AX[i]} {max(t) - min(t):.2g}" if t else f"{AX[i]} none")
    return (f"the rotations that turn each gyro axis span ({', '.join(spans)}) degC of the capture's "
            f"{max(temps) - min(temps):.2g} degC")


def _why_force(summaries) -> str:
    """The mean force along each axis during the rotations about it (g)."""
    g0 = summaries.gravity_mps2 or 9.80665
    parts = []
    for i in range(3):
        f = sorted({round(float(r.accel_dc[i]) * summaries.accel_factor / g0, 1) + 0.0 for r in _turning(summaries, i)})
        parts.append(f"{AX[i]} {', '.join(f'{v:+.1f}' for v in f) or 'none'}")
    return ("each gyro axis is turned with only these mean forces along it, in g: " + "; ".join(parts)
            + " (a change of scale with the force needs the same axis turned with two or more)")


def _why_statics(summaries) -> str:
    """The temperature spans of the statics that put each accelerometer axis near +-1 g."""
    spans = []
    for i in range(3):
        t = [st.temp_c for st in summaries.statics if st.temp_c is not None and st.up_body is not None
             and abs(float(np.asarray(st.up_body)[i])) >= TURNS * float(np.linalg.norm(st.up_body))]
        spans.append(f"{AX[i]} {max(t) - min(t):.2g}" if t else f"{AX[i]} none")
    return f"the statics with gravity along each accelerometer axis span ({', '.join(spans)}) degC"


WHY = {"gyro_scale_temperature_squared": _why_temperature, "gyro_misalignment_temperature": _why_temperature,
       "gyro_scale_force": _why_force, "accel_scale_temperature_squared": _why_statics}


def _term_keys(eid: str) -> dict:
    """Parameter -> (sensor, axis, regressor key) of the dictionary term that is the same physics
    (station/diagnose/terms.py): a parameter already in the model as a discovered term is not
    said again."""
    out = {}
    for i, a in enumerate(AX):
        if eid == "gyro_scale_temperature_squared":
            out[f"gyro_scale_tempco2_{a}"] = ("gyro", i, f"w{a}T2")
        elif eid == "accel_scale_temperature_squared":
            out[f"accel_scale_tempco2_{a}"] = ("accel", i, f"f{a}T2")
        for j, b in enumerate(AX):
            if eid == "gyro_misalignment_temperature" and j != i:
                out[f"gyro_misalignment_tempco_{a}{b}"] = ("gyro", i, f"w{b}T")
            elif eid == "gyro_scale_force":
                out[f"gyro_scale_force_{a}{b}"] = ("gyro", i, f"w{a}f{b}")
    return out


@dataclass
class Unrevealed:
    """An effect of station/model/unlisted.py this capture leaves not revealed."""
    text: str                 # in words: the parameters, their 1-sigma against their typical size, why
    spec: str                 # what --add takes: station.model.unlisted:CLASS
    reveal: str               # the --reveal pattern of its parameters
    sigmas: dict              # parameter -> its 1-sigma from this capture (reported unit)
    squared_in_temperature: bool = False    # needs each axis at three or more temperatures


# the budget printed in the chamber design's command (seconds of table time, its chamber steps
# included): an hour, the fifteenth session's two-setpoint designs (3432-3715 s); the user's own
# budget replaces it.  A number, so that the command runs as printed
CHAMBER_DESIGN_S = 3600.0


def after(u: Unrevealed, capture_path, design_command) -> str:
    """What follows the words: the `station design --from` command, or, for a change with the
    temperature's square, why segments added at this capture's temperatures cannot reveal it and
    what can (a chamber's setpoints in a new design: --from adds no chamber step, and its
    proposals were refused on the quick-start capture: 'no 12 segments ... reveal')."""
    if u.squared_in_temperature:
        return ("; segments added at this capture's temperatures cannot reveal it (each axis needs three or more "
                "temperatures); a run at several setpoints of a temperature chamber (chamber: in station.yaml) "
                f"would: station design --config station.yaml --add {u.spec} "
                f"--criterion 'worst:{u.reveal.strip(chr(39))}' --duration {CHAMBER_DESIGN_S:g} -o scheme.yaml")
    return f"; the segments that would reveal it: {design_command(capture_path, [u.spec], [u.reveal])}"


def find(diagnosis, summaries) -> list[Unrevealed]:
    """The effects of station/model/unlisted.py not in the model that this capture leaves not
    revealed (a parameter's 1-sigma above its typical size, or aliased) and does not find
    significant; each with why, from the capture."""
    result = diagnosis.result
    if not summaries.rotations or getattr(result, "model", None) is None:
        return []
    in_model = {e.id for e in result.model.effects}
    discovered = {(t.sensor, t.axis, t.regressor.key) for e in result.model.effects for t in getattr(e, "terms", ())}
    phi = overdispersion(result)
    out = []
    for eid, cls in UNLISTED.items():
        effect = in_capture_units(cls)()
        if eid in in_model or ("temperature" in effect.needs and not _has_temperature(summaries)):
            continue
        try:
            cand = score_test(result, effect, overdispersion=phi)
        except Exception:        # an effect with nothing to act on in this capture says nothing
            continue
        typical = {p.name: p.typical for p in effect.params}
        known = _term_keys(eid)
        blind = [(n, s, u) for n, s, u in zip(cand.names, cand.sigma, cand.units)
                 if (n in cand.aliased or not DETECT_Z * s <= typical[n]) and known.get(n) not in discovered]
        if not blind or cand.significant:
            continue
        unit = blind[0][2]
        sizes = ", ".join(f"{n.rsplit('_', 1)[1]} {'aliased' if n in cand.aliased else f'{s:.2g}'}"
                          for n, s, _ in blind)
        text = (f"not revealed by this capture: {cls.title[0].lower() + cls.title[1:]} (1-sigma {sizes} {unit}: "
                f"detected only above {DETECT_Z:.2g}x that, typical {typical[blind[0][0]]:g}): {WHY[eid](summaries)}")
        out.append(Unrevealed(text, f"{SPEC}:{cls.__name__}", shlex.quote(blind[0][0].rsplit("_", 1)[0] + "_*"),
                              {n: s for n, s, _ in blind}, eid in SQUARED_IN_TEMPERATURE))
    return out


def _has_temperature(summaries) -> bool:
    temps = [x.temp_c for x in [*summaries.statics, *summaries.rotations] if x.temp_c is not None]
    return len(temps) > 1 and max(temps) - min(temps) > 0.0
