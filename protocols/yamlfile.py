"""YAML files with line numbers: load a document and report errors as ``FILE:LINE: field: msg``.

Protocol and bench files are validated by pydantic models; when validation fails the error must
name the file, the line and the field. PyYAML's node tree keeps line marks, so the loader here
builds plain Python objects *and* a map from each key path to its line.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

__all__ = ["ConfigError", "YamlDoc", "load_yaml", "parse_yaml", "validate"]

M = TypeVar("M", bound=BaseModel)
Path_ = tuple[str | int, ...]


class ConfigError(ValueError):
    """A protocol or bench file is malformed or invalid; the message is one line."""


@dataclass
class YamlDoc:
    """A loaded YAML document: data, text, source name and key path -> line (1-based)."""

    data: Any
    text: str
    source: str
    lines: dict[Path_, int] = field(default_factory=dict)

    def line_of(self, path: Sequence[str | int]) -> int:
        """Line of the deepest known prefix of ``path`` (1 when nothing is known)."""
        p = tuple(path)
        while p:
            if p in self.lines:
                return self.lines[p]
            p = p[:-1]
        return self.lines.get((), 1)

    def error(self, path: Sequence[str | int], message: str) -> ConfigError:
        """A :class:`ConfigError` ``SOURCE:LINE: a.b.c: message``."""
        dotted = ".".join(str(p) for p in path)
        where = f"{dotted}: " if dotted else ""
        return ConfigError(f"{self.source}:{self.line_of(path)}: {where}{message}")


def _build(node: yaml.Node, path: Path_, lines: dict[Path_, int]) -> Any:
    lines[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        out: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            key = _build(key_node, (), {})
            if key in out:
                raise ConfigError(f"duplicate key {key!r}")
            lines[(*path, key)] = key_node.start_mark.line + 1
            out[key] = _build(value_node, (*path, key), lines)
            lines[(*path, key)] = key_node.start_mark.line + 1  # the key's line, not the value's
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_build(item, (*path, i), lines) for i, item in enumerate(node.value)]
    loader = yaml.SafeLoader("")
    try:
        return loader.construct_object(node, deep=True)
    finally:
        loader.dispose()


def parse_yaml(text: str, source: str = "<string>") -> YamlDoc:
    """Parse YAML text; a syntax error becomes ``SOURCE:LINE: malformed YAML: ...``."""
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else 1
        problem = (exc.problem or exc.context or "syntax error").strip()
        raise ConfigError(f"{source}:{line}: malformed YAML: {problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}:1: malformed YAML: {exc}".splitlines()[0]) from None
    lines: dict[Path_, int] = {}
    if node is None:
        return YamlDoc({}, text, source, {(): 1})
    try:
        data = _build(node, (), lines)
    except ConfigError as exc:
        raise ConfigError(f"{source}:{node.start_mark.line + 1}: {exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}:1: malformed YAML: {str(exc).splitlines()[0]}") from None
    return YamlDoc(data, text, source, lines)


def load_yaml(path: str | Path) -> YamlDoc:
    """Read and parse a YAML file; unreadable files raise :class:`ConfigError`."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read ({exc.strerror or exc})") from None
    return parse_yaml(text, str(p))


def validate(doc: YamlDoc, model: type[M], context: dict[str, Any] | None = None) -> M:
    """Validate ``doc.data`` against ``model``; the first error becomes a one-line
    :class:`ConfigError` naming the file, the line and the field."""
    if not isinstance(doc.data, dict):
        raise doc.error((), "the file must hold a mapping of keys to values")
    try:
        return model.model_validate(doc.data, context=context)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = [p for p in err["loc"] if not (isinstance(p, str) and "[" in p)]
        msg = str(err["msg"])
        for prefix in ("Value error, ", "Assertion failed, "):
            msg = msg.removeprefix(prefix)
        if err["type"] == "extra_forbidden":
            msg = "unknown key"
        elif err["type"] == "missing":
            msg = "missing (required)"
        msg = msg.splitlines()[0]
        # a model-level check names its field at the start of the message: "field: why"
        head, sep, tail = msg.partition(": ")
        if sep and " " not in head and isinstance(doc.data, dict):
            sub = tuple(head.split("."))
            if (*loc, sub[0]) in doc.lines:
                loc, msg = [*loc, *sub], tail
        raise doc.error(loc, msg) from None
