"""The diagnosis of a capture, once: the first fit, --auto's steps, the final verdict and what
diagnose says beside its findings.  ``station diagnose`` (station.api.diagnose and the CLI's
``--report`` path), ``station report`` (station.diagnose.report) and ``station batch diagnose``
all call :func:`run`, so that they cannot disagree on a verdict, an account or a suggestion."""
from __future__ import annotations

from typing import NamedTuple


class Diagnosed(NamedTuple):
    """(first, steps, final, summaries): the diagnosis of the model as fitted, --auto's steps
    (station.diagnose.auto.Step, empty without it), the diagnosis of the model it ends with (the
    first without --auto) and the capture's summaries (station.estimate.lsq.summarise)."""
    first: object
    steps: list
    final: object
    summaries: object


def run(capture, effects=(), *, registry=None, auto: bool = False, on_first=None,
        suggestions: bool = True) -> Diagnosed:
    """Diagnose ``capture`` (a Capture whose segments are summarised or can be) with the effect
    ids ``effects`` from ``registry`` (default: the library's).  ``auto``: add the most
    significant candidate that passes the checks, refit, repeat (station.diagnose.auto.run,
    which ends with auto.conclude); without it the model is fitted once (the discrete effects'
    parameters located, station.estimate.profile.fit_located, as --auto's first fit) and
    concluded the same way (auto.conclude: the account of a fit that still fails).
    ``on_first(diagnosis)``: called with the first diagnosis as soon as it is known (a page
    draws its candidates' figures meanwhile).  ``suggestions``: what the capture cannot reveal,
    with the design --from commands (station.diagnose.suggest.suggest_all)."""
    from station.diagnose import auto as auto_loop
    from station.diagnose.core import diagnose
    from station.estimate import lsq
    from station.model.registry import EffectRegistry

    registry = registry if registry is not None else EffectRegistry()
    s = lsq.summarise(capture)
    if auto:
        steps, final = auto_loop.run(s, list(effects), progress=None, registry=registry, on_first=on_first)
        first = steps[0].before if steps else final
    else:
        from station.estimate.profile import fit_located

        steps, first = [], diagnose(fit_located(s, [registry.create(e) for e in effects]), registry=registry)
        if on_first is not None:
            on_first(first)
        auto_loop.conclude(first, s)
        final = first
    if suggestions:
        from station.diagnose.suggest import suggest_all

        suggest_all(first, final, steps, capture, s, registry)
    return Diagnosed(first, steps, final, s)
