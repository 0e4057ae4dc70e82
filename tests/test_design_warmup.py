"""Issue 28 (sixteenth session), item 3: the designer's time model counts a configured warm-up
(station.yaml ``warmup:``) as the compiler does -- the budget holds the warm-up and the segments,
the written scheme's compiled plan (station plan's total) includes the warm-up step and stays
within the budget, and the segments get the budget less the warm-up."""
from dataclasses import replace

import pytest

from station.bench.compile import compile_scheme
from station.bench.config import WarmupConfig, load_config
from station.bench.plan import WarmUp
from station.design import designer
from station.design.noise import Noise

BUDGET_S = 700.0
WARMUP_S = 300.0


def _design(config):
    return designer.design(config, [], Noise(), BUDGET_S, "D", rates_dps=(100.0,), revolutions=(1,),
                           dwells_s=(10.0, 30.0), max_passes=1, compare=(), verify_runs=0, statics="unknown")


def test_a_configured_warm_up_is_paid_for_within_the_budget():
    plain = load_config(None, env={})
    warm = replace(plain, warmup=WarmupConfig(duration_s=WARMUP_S))
    d = _design(warm)
    plan = compile_scheme(d.scheme, warm)
    steps = [s for s in plan.steps if isinstance(s, WarmUp)]
    assert len(steps) == 1 and steps[0].estimate_s == pytest.approx(WARMUP_S)
    assert d.duration_s == pytest.approx(plan.duration_s) and d.duration_s <= BUDGET_S
    # and it is said that every scheme is predicted as recorded after it (seventeenth session)
    assert any(n.startswith("warm-up") and f"powered on {WARMUP_S:.0f} s before the first segment" in n
               for n in d.notes), d.notes
    # the segments had the budget less the warm-up: the same design without the warm-up in the
    # configuration fills more of the same budget with segments
    segments_s = plan.duration_s - WARMUP_S
    assert segments_s <= BUDGET_S - WARMUP_S
    free = _design(plain)
    assert compile_scheme(free.scheme, plain).duration_s > segments_s
