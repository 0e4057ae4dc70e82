"""The calibration file written through libyaml's C emitter is byte for byte what the
pure-Python emitter writes (issue 27, item 1): fuzzed documents and a real calibration."""
import pytest
import yaml
from hypothesis import HealthCheck, given, settings, strategies as st

from station.io import calfile

pytestmark = pytest.mark.skipif(calfile._CDumper is None, reason="PyYAML without libyaml")


def pure_python(doc) -> str:
    return yaml.dump(doc, Dumper=calfile._Dumper, sort_keys=False, width=100, allow_unicode=True)


# every character, the astral planes and controls included: strings the C emitter would write
# differently must be sent to the pure-Python one, so the text is always the pure-Python text
TEXT = st.text(st.characters(max_codepoint=0x1FFFF, exclude_categories=("Cs",)), max_size=120)
WORDS = st.sampled_from(["µg", "°/h", "a: b", "- x", "'q'", "x #y", " lead", "trail ", "yes", "1e3",
                         "a\nb", "a\n\nb ", "\n", "", "\x85", "\u2028", "\ufeff", "\U0001F600",
                         "x" * 150, ("word " * 40).strip()])
LEAF = st.one_of(TEXT, WORDS, st.floats(), st.integers(), st.booleans(), st.none())
TREE = st.recursive(LEAF, lambda c: st.one_of(st.lists(c, max_size=4),
                                              st.dictionaries(st.one_of(TEXT, WORDS), c, max_size=4)),
                    max_leaves=20)


@settings(max_examples=400, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.dictionaries(st.one_of(TEXT, WORDS), TREE, min_size=1, max_size=4))
def test_the_file_text_is_the_pure_python_emitters(doc):
    assert calfile.dump_text(doc) == pure_python(doc)


@settings(max_examples=300, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.dictionaries(st.text(st.characters(min_codepoint=0x20, max_codepoint=0xFFFD, exclude_categories=("Cs", "Cc")),
                               min_size=1, max_size=60),
                       st.text(st.characters(min_codepoint=0x20, max_codepoint=0xFFFD, exclude_categories=("Cs", "Cc")),
                               min_size=1, max_size=200), min_size=1, max_size=6))
def test_plain_text_documents_take_the_c_emitter_and_agree(doc):
    if calfile._c_safe(doc):        # what the C emitter is given must agree with the pure-Python one
        assert yaml.dump(doc, Dumper=calfile._CDumper, sort_keys=False, width=100,
                         allow_unicode=True) == pure_python(doc)


def test_a_real_calibration_is_written_by_the_c_emitter_with_the_same_bytes(optimal9_run):
    text = (optimal9_run / "calibration.yaml").read_text(encoding="utf-8")
    doc = yaml.safe_load(text)
    assert calfile._c_safe(doc)             # a calibration's own strings take the fast path
    assert calfile.dump_text(doc) == pure_python(doc) == text
    doc["provenance"]["note"] = "a path with an astral character \U0001F600 and a \x85"
    assert not calfile._c_safe(doc)
    assert calfile.dump_text(doc) == pure_python(doc)
