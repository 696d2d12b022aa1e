"""The bounded safe YAML loader of specs, batch plans and dataset calibration files.

At most ``MAX_SPEC_BYTES`` of text, ``MAX_NESTING`` levels, ``MAX_ALIASES`` alias uses and
``MAX_VALUES`` values after expanding aliases (a "billion laughs" file is refused, not
expanded); recursive aliases and tags other than YAML's plain types are refused; no tag
runs code. Mappings and lists remember their lines, so errors can name them.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from tofnet.errors import DataError, SpecError, located, quote, quote_field

# YAML 1.1 (PyYAML) reads 1e-3 as a string; YAML 1.2 and people read it as a number.
_FLOAT = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$")

#: Limits of the YAML loader (docs/reliability.md): a spec is a few KB.
MAX_SPEC_BYTES = 1 << 20
MAX_NESTING = 32
MAX_ALIASES = 100
MAX_VALUES = 100_000
_PLAIN_TAGS = {"tag:yaml.org,2002:" + name for name in ("str", "int", "float", "bool", "null", "timestamp")}


class _Map(dict):
    """A mapping that remembers its line and the line of each key (1-based)."""

    line: int | None = None
    key_lines: dict = {}


class _Seq(list):
    """A list that remembers its line and the line of each item (1-based)."""

    line: int | None = None
    item_lines: list = []


def kind_word(value: object) -> str:
    """What a YAML value is, in a user's words (``a list``, ``text``), not the loader's class names (``_Seq``)."""
    kinds = ((list, "a list"), (str, "text"), (bool, "true or false"), ((int, float), "a number"))
    return "nothing" if value is None else next((word for kind, word in kinds if isinstance(value, kind)), "a value")


def _parse_yaml(text: str, source: str, empty: str = "empty spec; expected a mapping with processes and connections"
                ) -> Any:
    if len(text) > MAX_SPEC_BYTES:
        raise SpecError(located(source, None, f"{len(text):,} characters; a spec may hold at most {MAX_SPEC_BYTES:,}"))
    try:
        _check_shape(text, source)
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as err:
        raise _yaml_error(err, source) from None
    if node is None:
        raise SpecError(located(source, None, empty))
    return _Builder(source).build(node)


def _yaml_error(err: yaml.YAMLError, source: str) -> SpecError:
    mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
    problem = getattr(err, "problem", None) or str(err).splitlines()[0]
    where = f" (column {mark.column + 1})" if mark else ""
    return SpecError(located(source, mark.line + 1 if mark else None, f"malformed YAML: {problem}{where}"))


def _check_shape(text: str, source: str) -> None:
    """Nesting depth and alias count from the parser's event stream (which does not
    recurse), before anything is composed or expanded."""
    depth, aliases = 0, 0
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_NESTING:
                raise SpecError(located(source, event.start_mark.line + 1,
                                        f"nested more than {MAX_NESTING} levels deep"))
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1
        elif isinstance(event, yaml.AliasEvent):
            aliases += 1
            if aliases > MAX_ALIASES:
                raise SpecError(located(source, event.start_mark.line + 1,
                                        f"more than {MAX_ALIASES} aliases (*name)"))


class _Builder:
    """Nodes to Python values with line numbers, expanding aliases within a budget."""

    def __init__(self, source: str):
        self.source, self.loader, self.values, self.active = source, yaml.SafeLoader(""), 0, set()

    def quote(self, value: Any) -> str:
        """A field of the document: from a file, as the text readers quote (``quote_field``: never from a
        file that links out of its folder, a calibration YAML linked to ``~/.ssh/config``)."""
        return quote(value) if self.source == "<string>" else quote_field(self.source, value)

    def fail(self, node: yaml.Node, message: str) -> SpecError:
        return SpecError(located(self.source, node.start_mark.line + 1, message))

    def build(self, node: yaml.Node) -> Any:
        self.values += 1
        if self.values > MAX_VALUES:
            raise self.fail(node, f"expands to more than {MAX_VALUES:,} values (through aliases)")
        if id(node) in self.active:
            raise self.fail(node, "recursive alias: a value contains itself")
        line = node.start_mark.line + 1
        if isinstance(node, (yaml.MappingNode, yaml.SequenceNode)):
            kind = "map" if isinstance(node, yaml.MappingNode) else "seq"
            if node.tag != f"tag:yaml.org,2002:{kind}":
                raise self.fail(node, f"tag {self.quote(node.tag)} is not allowed; a spec holds plain values")
            self.active.add(id(node))
            try:
                return self.mapping(node, line) if kind == "map" else self.sequence(node, line)
            finally:
                self.active.discard(id(node))
        if node.tag not in _PLAIN_TAGS:
            raise self.fail(node, f"tag {self.quote(node.tag)} is not allowed; a spec holds plain values")
        if node.tag == "tag:yaml.org,2002:str" and node.style is None and _FLOAT.match(node.value):
            return float(node.value)
        try:
            return self.loader.construct_object(node, deep=True)
        except yaml.YAMLError as err:
            raise _yaml_error(err, self.source) from None
        except (ValueError, OverflowError):  # e.g. an integer of more than 4300 digits
            raise self.fail(node, f"cannot read the value {self.quote(node.value)}") from None

    def mapping(self, node: yaml.MappingNode, line: int) -> "_Map":
        try:
            self.loader.flatten_mapping(node)  # YAML merge keys (<<)
        except yaml.YAMLError as err:
            raise _yaml_error(err, self.source) from None
        out = _Map()
        out.line, out.key_lines = line, {}
        for key_node, value_node in node.value:
            key = self.build(key_node)
            key_line = key_node.start_mark.line + 1
            if isinstance(key, (dict, list)):
                raise SpecError(located(self.source, key_line, "a mapping key must be a plain value"))
            if key in out:
                raise SpecError(located(self.source, key_line,
                                        f"duplicate key {self.quote(key)} (first on line {out.key_lines[key]})"))
            out[key] = self.build(value_node)
            out.key_lines[key] = key_line
        return out

    def sequence(self, node: yaml.SequenceNode, line: int) -> "_Seq":
        out = _Seq(self.build(item) for item in node.value)
        out.line, out.item_lines = line, [item.start_mark.line + 1 for item in node.value]
        return out


def _line(container: Any, key: Any = None) -> int | None:
    """Line of ``container[key]`` (or of the container) when it came from YAML."""
    if key is not None:
        if isinstance(container, _Map) and key in container.key_lines:
            return container.key_lines[key]
        if isinstance(container, _Seq) and isinstance(key, int) and key < len(container.item_lines):
            return container.item_lines[key]
    return getattr(container, "line", None)


def yaml_source(path_or_text: str | Path, what: str) -> tuple[str, str, Path | None]:
    """``(text, source name, file)`` of a YAML document given as a file or as text (``file`` None).

    A ``Path``, or a one-line string naming a file (or ending in ``.yaml``), is read as a file,
    with the limits of ``MAX_SPEC_BYTES`` and regular files only; one line that is neither a
    file nor a mapping is taken for a missing file. Errors are ``SpecError`` naming ``what``.
    """
    if isinstance(path_or_text, Path) or ("\n" not in path_or_text and (
            path_or_text.endswith((".yaml", ".yml")) or _is_file(path_or_text))):
        path = Path(path_or_text)
        return _read_spec_file(path, what), str(path), path
    if "\n" not in path_or_text and ":" not in path_or_text and "{" not in path_or_text:
        # One line that is neither a mapping nor an existing file: most likely a file name.
        raise SpecError(f"{quote(path_or_text)}: no such {what} file (and not YAML text describing a mapping)")
    return path_or_text, "<string>", None


def _is_file(name: str) -> bool:
    try:
        return len(name) < 4096 and Path(name).is_file()
    except (OSError, ValueError):  # a name too long for the system, a NUL byte
        return False


def _read_spec_file(path: Path, what: str) -> str:
    from tofnet.io.files import read_text
    try:
        return read_text(path, f"{what} file", limit=MAX_SPEC_BYTES)
    except DataError as err:
        message = str(err).removeprefix(located(path, None, ""))
        raise SpecError(located(path, None, f"cannot read the {what}: {message}")) from None


def read_yaml_file(path: str | Path, what: str) -> Any:
    """Plain data of a YAML file that is not a spec (DSEC's ``cam_to_cam.yaml``), read under
    the spec's limits (size, nesting, aliases, plain types only)."""
    path = Path(path)
    return _parse_yaml(_read_spec_file(path, what), str(path), empty=f"empty {what}")
