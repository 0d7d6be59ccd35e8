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

Numbers are read the YAML 1.2 way: ``1e-6`` is a float, while YAML 1.1's octal and base-60
integers (``010`` -> 8, ``2:30`` -> 150) and dates stay strings, so a field that expects a
number refuses them with one line instead of silently taking a different value.

Values that do not come from a file go through the same limits: :func:`parse_value` reads one
``--set`` value, :func:`check_value` measures a Python value (env ``overrides=``, options) and
:func:`read_text_file` reads a file as UTF-8 text only if it is a regular file of bounded size.

Parsing uses libyaml when PyYAML has it (about ten times faster than pure Python).
"""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from crowdnav.errors import CrowdNavError

MAX_CHARACTERS = 262_144  # 256 KiB: library files are a few kB; libyaml composes this in ~0.5 s
MAX_DEPTH = 64
MAX_VALUES = 100_000
MAX_BYTES = 4 * MAX_CHARACTERS  # UTF-8 takes at most 4 bytes per character
_BASE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_INT, _FLOAT, _TIMESTAMP = (f"tag:yaml.org,2002:{kind}" for kind in ("int", "float", "timestamp"))


class _Loader(_BASE_LOADER):  # type: ignore[misc, valid-type]
    """The safe loader with YAML 1.2 numbers: decimal integers without a leading zero, floats with
    a point or an exponent (``1e-6``), ``.inf`` and ``.nan``; no octal, base-60 or dates."""

    yaml_implicit_resolvers = {
        first: [(tag, rx) for tag, rx in resolvers if tag not in (_INT, _FLOAT, _TIMESTAMP)]
        for first, resolvers in _BASE_LOADER.yaml_implicit_resolvers.items()
    }


_Loader.add_implicit_resolver(_INT, re.compile(r"^[-+]?(?:0|[1-9][0-9]*)$"), list("-+0123456789"))
_Loader.add_implicit_resolver(_FLOAT, re.compile(
    r"^(?:[-+]?(?:[0-9]+\.[0-9]*|\.[0-9]+|[0-9]+(?=[eE]))(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"),
    list("-+0123456789."))
_LOADER = _Loader


class YamlLimitError(CrowdNavError, ValueError):
    """A YAML text over one of the limits; ``line`` is where the problem shows, if known."""

    def __init__(self, message: str, line: int | None = None):
        self.line = line
        super().__init__(message)


def read_bounded_yaml(text: str) -> tuple[Any, yaml.Node | None]:
    """``(document, node tree)`` of ``text`` within the limits; yaml.YAMLError for malformed YAML."""
    if len(text) > MAX_CHARACTERS:
        raise YamlLimitError(f"holds {len(text):,} characters; expected at most {MAX_CHARACTERS:,}")
    try:
        root = yaml.compose(text, Loader=_LOADER)
    except yaml.reader.ReaderError as error:  # its own message spans two lines
        line = text.count("\n", 0, error.position) + 1
        raise YamlLimitError(f"holds the control character #x{ord(error.character) if isinstance(error.character, str) else error.character:04x} "
                             "(YAML allows printable characters only); expected text", line) from None
    except RecursionError:
        raise YamlLimitError(f"is nested too deep for the YAML parser; expected at most {MAX_DEPTH} levels") from None
    if root is None:
        return None, None
    values, depth, deepest = _measure(root)
    if depth > MAX_DEPTH:
        raise YamlLimitError(f"is nested {depth} levels deep; expected at most {MAX_DEPTH}", deepest.start_mark.line + 1)
    if values > MAX_VALUES:
        raise YamlLimitError(f"holds more than {MAX_VALUES:,} values once its aliases are expanded; expected at most {MAX_VALUES:,}")
    # the tree is within bounds: building the document from it cannot blow up either
    try:
        return yaml.load(text, Loader=_LOADER), root
    except (ValueError, TypeError, OverflowError, IndexError) as error:  # a tag its value cannot fill: !!int 1e-6, a bare !!int
        problem = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise YamlLimitError(f"holds a value its explicit tag (such as !!int) cannot read ({problem}); expected the value "
                             "without the tag") from None


def parse_value(text: str) -> Any:
    """One value written in YAML (a ``--set`` value), within the same limits as a file."""
    return read_bounded_yaml(text)[0]


def read_text_file(path: str | Path) -> str:
    """The UTF-8 text of a regular file of at most :data:`MAX_BYTES` bytes; YamlLimitError (one line) otherwise.

    A FIFO, a device such as /dev/zero or a directory is refused before reading (a FIFO is opened
    without blocking); UTF-16 and other non-UTF-8 files are named as such, with the first bad byte.
    """
    try:
        handle = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as error:
        raise YamlLimitError(f"cannot read the file: {error.strerror or error}") from None
    try:
        mode = os.fstat(handle).st_mode
        if not stat.S_ISREG(mode):
            raise YamlLimitError(f"is {_file_kind(mode)}, not a regular file; expected a YAML file")
        with os.fdopen(os.dup(handle), "rb") as stream:
            data = stream.read(MAX_BYTES + 1)
    except OSError as error:
        raise YamlLimitError(f"cannot read the file: {error.strerror or error}") from None
    finally:
        os.close(handle)
    if len(data) > MAX_BYTES:
        raise YamlLimitError(f"holds more than {MAX_BYTES:,} bytes, so more than {MAX_CHARACTERS:,} "
                             f"characters; expected at most {MAX_CHARACTERS:,}")
    return decode_utf8(data)


def decode_utf8(data: bytes) -> str:
    """``data`` as text (a UTF-8 byte-order mark is allowed); a one-line YamlLimitError naming what it is instead."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise YamlLimitError("is UTF-16 text; expected UTF-8 (save the file as UTF-8)")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise YamlLimitError(f"is not UTF-8 text (byte 0x{data[error.start]:02x} at offset {error.start}); "
                             "expected a UTF-8 YAML file", line) from None
    if "\x00" in text:  # UTF-16 without a byte-order mark, or a binary file
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise YamlLimitError("holds NUL bytes: not UTF-8 text (UTF-16 or binary?); expected a UTF-8 YAML file", line)
    return text


def _file_kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a special file"


def check_value(value: Any, what: str = "the value") -> None:
    """Refuse a Python value (an override, an env option) over the limits a file has; YamlLimitError names ``what``.

    Containers shared by reference are measured once and counted wherever they are used, like
    YAML aliases (validating or copying the value expands them); a container that holds itself
    is refused; a string may hold up to :data:`MAX_CHARACTERS` characters.
    """
    size: dict[int, int] = {}
    height: dict[int, int] = {}  # levels from a container down to its deepest scalar
    visiting: set[int] = set()
    stack: list[tuple[Any, int, bool]] = [(value, 1, False)]
    while stack:
        item, level, expanded = stack.pop()
        children = _python_children(item)
        if children is None:
            if isinstance(item, (str, bytes)) and len(item) > MAX_CHARACTERS:
                raise YamlLimitError(f"{what} holds a string of {len(item):,} characters; expected at most {MAX_CHARACTERS:,}")
            continue
        key = id(item)
        if expanded:
            visiting.discard(key)
            size[key] = 1 + sum(size.get(id(child), 1) for child in children)
            height[key] = 1 + max((height.get(id(child), 1) for child in children), default=0)
            if size[key] > MAX_VALUES:
                raise YamlLimitError(f"{what} holds more than {MAX_VALUES:,} values once shared parts are counted "
                                     f"wherever they are used; expected at most {MAX_VALUES:,}")
            continue
        if key in size:  # shared: measured once, but its depth counts from here too
            level += height[key] - 1
        if level > MAX_DEPTH:
            raise YamlLimitError(f"{what} is nested more than {MAX_DEPTH} levels deep; expected at most {MAX_DEPTH}")
        if key in size:
            continue
        stack.append((item, level, True))
        visiting.add(key)
        for child in children:
            if id(child) in visiting:
                raise YamlLimitError(f"{what} contains itself; expected a finite value")
            stack.append((child, level + 1, False))


def _python_children(item: Any) -> list[Any] | None:
    """The items of a container (keys and values of a mapping), None for a scalar."""
    if isinstance(item, Mapping):
        return [part for pair in item.items() for part in pair]
    if isinstance(item, (list, tuple, set, frozenset)):
        return list(item)
    return None


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
