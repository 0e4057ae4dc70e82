"""station.core.yaml_text: libyaml's speed with the pure-Python loader's results, errors and safety."""
import subprocess
import sys

import pytest
import yaml
from hypothesis import example, given, settings, strategies as st

from station.core import yaml_text

DOCS = [
    "a: 1\nb: [1, 2.5, -3e-4]\nc: {d: x, e: null}\n",
    "format: station-capture/1\nsegments:\n  - name: pos01\n    t0: 2026-11-23T10:00:00Z\n",
    "- - - 1\n",
    "\ufeffkey: value\n",
    "x: &a [1, 2]\ny: *a\n",
]


@pytest.mark.parametrize("text", DOCS)
def test_same_document_as_safe_load(text):
    assert yaml_text.safe_load(text) == yaml.safe_load(text)
    assert yaml_text.safe_load(text.encode("utf-8")) == yaml.safe_load(text.encode("utf-8"))


@pytest.mark.parametrize("text", ["a: [1, 2\n", "a: 1\n b: 2\n", "a: !!python/object:os.system x\n",
                                  "t: 2026-13-01\n", "\tkey: 1\n"])
def test_same_error_as_safe_load(text):
    with pytest.raises(Exception) as expected:
        yaml.safe_load(text)
    with pytest.raises(type(expected.value)) as got:
        yaml_text.safe_load(text)
    assert str(got.value) == str(expected.value)


def test_aliases_refused_with_their_line():
    with pytest.raises(yaml.MarkedYAMLError) as e:
        yaml_text.safe_load("x: &a [1]\ny: 2\nz: *a\n", allow_aliases=False)
    assert "aliases" in e.value.problem and e.value.problem_mark.line == 2


def test_deep_nesting_is_an_error_not_a_crash():
    """The C loader segfaults on 100,000 nested brackets: such text never reaches it; and the
    pure-Python loader's refusal is TooDeep (a yaml.YAMLError naming the line), not a RecursionError."""
    code = ("import sys; from station.core import yaml_text\n"
            "try:\n    yaml_text.safe_load('[' * 100000 + ']' * 100000)\n"
            "except yaml_text.TooDeep as e:\n    print('refused', e.problem_mark.line)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and run.stdout.strip() == "refused 0", run.stderr[-500:]


@pytest.mark.parametrize("text", ["[" * 101 + "]" * 101, "a:\n" + "".join(" " * i + "-\n" for i in range(1, 120)),
                                  "x: " + "{a: " * 150 + "1" + "}" * 150 + "\n"])
def test_nesting_deeper_than_the_limit_is_refused_by_both_loaders(text):
    for allow_aliases in (True, False):
        with pytest.raises(yaml_text.TooDeep) as e:
            yaml_text.safe_load(text, allow_aliases)
        assert f"deeper than {yaml_text.MAX_DEPTH}" in e.value.problem
    assert yaml_text.safe_load("[" * 100 + "]" * 100) is not None       # the limit itself: read


def test_the_c_loader_is_used_when_present():
    if yaml_text._C_LOADER is None:
        pytest.skip("PyYAML without libyaml")
    assert yaml_text._c_safe(DOCS[1], True) is yaml_text._CLoader
    assert yaml_text._c_safe("[" * 6000, True) is yaml_text._EventLoader     # its composer in Python
    assert yaml_text._c_safe(DOCS[4], False) is None


@settings(max_examples=1500, deadline=None)
@given(st.text(alphabet="ab:-[]{},\n #&*!'\"0123456789.?|>%@`\t\\eE+_~", max_size=80))
@example("{0?}")            # found here: a plain scalar for libyaml, an error for PyYAML
def test_fuzz_same_outcome_as_safe_load(text):
    try:
        expected = ("ok", yaml.safe_load(text))
    except Exception as e:  # noqa: BLE001
        expected = ("error", type(e).__name__)
    try:
        got = ("ok", yaml_text.safe_load(text))
    except Exception as e:  # noqa: BLE001
        got = ("error", type(e).__name__)
    assert got == expected


def test_a_large_manifest_is_read_by_libyaml_and_deep_nesting_never_is():
    """A manifest of more segments than MAX_C_DEPTH (every segment a mapping with a flow
    sequence: more brackets than MAX_C_DEPTH, nested two deep) goes to the C loader itself (not
    _EventLoader), with safe_load's result; texts nested deeper than MAX_C_DEPTH never do,
    whatever hides their closing brackets (quotes, comments, stray closers before them) or
    however they nest (flow, block indentation, compact forms).  (6,000 segments: 1.2 times
    MAX_C_DEPTH's brackets, as a bound that counted the brackets would refuse; 20,000 before the
    twenty-first session, 2.6 s of CPU against 0.7; the check was only that some libyaml loader
    took it, which _EventLoader passed too.)"""
    if yaml_text._C_LOADER is None:
        pytest.skip("PyYAML without libyaml")
    n = int(1.2 * yaml_text.MAX_C_DEPTH)
    doc = {"format": "station-capture/1",
           "segments": [{"name": f"s{i:05d}", "kind": "static", "file": f"s{i:05d}.csv",
                         "status": "complete", "up_body": [0.0, 0.0, 1.0]} for i in range(n)]}
    text = yaml.dump(doc, Dumper=yaml.CSafeDumper, sort_keys=False, default_flow_style=None)   # libyaml's emitter: 20x the pure-Python one
    assert text.count("[") > yaml_text.MAX_C_DEPTH
    assert yaml_text._c_safe(text, True) is yaml_text._CLoader and yaml_text.safe_load(text) == doc
    deep = yaml_text.MAX_C_DEPTH + 10
    for nested in ("[" * deep + "]" * deep,
                   '[ "]" ' * deep,                                        # quoted closers
                   "".join("[ # ]\n" for _ in range(deep)),               # commented-out closers
                   "a: " + "]" * deep + "\nb: " + "[" * deep + "]" * deep,  # stray closers first
                   "".join(" " * k + f"k{k}:\n" for k in range(deep)),     # block, by indentation
                   "- " * deep + "x\n"):                                  # block, compact
        assert yaml_text.nesting_bound(nested) > yaml_text.MAX_C_DEPTH
        assert yaml_text._c_safe(nested, True) is not yaml_text._CLoader


def test_a_100000_segment_manifest_is_read_by_libyaml_in_linear_time():
    """A station manifest has one bracket per segment and a quoted time stamp (``started_utc:
    '2026-...'``): the quote makes nesting_bound count every bracket, so above ~5,000 segments
    such a manifest went to the pure-Python loader (8,000 segments: 5 s, 4 times the C loader).
    It now takes libyaml's parser with the depth counted in Python (_EventLoader), with
    safe_load's result, on 1,000 and 4,000 segments alike."""
    if yaml_text._C_LOADER is None:
        pytest.skip("PyYAML without libyaml")
    for n in (1_000, 4_000):
        doc = {"format": "station-capture/1",
               "segments": [{"name": f"s{i:06d}", "kind": "static", "file": f"s{i:06d}.csv",
                             "status": "complete", "up_body": [0.0, 0.1, 1.0],
                             "started_utc": "2026-11-27T14:00:00+00:00"} for i in range(n)]}
        text = yaml.dump(doc, Dumper=yaml.CSafeDumper, sort_keys=False, default_flow_style=None)   # libyaml's emitter: 20x the pure-Python one
        assert "'2026-11-27T14:00:00+00:00'" in text
        loader = yaml_text._c_safe(text, True)
        assert loader is (yaml_text._CLoader if n < yaml_text.MAX_C_DEPTH else yaml_text._EventLoader)
        assert yaml.load(text, Loader=yaml_text._EventLoader) == doc == yaml_text.safe_load(text)


def test_deep_nesting_that_hides_its_closers_is_an_error_not_a_crash():
    """100,000 brackets whose closers are quoted reach libyaml's parser (_EventLoader), never
    its recursive composer: refused with TooDeep at the 101st level's line, like the
    pure-Python loader."""
    code = ("from station.core import yaml_text\n"
            "text = '[ \"]\",\\n' * 100000\n"
            "assert yaml_text._c_safe(text, True) is yaml_text._EventLoader\n"
            "try:\n    yaml_text.safe_load(text)\n"
            "except yaml_text.TooDeep as e:\n    print('refused', e.problem_mark.line)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and run.stdout.strip() == f"refused {yaml_text.MAX_DEPTH}", run.stderr[-500:]


@settings(max_examples=1500, deadline=None)
@given(st.text(alphabet="ab:-[]{},\n #&*!'\"0123456789.?|>%@`\t\\eE+_~", max_size=80))
@example("{0?}")
@example("[[[[1]]]]")
def test_fuzz_the_event_loader_same_outcome_as_safe_load(text):
    """Every text the libyaml loaders may take, through _EventLoader: safe_load's outcome."""
    if yaml_text._c_safe(text, True) is None:
        return
    try:
        expected = ("ok", yaml.safe_load(text))
    except Exception as e:  # noqa: BLE001
        expected = ("error", type(e).__name__)
    try:
        got = ("ok", yaml.load(text, Loader=yaml_text._EventLoader))
    except yaml_text.TooDeep:
        got = ("error", "TooDeep")
    except Exception:  # noqa: BLE001 - safe_load judges these again with the pure-Python loader
        got = expected if expected[0] == "error" else ("error", "event loader")
    assert got == expected


@pytest.mark.parametrize("brk", ["\n\r", "\r", "\n\x85", "\u2028", "\u2029"])
def test_every_kind_of_line_break_counts_for_the_nesting_bound(brk):
    """YAML breaks lines at CR, NEL, LS and PS too: indentation after any of them counts (found
    by a review: lines joined by "\\n\\r" measured no indentation, and libyaml crashed on them)."""
    lines = [" " * (40 * j) + "- " * 30 for j in range(40)]
    text = brk.join(lines) + "x"
    assert yaml_text.nesting_bound(text) >= 40 * 39


def test_an_integer_beyond_every_float_is_read_as_infinity_by_every_loader():
    """(thirteenth session) so that the readers' finite checks refuse it in one line instead of
    raising OverflowError; integers a float holds are read as before, exactly."""
    big = "1" + "0" * 400
    for text in (f"a: {big}", f"a: {big}  # a comment", f"a: [{big}, 1]\n#'", f"a: {big}\n\tb: 1"):
        for aliases in (True, False):
            doc = yaml_text.safe_load(text, allow_aliases=aliases) if "\t" not in text else None
            if doc is not None:
                assert doc["a"] in (float("inf"), [float("inf"), 1]), (text, doc)
    assert yaml_text.safe_load(f"a: -{big}") == {"a": float("-inf")}
    assert yaml_text.safe_load("a: 17976931348623157" + "0" * 292) == {"a": 17976931348623157 * 10 ** 292}   # <= max
    assert yaml_text.safe_load(f"a: '{big}'") == {"a": big}
