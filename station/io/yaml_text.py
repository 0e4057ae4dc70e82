"""YAML documents from outside, loaded safely and fast.

``safe_load(text)`` is ``yaml.safe_load``'s result and behaviour, through libyaml (PyYAML's C
loader: 5-8 times faster on a manifest or a calibration file) when PyYAML has it and the text
is one libyaml can take safely, through the pure-Python loader otherwise:
- any failure of the C loader is parsed again by the pure-Python one, so that errors carry the
  same message and line as before (and a text only one of the two accepts is judged by the
  pure-Python loader when the C loader refuses it);
- the C loader composes nodes recursively without a depth limit: a text whose nesting could be
  deep (brackets, braces, dashes, colons, question marks and lines counted together exceed
  MAX_C_DEPTH) goes to the pure-Python loader, whose recursion limit ends in a RecursionError,
  not in a crash of the interpreter (a 100,000-deep ``[[[...]]]`` segfaults the C loader);
- a text with a tab, a tag (``!``) or a block scalar (``|``, ``>``) goes to the pure-Python loader: the
  two differ on some malformed ones (``!`` alone is None for one and '' for the other, ``|#`` an
  error for one and '' for the other, ``0<TAB>`` too: found by tests/test_yaml_text.py's fuzzing); station's
  files need neither;
- ``allow_aliases=False`` refuses ``*alias`` nodes (the "billion laughs"): a text with a ``*``
  goes to the pure-Python loader, which names the alias's line.

Both loaders construct the same Python objects (yaml.SafeConstructor).
"""
from __future__ import annotations

import yaml

MAX_C_DEPTH = 5000      # the C loader took 10,000 levels here; its recursion has no limit of its own
_C_LOADER = getattr(yaml, "CSafeLoader", None)


class NoAliasLoader(yaml.SafeLoader):
    """yaml.SafeLoader that refuses aliases (``*name``), naming the line of the first."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise yaml.MarkedYAMLError(problem="aliases (*name) are not allowed here",
                                       problem_mark=mark)
        return super().compose_node(parent, index)


def _c_safe(text: str | bytes, allow_aliases: bool) -> bool:
    marks = "\t!|>*[{-:?\n" if isinstance(text, str) else [bytes([c]) for c in b"\t!|>*[{-:?\n"]
    if _C_LOADER is None or any(m in text for m in marks[:4]) or (not allow_aliases and marks[4] in text):
        return False
    return sum(text.count(c) for c in marks[5:]) <= MAX_C_DEPTH


def safe_load(text: str | bytes, allow_aliases: bool = True):
    """The document in ``text`` (yaml.safe_load's result); yaml.YAMLError, ValueError or
    RecursionError as the pure-Python loader raises them."""
    if _c_safe(text, allow_aliases):
        try:
            return yaml.load(text, Loader=_C_LOADER)
        except Exception:               # noqa: BLE001 - judged again below, with the usual message
            pass
    return yaml.load(text, Loader=yaml.SafeLoader if allow_aliases else NoAliasLoader)
