"""YAML documents from outside, loaded safely and fast.

``safe_load(text)`` is ``yaml.safe_load``'s result and behaviour, through libyaml (PyYAML's C
loader: 5-8 times faster on a manifest or a calibration file) when PyYAML has it and the text
is one libyaml can take safely, through the pure-Python loader otherwise:
- any failure of the C loader is parsed again by the pure-Python one, so that errors carry the
  same message and line as before (and a text only one of the two accepts is judged by the
  pure-Python loader when the C loader refuses it);
- the C loader composes nodes recursively without a depth limit: a text whose nesting could be
  deep (``nesting_bound`` above MAX_C_DEPTH) goes to the pure-Python loader, whose recursion
  limit ends in a RecursionError, not in a crash of the interpreter (a 100,000-deep
  ``[[[...]]]`` segfaults the C loader).  The bound is the flow collections' depth (brackets
  and braces open at once; every one in the text when a quote or a comment could hide a
  closing one) plus the block collections' (a block level is indented further than its parent,
  but for a sequence that is a mapping's value and the compact ``- - x`` / ``? x`` / ``a: b``
  forms on one line: twice the indentation plus the dashes, question marks and colons of the
  line, at most over the lines).  A text whose bound is above MAX_C_DEPTH (a quote or a
  comment makes every bracket count: a station manifest has one bracket per segment and quoted
  time stamps, so every manifest above ~5,000 segments) takes ``_EventLoader``: libyaml's
  scanner and parser, which keep their stacks on the heap and cannot crash on depth, with
  PyYAML's own composer counting the depth (TooDeep at the same event as the pure-Python
  loader) and its safe constructor: no heuristic, linear in the text (~85 µs of CPU a segment
  from 3,000 to 30,000 segments, the garbage collector paused: ``gc_paused``), where the
  pure-Python loader took 5 s for 8,000 segments and grew faster;
- a text with a tab, a tag (``!``) or a block scalar (``|``, ``>``) goes to the pure-Python loader: the
  two differ on some malformed ones (``!`` alone is None for one and '' for the other, ``|#`` an
  error for one and '' for the other, ``0<TAB>`` too: found by tests/test_yaml_text.py's fuzzing); station's
  files need neither; nor does a text with a ``?`` and a flow collection (``{0?}``: the plain
  scalar ``0?`` for libyaml, an error for PyYAML, where ``?`` ends a plain scalar in a flow);
- ``allow_aliases=False`` refuses ``*alias`` nodes (the "billion laughs"): a text with a ``*``
  goes to the pure-Python loader, which names the alias's line.

Both loaders construct the same Python objects (yaml.SafeConstructor).

Depth: a document nested deeper than MAX_DEPTH collections is refused with ``TooDeep`` (a
yaml.MarkedYAMLError naming the line), by either loader, before anything is constructed; it was
a RecursionError traceback in every input read through PyYAML (issue 26).  ``load_text`` turns
a loader's failure into one UserError line naming the source (file) and the line.
"""
from __future__ import annotations

import gc
import re
from contextlib import contextmanager

import yaml

MAX_DEPTH = 100        # collections nested in one another: station's files use fewer than 10
MAX_C_DEPTH = 5000      # the C loader took 10,000 levels here; its recursion has no limit of its own
_C_LOADER = getattr(yaml, "CSafeLoader", None)


class TooDeep(yaml.MarkedYAMLError):
    """A document nested deeper than MAX_DEPTH collections."""

    def __init__(self, mark):
        super().__init__(problem=f"nested deeper than {MAX_DEPTH} levels", problem_mark=mark)


class DepthLimitedLoader(yaml.SafeLoader):
    """yaml.SafeLoader that refuses a document nested deeper than MAX_DEPTH (TooDeep)."""

    _depth = 0

    def compose_node(self, parent, index):
        if self._depth >= MAX_DEPTH and not self.check_event(yaml.AliasEvent, yaml.ScalarEvent):
            raise TooDeep(self.peek_event().start_mark)
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


class NoAliasLoader(DepthLimitedLoader):
    """DepthLimitedLoader that refuses aliases (``*name``), naming the line of the first."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise yaml.MarkedYAMLError(problem="aliases (*name) are not allowed here",
                                       problem_mark=mark)
        return super().compose_node(parent, index)


def check_depth(node) -> None:
    """TooDeep when the node tree (as composed: an alias is not followed) is deeper than MAX_DEPTH."""
    seen = set()
    stack = [(node, 1)]
    while stack:
        node, depth = stack.pop()
        if id(node) in seen or not isinstance(node, yaml.CollectionNode):
            continue
        seen.add(id(node))
        if depth > MAX_DEPTH:
            raise TooDeep(node.start_mark)
        children = node.value if isinstance(node, yaml.SequenceNode) else [n for kv in node.value for n in kv]
        stack.extend((child, depth + 1) for child in reversed(children))


if _C_LOADER is not None:
    class _CLoader(_C_LOADER):
        """libyaml's loader, with the depth checked on the composed nodes (before constructing)."""

        def get_single_data(self):
            node = self.get_single_node()
            if node is None:
                return None
            check_depth(node)
            return self.construct_document(node)


if _C_LOADER is not None:
    from yaml.composer import Composer
    from yaml.constructor import SafeConstructor
    from yaml.cyaml import CParser
    from yaml.resolver import Resolver

    class _EventLoader(CParser, Composer, SafeConstructor, Resolver):
        """libyaml's scanner and parser (iterative: its stacks are on the heap, so no depth crashes
        them), PyYAML's composer with the depth limit (DepthLimitedLoader's: TooDeep at the same
        event) and PyYAML's safe constructor: for a text whose nesting cannot be bounded from its
        characters (a quote or a comment makes every bracket count; a station manifest has one
        bracket per segment and a quoted time stamp), no heuristic, linear in the text.  The
        nodes are PyYAML's composer's, so the objects are yaml.safe_load's."""

        _depth = 0
        get_single_node = Composer.get_single_node      # (not CParser's: its composer recurses in C)
        check_node = Composer.check_node
        get_node = Composer.get_node

        def __init__(self, stream):
            CParser.__init__(self, stream)
            Composer.__init__(self)
            SafeConstructor.__init__(self)
            Resolver.__init__(self)

        def compose_node(self, parent, index):
            if self._depth >= MAX_DEPTH and not self.check_event(yaml.AliasEvent, yaml.ScalarEvent):
                raise TooDeep(self.peek_event().start_mark)
            self._depth += 1
            try:
                return Composer.compose_node(self, parent, index)
            finally:
                self._depth -= 1


def _construct_int(loader, node):
    """An integer as yaml.safe_load reads it; one beyond every float (|n| > 1.8e308: 309 digits
    or more) is read as +-inf.  Every number station reads from a file is used as a float, and
    its checks ask for a finite one: such an integer then gets the one-line refusal ("must be a
    finite number") instead of ``OverflowError: int too large to convert to float`` from the
    first ``math.isfinite`` or ``float()`` (found by tests/test_fuzz_consumers.py in a
    calibration's sigma and a manifest's gravity_mps2, thirteenth session)."""
    value = yaml.constructor.SafeConstructor.construct_yaml_int(loader, node)
    if -_FLOAT_MAX <= value <= _FLOAT_MAX:
        return value
    return float("inf") if value > 0 else float("-inf")


_FLOAT_MAX = 1.7976931348623157e308
for _loader in (DepthLimitedLoader, NoAliasLoader, *((_CLoader, _EventLoader) if _C_LOADER is not None else ())):
    _loader.add_constructor("tag:yaml.org,2002:int", _construct_int)


def _c_safe(text: str | bytes, allow_aliases: bool):
    """The libyaml loader ``text`` may take (module doc): _CLoader (its composer in C) when the
    text's nesting is bounded below MAX_C_DEPTH, _EventLoader (its parser in C, the composer in
    Python, the depth counted) when it is not; None: the pure-Python loader."""
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:      # (libyaml reads UTF-16 too): judged by the pure-Python loader
            return None
    if _C_LOADER is None or any(m in text for m in "\t!|>") or (not allow_aliases and "*" in text):
        return None
    if "?" in text and ("[" in text or "{" in text):      # "{0?}": a plain scalar "0?" for libyaml,
        return None                                       # an error for PyYAML ("?" ends it in a flow)
    return _CLoader if nesting_bound(text) <= MAX_C_DEPTH else _EventLoader


_FLOW = re.compile(r"[\[\]{}]")
_INDENT = re.compile(r"^ *", re.MULTILINE)


_BREAKS = re.compile("\r\n?|[\x85\u2028\u2029]")


def nesting_bound(text: str) -> int:
    """An upper bound of the depth of the YAML node tree in ``text`` (module doc).  Lines are
    YAML's: broken at CR, LF, CRLF, NEL, LS and PS alike (counted at LF only, a text joined by
    "\\n\\r" was measured with no indentation: found by a review, a crash of libyaml)."""
    text = _BREAKS.sub("\n", text)
    if any(c in text for c in "\"'#"):           # a closing bracket could be quoted or commented out
        flow = text.count("[") + text.count("{")
    else:                   # brackets are structure (a stray closer outside a collection: ignored)
        flow = depth = 0
        for m in _FLOW.finditer(text):
            depth = depth + 1 if m.group() in "[{" else max(0, depth - 1)
            flow = max(flow, depth)
    indent = max(map(len, _INDENT.findall(text)), default=0)
    marks = max((line.count("-") + line.count("?") + line.count(":") for line in text.split("\n")), default=0)
    return flow + 2 * (indent + 1) + marks      # (the largest of each: a bound of their sum per line)


@contextmanager
def gc_paused():
    """Python's cyclic garbage collector off for the block (and back on after it if it was on).
    A loader allocates a node and an object for every scalar, none of them in a cycle; the
    collector, run every 700 allocations over a heap that grows with the document, took two
    thirds of a large manifest's load and made it grow faster than the text (10,000 segments:
    250 us a segment with it, 80 without; 30,000: 270 against 86)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def safe_load(text: str | bytes, allow_aliases: bool = True):
    """The document in ``text`` (yaml.safe_load's result); yaml.YAMLError or ValueError as the
    pure-Python loader raises them, TooDeep (a yaml.YAMLError) for a document nested deeper
    than MAX_DEPTH."""
    loader = _c_safe(text, allow_aliases)
    if loader is not None:
        try:
            with gc_paused():
                return yaml.load(text, Loader=loader)
        except TooDeep:
            raise
        except Exception:               # noqa: BLE001 - judged again below, with the usual message
            pass
    try:
        with gc_paused():
            return yaml.load(text, Loader=DepthLimitedLoader if allow_aliases else NoAliasLoader)
    except RecursionError:                              # (not expected below MAX_DEPTH): one line too
        raise TooDeep(None) from None


def load_text(text: str | bytes, source, *, allow_aliases: bool = True):
    """safe_load(text); UserError, one line naming ``source`` and the line, when it is not valid YAML."""
    from station.core.errors import UserError

    try:
        return safe_load(text, allow_aliases)
    except (yaml.YAMLError, ValueError) as e:       # ValueError: a timestamp in month 13
        raise UserError(f"{source}: not valid YAML: {error_line(e)}") from None


def error_line(e: Exception) -> str:
    """A YAML error (or a loader's ValueError) in one line: its problem and line."""
    mark = getattr(e, "problem_mark", None)
    problem = getattr(e, "problem", None)
    if problem is None:
        return " ".join(str(e).split())[:200] or type(e).__name__
    if mark is not None and f"line {mark.line + 1}" not in problem:
        problem = f"line {mark.line + 1}: {problem}"
    return " ".join(problem.split())
