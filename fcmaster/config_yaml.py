"""YAML text to checked data: a strict reader, ``${ENV_VAR}`` substitution, pydantic's errors.

Each reports problems as ``(key path, reason)`` pairs, the form every config problem takes.

The reader (:func:`read`) refuses what plain YAML lets a file smuggle past a reviewer: a key
given twice in one mapping (YAML keeps the last silently, so ``max_frequency_hz: 50`` then
``max_frequency_hz: 500`` would run at 500), nesting deeper than any config needs, and
aliases that expand a small file into a huge one (an "alias bomb") or into itself. Anchors
and aliases themselves stay allowed, merge keys (``<<: *defaults``) too: a fleet of alike
drives is written with them, and their expansion is bounded.
"""

from __future__ import annotations

import re
from typing import Any, Final

import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from fcmaster.errors import ConfigError

MAX_DEPTH: Final = 32  # a config nests about 7 deep (buses, a drive, its watchdog, …)
# Aliases may make the document at most this many times the nodes it writes out (and at
# least MIN_EXPANDED_NODES in all): ample for merge keys, far from a bomb's billions.
ALIAS_GROWTH: Final = 10
MIN_EXPANDED_NODES: Final = 100_000
_CAP: Final = 1 << 62  # sizes are counted up to here
_MERGE: Final = "tag:yaml.org,2002:merge"
_ONCE: Final = "a key may appear once in a mapping (YAML would silently keep the second)"

Problem = tuple[str, str]


def _line(mark: Any) -> str:
    return f"line {mark.line + 1}"


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader, composing no deeper than MAX_DEPTH, noting where aliases are."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self.depth = 0
        self.aliases: list[Any] = []  # each alias's start mark

    def compose_node(self, parent: Node | None, index: int) -> Node | None:
        # PyYAML composes recursively: bounded here, a 100,000-deep list is refused after
        # reading MAX_DEPTH levels instead of ending in a RecursionError.
        event = self.peek_event()  # type: ignore[no-untyped-call]
        if isinstance(event, yaml.AliasEvent):
            self.aliases.append(event.start_mark)
        elif self.depth >= MAX_DEPTH:
            raise ConfigError(
                [(_line(event.start_mark), f"nested deeper than {MAX_DEPTH} levels; a config "
                  "needs far fewer")]
            )  # fmt: skip
        self.depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1


_INDENT = "the indentation does not line up: keys of one mapping start in the same column"
# PyYAML says where it stopped and what its grammar expected there ("expected <block end>,
# but found '<block mapping start>'"); a user needs what to change in the file.
# (what PyYAML's problem text contains, what it means in the file)
_IN_WORDS: tuple[tuple[str, str], ...] = (
    ("expected <block end>", _INDENT),
    ("did not find expected key", _INDENT),
    ("did not find expected '-' indicator", "a list item is indented unlike the ones above it"),
    ("'\\t' that cannot start any token", "a tab character: indent with spaces only"),
    ("found unexpected end of stream", "a quote that opens here is never closed"),
    ("could not find expected ':'", "a line that is not 'key: value' (is a ':' missing?)"),
    ("expected ',' or ']'", "a list opened with '[' is not closed with ']'"),
    ("expected ',' or '}'", "a mapping opened with '{' is not closed with '}'"),
    (
        "mapping values are not allowed here",
        "a second ':' on one line: put quotes around a value that contains ': ', or "
        "start the key on a line of its own",
    ),
    ("found undefined alias", "*NAME refers to an anchor &NAME that is not defined above it"),
)


def yaml_problem(exc: yaml.YAMLError) -> tuple[str, str]:
    """``(where, what)`` of a YAML syntax error: line and column, and the mistake in words."""
    problem = str(getattr(exc, "problem", None) or exc)
    mark = getattr(exc, "problem_mark", None)
    words = next((w for jargon, w in _IN_WORDS if jargon in problem), "")
    if "stream" in problem and getattr(exc, "context_mark", None) is not None:
        mark = exc.context_mark  # type: ignore[attr-defined] # where the quote or bracket opened
    where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "(file)"
    return where, f"not valid YAML: {words or problem}"


def read(text: str, problems: list[Problem]) -> Any:
    """The data of one YAML document; each key given twice added to ``problems``.

    Keys given twice are all collected (naming both lines) and the data still comes back,
    so that the rest of the file is checked too; a syntax error, too deep a nesting, or
    aliases beyond the bound end the reading with a ConfigError.
    """
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        refused = _expansion(node, loader.aliases)
        if refused:
            raise ConfigError(refused)
        problems.extend(_duplicates(node, loader))
        return loader.construct_document(node)
    except yaml.YAMLError as exc:
        raise ConfigError([yaml_problem(exc)]) from None
    finally:
        loader.dispose()


def _children(node: Node) -> list[Node]:
    if isinstance(node, SequenceNode):
        return list(node.value)
    if isinstance(node, MappingNode):
        return [part for pair in node.value for part in pair]
    return []


def _expansion(root: Node, aliases: list[Any]) -> list[Problem]:
    """What aliases do to the document: a node inside itself, too many nodes, too deep.

    Measured over the composed graph, where an alias is the anchored node met again, in one
    pass that never expands anything (iterative: the graph may be long).
    """
    if not aliases:
        return []  # without aliases the graph is the tree the reader bounded already
    size: dict[int, int] = {}
    height: dict[int, int] = {}
    on_path: set[int] = set()
    stack: list[tuple[Node, bool]] = [(root, False)]
    while stack:
        node, finished = stack.pop()
        key = id(node)
        if finished:
            kids = _children(node)
            # Capped: a bomb's sizes would be numbers of hundreds of digits.
            size[key] = min(1 + sum(size[id(k)] for k in kids), _CAP)
            height[key] = 1 + max((height[id(k)] for k in kids), default=0)
            on_path.discard(key)
        elif key in on_path:
            return [(_line(node.start_mark), "an alias refers to the node that contains it "
                     f"(anchored at {_line(node.start_mark)}): it would never end")]  # fmt: skip
        elif key not in size:
            on_path.add(key)
            stack.append((node, True))
            stack.extend((kid, False) for kid in _children(node))
    written = len(size)
    bound = max(MIN_EXPANDED_NODES, ALIAS_GROWTH * written)
    more = f" and {len(aliases) - 1} more" if len(aliases) > 1 else ""
    where = f"{_line(aliases[0])}{more}"
    if size[id(root)] > bound:
        return [(_line(aliases[0]), f"the aliases (*name) at {where} expand the file's "
                 f"{written} values to more than {bound:,}: refused as an alias bomb; write "
                 "the repeated parts out, or repeat less")]  # fmt: skip
    if height[id(root)] > MAX_DEPTH:
        return [(_line(aliases[0]), f"the aliases (*name) at {where} nest the file deeper "
                 f"than {MAX_DEPTH} levels; a config needs far fewer")]  # fmt: skip
    return []


def _duplicates(root: Node, loader: _Loader) -> list[Problem]:
    """Every key given twice in one mapping, at its key path, naming both lines."""
    found: list[tuple[int, Problem]] = []  # with the line, to report in file order
    seen: set[int] = set()  # a node reached again through an alias is checked once
    stack: list[tuple[Node, str]] = [(root, "")]
    while stack:
        node, path = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, SequenceNode):
            stack.extend((kid, f"{path}[{i}]") for i, kid in enumerate(node.value))
            continue
        if not isinstance(node, MappingNode):
            continue
        first: dict[tuple[str, Any], Node] = {}
        for key_node, value in node.value:
            if not isinstance(key_node, ScalarNode):
                continue  # a complex key: the constructor refuses it as unhashable
            # Compared as YAML means them: `a` and "a" are one key, `1` and "1" are two.
            merge = key_node.tag == _MERGE  # `<<`: no value of its own to construct
            key = (key_node.tag, key_node.value if merge else loader.construct_object(key_node))
            at = _join(path, key_node.value)
            if key in first:
                lines = f"{_line(first[key].start_mark)} and {_line(key_node.start_mark)}"
                reason = f"given twice, at {lines}: {_ONCE}"
                found.append((key_node.start_mark.line, (at, reason)))
            else:
                first[key] = key_node
            stack.append((value, at))
    return [problem for _, problem in sorted(found)]


_ENV = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?::-([^}]*))?\}")


def substitute(value: Any, path: str, env: Any, problems: list[tuple[str, str]]) -> Any:
    """``value`` with ``${VAR}`` (``${VAR:-default}``) replaced from ``env`` throughout.

    An unset variable without a default is a problem at ``path``'s key; it leaves a
    stand-in long enough to pass a token's length check, so that it is reported once.
    """
    if isinstance(value, str):

        def replace(match: re.Match[str]) -> str:
            name, default = match[1], match[2]
            if name in env:
                return str(env[name])
            if default is not None:
                return default
            problems.append((path or "(top)", f"environment variable {name} is not set"))
            return f"unset-{name}".ljust(_UNSET_LENGTH, "-")

        return _ENV.sub(replace, value)
    if isinstance(value, dict):
        return {k: substitute(v, _join(path, k), env, problems) for k, v in value.items()}
    if isinstance(value, list):
        return [substitute(v, f"{path}[{i}]", env, problems) for i, v in enumerate(value)]
    return value


_UNSET_LENGTH = 32  # an unset variable's stand-in passes a token's length check


def _join(path: str, key: object) -> str:
    return f"{path}.{key}" if path else str(key)


def _location(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        out = f"{out}[{part}]" if isinstance(part, int) else _join(out, part)
    return out or "(top)"


def describe_error(error: Any) -> tuple[str, str]:
    """One of pydantic's errors as ``(key path, reason)``, in the words users read."""
    loc = tuple(p for p in error["loc"] if not (isinstance(p, str) and p.startswith("function-")))
    kind, given = error["type"], error.get("input")
    if kind == "extra_forbidden":
        return _location(loc), "unknown key"
    if kind == "missing":
        return _location(loc), "required key is missing"
    if kind == "literal_error":
        expected = error.get("ctx", {}).get("expected", "")
        return _location(loc), f"{given!r} is not one of {expected}"
    return _location(loc), f"{error['msg'].lower()} (got {given!r})"
