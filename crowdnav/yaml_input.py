"""Reading a YAML configuration file at a bounded cost, whatever it holds.

Every file crowdnav reads (scenarios, training configs, experiments) goes through
:func:`read_bounded_yaml`. A hostile or broken file is refused in well under a second with one
line saying why, instead of hanging or exhausting memory:

* more than :data:`MAX_CHARACTERS` characters (library files are a few kB);
* nesting deeper than :data:`MAX_DEPTH` levels (Python's parser would hit its recursion limit
  near 1,000 levels; that is caught too);
* more than :data:`MAX_VALUES` values once aliases are expanded. An "alias bomb" of a few
  hundred bytes expands to billions of values: the count walks each distinct node once and
  multiplies, so counting costs as little as the file is long.

Parsing uses libyaml when PyYAML has it (about ten times faster than pure Python).
"""

from __future__ import annotations

from typing import Any

import yaml

MAX_CHARACTERS = 262_144  # 256 KiB: library files are a few kB; libyaml composes this in ~0.5 s
MAX_DEPTH = 64
MAX_VALUES = 100_000
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class YamlLimitError(ValueError):
    """A YAML text over one of the limits; ``line`` is where the problem shows, if known."""

    def __init__(self, message: str, line: int | None = None):
        self.line = line
        super().__init__(message)


def read_bounded_yaml(text: str) -> tuple[Any, yaml.Node | None]:
    """``(document, node tree)`` of ``text`` within the limits; yaml.YAMLError for malformed YAML."""
    if len(text) > MAX_CHARACTERS:
        raise YamlLimitError(f"the file holds {len(text):,} characters; expected at most {MAX_CHARACTERS:,}")
    try:
        root = yaml.compose(text, Loader=_LOADER)
    except RecursionError:
        raise YamlLimitError(f"nesting too deep for the YAML parser; expected at most {MAX_DEPTH} levels") from None
    if root is None:
        return None, None
    values, depth, deepest = _measure(root)
    if depth > MAX_DEPTH:
        raise YamlLimitError(f"nested {depth} levels deep; expected at most {MAX_DEPTH}", deepest.start_mark.line + 1)
    if values > MAX_VALUES:
        raise YamlLimitError(f"holds more than {MAX_VALUES:,} values once its aliases are expanded; expected at most {MAX_VALUES:,}")
    # the tree is within bounds: building the document from it cannot blow up either
    return yaml.load(text, Loader=_LOADER), root


def _measure(root: yaml.Node) -> tuple[int, int, yaml.Node]:
    """(values after alias expansion, depth, the deepest node), visiting each distinct node once.

    Iterative (no recursion limit), post-order with memoised sizes: an aliased node is one
    object in the tree, so its size is computed once and added wherever it is referenced.
    """
    size: dict[int, int] = {}
    depth_of: dict[int, int] = {id(root): 1}
    visiting: set[int] = set()
    deepest, depth = root, 1
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, expanded = stack.pop()
        key = id(node)
        if expanded:
            visiting.discard(key)
            size[key] = 1 + sum(size[id(child)] for child in _children(node))
            if size[key] > MAX_VALUES:  # no need to count further
                return size[key], depth, deepest
            continue
        if key in size:
            continue
        stack.append((node, True))
        visiting.add(key)
        level = depth_of[key]
        if level > depth:
            depth, deepest = level, node
        if level > MAX_DEPTH:  # no need to look deeper
            return 0, level, node
        for child in _children(node):
            if id(child) in visiting:
                raise YamlLimitError("an alias refers to a value that contains it; expected no recursive aliases", child.start_mark.line + 1)
            if id(child) not in size:
                depth_of[id(child)] = max(depth_of.get(id(child), 0), level + 1)
                stack.append((child, False))
    return size[id(root)], depth, deepest


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [item for pair in node.value for item in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []
