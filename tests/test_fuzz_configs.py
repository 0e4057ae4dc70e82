"""Hypothesis fuzz of the station's own input files that a user or a capture from elsewhere
hands it, structure-aware (issue 26 item 5, goal): station.yaml (both the single ``imu:`` and the
several-IMU ``imus:`` forms) and scheme files.  Every field of a valid document, found by walking
it, is set to a value of another type or an absurd one (up to three at a time, and a field
deleted): parse_config and scheme_from_text either accept the document or raise UserError (the
one line the CLI prints, exit 2); never another exception, never a hang."""
import os

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from station.bench.config import EXAMPLE, parse_config
from station.core.errors import UserError
from station.io.scheme import builtin_names, scheme_text, scheme_from_text

from test_fuzz_readers import values

EXAMPLES = int(os.environ.get("STATION_FUZZ_EXAMPLES", "100"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))

CONFIG = yaml.safe_load(EXAMPLE)
SEVERAL = {**{k: v for k, v in CONFIG.items() if k != "imu"},
           "imus": [dict(CONFIG["imu"], port="/dev/ttyUSB0"),
                    dict(CONFIG["imu"], port="/dev/ttyUSB2", name="left", mounting=["-x", "-y", "+z"])]}
SCHEMES = [yaml.safe_load(scheme_text(name)[0]) for name in ("optimal9", "manual6", "sizeeffect", "screwdriver")
           if name in builtin_names()]


def paths(doc, prefix=(), depth=4):
    """Every key and list index of ``doc`` down to ``depth`` levels (the fields a mutation sets)."""
    out = []
    items = doc.items() if isinstance(doc, dict) else enumerate(doc) if isinstance(doc, list) else ()
    for key, value in items:
        out.append(prefix + (key,))
        if depth > 1:
            out += paths(value, prefix + (key,), depth - 1)
    return out


def mutated(doc, changes):
    doc = yaml.safe_load(yaml.safe_dump(doc))
    for path, value, delete in changes:
        target = doc
        try:
            for key in path[:-1]:
                target = target[key]
            if delete:
                del target[path[-1]]
            else:
                target[path[-1]] = value
        except (TypeError, KeyError, IndexError):
            pass
    return doc


def accepts_or_refuses(call):
    try:
        call()
    except UserError as e:
        assert "\n" not in str(e).strip() and len(str(e)) < 2000, str(e)
        return "refused"
    return "accepted"


def changes_of(doc):
    return st.lists(st.tuples(st.sampled_from(paths(doc)), values, st.booleans()), min_size=1, max_size=3)


@FUZZ
@given(data=st.data(), several=st.booleans())
def test_fuzzed_station_yaml(data, several):
    base = SEVERAL if several else CONFIG
    doc = mutated(base, data.draw(changes_of(base)))
    accepts_or_refuses(lambda: parse_config(doc, "station.yaml"))


@FUZZ
@given(data=st.data(), which=st.integers(0, len(SCHEMES) - 1))
def test_fuzzed_scheme_file(data, which):
    doc = mutated(SCHEMES[which], data.draw(changes_of(SCHEMES[which])))
    accepts_or_refuses(lambda: scheme_from_text(yaml.safe_dump(doc), "fuzzed.yaml"))


def test_the_valid_documents_are_accepted():
    """The fuzz starts from documents that parse (else it would test refusals only)."""
    assert accepts_or_refuses(lambda: parse_config(CONFIG, "station.yaml")) == "accepted"
    assert accepts_or_refuses(lambda: parse_config(SEVERAL, "station.yaml")) == "accepted"
    assert len(SCHEMES) >= 2
    for doc in SCHEMES:
        assert accepts_or_refuses(lambda: scheme_from_text(yaml.safe_dump(doc), "scheme.yaml")) == "accepted"
