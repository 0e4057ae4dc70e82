"""The property tests run the same examples on every machine (docs/testing.md, "Property tests"):
the hypothesis installed is the one pyproject's dev extra pins (a derandomised run's examples
depend on hypothesis' own code: CI's 6.170.17 found a case 6.155.2 never generated), and the
suite's default profile (tests/conftest.py) is derandomised with no example database, so that
neither a seed nor a database of earlier failures on one machine changes what runs."""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

import hypothesis
import pytest
from hypothesis import given, settings, strategies as st

ROOT = Path(__file__).resolve().parents[1]


def _pinned() -> str:
    dev = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]["dev"]
    pins = [re.fullmatch(r"hypothesis\s*==\s*([\w.]+)", d.strip()) for d in dev if d.strip().startswith("hypothesis")]
    assert len(pins) == 1 and pins[0], f"hypothesis is not pinned with == in the dev extra: {dev}"
    return pins[0].group(1)


def test_the_installed_hypothesis_is_the_pinned_one():
    assert hypothesis.__version__ == _pinned(), (
        f"hypothesis {hypothesis.__version__} installed, the dev extra pins {_pinned()}: "
        "pip install -e '.[dev]' (or change the pin on purpose, in pyproject.toml)")


@pytest.fixture
def default_profile(request):
    if request.config.getoption("hypothesis_profile", None) not in (None, "repeatable"):
        pytest.skip("another hypothesis profile was asked for (--hypothesis-profile)")


def test_the_default_profile_is_derandomised_without_a_database(default_profile):
    assert settings.default.derandomize is True
    assert settings.default.database is None


def test_two_runs_draw_the_same_examples(default_profile):
    """The same property run twice in this process draws the same examples (random runs would
    not: 60 draws of 64-bit integers and floats, a collision of two random runs is ~0)."""
    def draws() -> list:
        seen = []

        @settings(max_examples=60)            # the profile's derandomize and database, inherited
        @given(st.integers(), st.floats(allow_nan=False), st.text(max_size=8))
        def prop(i, f, t):
            seen.append((i, f, t))

        prop()
        return seen

    first, second = draws(), draws()
    assert len(first) >= 30 and first == second
