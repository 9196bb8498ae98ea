"""The outline of a Zenoh JSON5 config (vstig_hw.links.zenoh_files): every key's line, nesting bounded, without
recursion; held against Python's own JSON writer for the JSON part of JSON5."""

from __future__ import annotations

import json
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw.links.zenoh_files import MAX_DEPTH, TooDeep, outline


def test_json5_comments_quotes_and_arrays_are_read_as_json5() -> None:
    text = """// a lab's config
{
  mode: 'peer', /* a comment with { braces: [ */
  "connect": { endpoints: ["tcp/10.0.0.5:7447", { not: 'a key' }] },
  transport: {
    link: { rx: { max_message_size: 131072, }, },
    'shared_memory': { enabled: false },
  },
  metadata: { name: "it's \\"quoted\\" : { }", 'm\\u0061x': 1 },
}
"""
    assert outline(text) == {
        "mode": 3, "connect": 4, "connect/endpoints": 4, "transport": 5, "transport/link": 6,
        "transport/link/rx": 6, "transport/link/rx/max_message_size": 6, "transport/shared_memory": 7,
        "transport/shared_memory/enabled": 7, "metadata": 9, "metadata/name": 9, "metadata/max": 9}


def test_nesting_beyond_the_bound_names_the_line_it_begins_on() -> None:
    assert outline("{a:" * MAX_DEPTH + "1" + "}" * MAX_DEPTH)
    with pytest.raises(TooDeep) as caught:
        outline("{\n x: " + "[" * 100_000 + "]" * 100_000 + "\n}")
    assert caught.value.line == 2


def _paths(value: Any, prefix: str = "") -> set[str]:
    if not isinstance(value, dict):
        return set()
    found = set()
    for key, inner in value.items():
        path = f"{prefix}/{key}" if prefix else key
        found |= {path} | _paths(inner, path)
    return found


_KEYS = st.text("az_09 :,{}[]'\"\\\n\té\u2028", min_size=1, max_size=6)  # what could confuse a tokenizer
_VALUES = st.recursive(st.none() | st.booleans() | st.integers() | st.text(max_size=8),
                       lambda inner: st.lists(inner, max_size=3) | st.dictionaries(_KEYS, inner, max_size=3),
                       max_leaves=12)


@given(st.dictionaries(_KEYS, _VALUES, max_size=4), st.booleans())
def test_every_key_json_writes_is_in_the_outline(config: dict[str, Any], indent: bool) -> None:
    text = json.dumps(config, indent=2 if indent else None)
    assert set(outline(text)) == _paths(config)
