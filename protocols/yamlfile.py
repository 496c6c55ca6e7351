"""YAML files with line numbers: load a document and report errors as ``FILE:LINE: field: msg``.

Protocol and bench files are validated by pydantic models; when validation fails the error must
name the file, the line and the field. PyYAML's node tree keeps line marks, so the loader here
builds plain Python objects *and* a map from each key path to its line.

This is the one loader of the settings files (protocol, bench, chain), and it is bounded: a file
larger than :data:`MAX_BYTES`, not UTF-8 text, nested deeper than :data:`MAX_DEPTH`, or whose
aliases would expand to more than :data:`MAX_NODES` values is refused in one line naming the
file and the bound, in time proportional to its size (a "billion laughs" file is refused while
it is read, never expanded). Merge keys (``<<``) and keys that are not scalars are refused too.
"""

from __future__ import annotations

import difflib
import os
import re
import types
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, TypeVar, Union, get_args, get_origin

import yaml
from pydantic import BaseModel, ValidationError
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.events import AliasEvent
from yaml.resolver import Resolver

__all__ = [
    "MAX_BYTES",
    "MAX_DEPTH",
    "MAX_NODES",
    "ConfigError",
    "InputBoundError",
    "YamlDoc",
    "load_yaml",
    "parse_yaml",
    "read_yaml_data",
    "read_yaml_text",
    "unknown_key_message",
    "validate",
]

#: the largest settings file read (bytes); the shipped ones hold a few kB
MAX_BYTES = 1 << 20
#: the deepest nesting of lists and mappings (the shipped files nest 3 deep)
MAX_DEPTH = 64
#: the most values (scalars, lists and mappings, aliases expanded) a file may hold
MAX_NODES = 100_000
_BOUND_NAME = "a settings file"

M = TypeVar("M", bound=BaseModel)
Path_ = tuple[str | int, ...]


class ConfigError(ValueError):
    """A protocol or bench file is malformed or invalid; the message is one line."""


class InputBoundError(ConfigError):
    """A settings text breaks a bound of this loader (size, nesting, values, aliases) or one
    of its rules (merge keys, keys that are not scalars); the message is one line."""


@dataclass
class YamlDoc:
    """A loaded YAML document: data, text, source name and key path -> line (1-based);
    ``empty``: the text held no document (``data`` is then ``{}``)."""

    data: Any
    text: str
    source: str
    lines: dict[Path_, int] = field(default_factory=dict)
    empty: bool = False

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


class _Refused(Exception):
    """A bound or rule of this loader broken at ``line`` (1-based)."""

    def __init__(self, line: int, message: str) -> None:
        super().__init__(message)
        self.line = line


try:  # libyaml's parser when present (fast), PyYAML's own otherwise
    from yaml.cyaml import CParser as _Parser  # type: ignore[attr-defined]

    def _init_parser(loader: Any, text: str) -> None:
        _Parser.__init__(loader, text)

except ImportError:  # pragma: no cover - PyYAML without libyaml
    from yaml.parser import Parser as _Parser  # type: ignore[assignment]
    from yaml.reader import Reader
    from yaml.scanner import Scanner

    class _Parser(Reader, Scanner, _Parser):  # type: ignore[no-redef]
        pass

    def _init_parser(loader: Any, text: str) -> None:
        Reader.__init__(loader, text)
        Scanner.__init__(loader)
        yaml.parser.Parser.__init__(loader)


class _BoundedComposer(Composer, _Parser, Resolver):  # type: ignore[misc, valid-type]
    """PyYAML's composer counting as it goes: nesting depth, and values with every alias
    counted as the size of what it refers to, so that expansion is bounded before it happens."""

    def __init__(self, text: str) -> None:
        _init_parser(self, text)
        Composer.__init__(self)
        Resolver.__init__(self)
        self.depth = 0
        self.count = 0
        self.sizes: dict[str, int] = {}

    def compose_node(self, parent: Any, index: Any) -> Any:
        event: Any = self.peek_event()
        line = event.start_mark.line + 1
        if isinstance(event, AliasEvent):
            anchor = str(event.anchor)
            if anchor in self.anchors and anchor not in self.sizes:
                raise _Refused(line, f"alias *{anchor} refers to the value that holds it")
            self.count += self.sizes.get(anchor, 0)
            if self.count > MAX_NODES:
                raise _Refused(
                    line, f"aliases expand to more than {MAX_NODES} values (the bound for "
                    f"{_BOUND_NAME}; write the values out, or use fewer aliases)"
                )  # fmt: skip
            return super().compose_node(parent, index)
        self.depth += 1
        self.count += 1
        if self.depth > MAX_DEPTH:
            raise _Refused(line, _too_deep())
        if self.count > MAX_NODES:
            raise _Refused(line, f"more than {MAX_NODES} values (the bound for {_BOUND_NAME})")
        before = self.count
        node = super().compose_node(parent, index)
        if event.anchor is not None:
            self.sizes[event.anchor] = self.count - before + 1
        self.depth -= 1
        return node


class _Duplicate(ConfigError):
    """A key given twice in one mapping, at the line of the second."""

    def __init__(self, line: int, message: str) -> None:
        super().__init__(message)
        self.line = line


def _build(
    node: yaml.Node, path: Path_, lines: dict[Path_, int], constructor: SafeConstructor
) -> Any:
    lines[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        out: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            where = key_node.start_mark.line + 1
            if key_node.tag == "tag:yaml.org,2002:merge":
                raise _Refused(where, "merge keys (<<) are not supported; write the keys out")
            if not isinstance(key_node, yaml.ScalarNode):
                raise _Refused(where, "a key must be a name, not a list or a mapping")
            key = constructor.construct_object(key_node, deep=True)
            if key in out:
                at = ".".join(str(k) for k in path)
                raise _Duplicate(
                    where,
                    f"duplicate key {key!r}" + (f" in {at}" if at else "")
                    + f" (first given on line {lines[(*path, key)]})",
                )  # fmt: skip
            lines[(*path, key)] = where
            out[key] = _build(value_node, (*path, key), lines, constructor)
            lines[(*path, key)] = where  # the key's line, not the value's
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_build(item, (*path, i), lines, constructor) for i, item in enumerate(node.value)]
    return constructor.construct_object(node, deep=True)


def _reader_line(text: str, exc: yaml.YAMLError) -> int:
    position = getattr(exc, "position", None)
    return text.count("\n", 0, position) + 1 if isinstance(position, int) else 1


def parse_yaml(text: str, source: str = "<string>") -> YamlDoc:
    """Parse YAML text within the bounds of this module; a syntax error becomes
    ``SOURCE:LINE: malformed YAML: ...``, a broken bound ``SOURCE:LINE: what, the bound``."""
    size = len(text.encode("utf-8", "surrogatepass"))
    if size > MAX_BYTES:
        raise InputBoundError(_too_big(source, size))
    loader = _BoundedComposer(text)
    try:
        node = loader.get_single_node()
    except _Refused as exc:
        raise InputBoundError(f"{source}:{exc.line}: {exc}") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else 1
        problem = (exc.problem or exc.context or "syntax error").strip()
        if "nesting depth" in problem:  # libyaml's own bound (1000), met while looking ahead
            raise InputBoundError(f"{source}:{line}: {_too_deep()}") from None
        raise ConfigError(f"{source}:{line}: malformed YAML: {problem}") from None
    except yaml.YAMLError as exc:
        first = str(exc).splitlines()[0]
        raise ConfigError(f"{source}:{_reader_line(text, exc)}: malformed YAML: {first}") from None
    finally:
        loader.dispose()
    lines: dict[Path_, int] = {}
    if node is None:
        return YamlDoc({}, text, source, {(): 1}, empty=True)
    try:
        data = _build(node, (), lines, SafeConstructor())
    except _Refused as exc:
        raise InputBoundError(f"{source}:{exc.line}: {exc}") from None
    except _Duplicate as exc:  # at the second key's own line, not the document's first
        raise ConfigError(f"{source}:{exc.line}: {exc}") from None
    except ConfigError as exc:
        raise ConfigError(f"{source}:{node.start_mark.line + 1}: {exc}") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else 1
        problem = (exc.problem or exc.context or "cannot construct").strip().splitlines()[0]
        raise ConfigError(f"{source}:{line}: malformed YAML: {problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}:1: malformed YAML: {str(exc).splitlines()[0]}") from None
    return YamlDoc(data, text, source, lines)


def _too_deep() -> str:
    return f"lists and mappings nested deeper than {MAX_DEPTH} levels (the bound for {_BOUND_NAME})"


def _too_big(source: str, size: int) -> str:
    return (
        f"{source}: {size / 2**20:.1f} MiB is larger than {_BOUND_NAME} may be "
        f"({MAX_BYTES // 2**20} MiB)"
    )


def read_yaml_text(path: str | Path) -> str:
    """The text of a settings file, read within :data:`MAX_BYTES`; a file that cannot be
    read, is too large or is not UTF-8 text raises :class:`ConfigError` (one line)."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            raw = f.read(MAX_BYTES + 1)
            if len(raw) > MAX_BYTES:
                size = max(os.fstat(f.fileno()).st_size, len(raw))
                raise InputBoundError(_too_big(str(p), size))
    except OSError as exc:
        if p.is_dir():
            raise ConfigError(f"{p}: is a folder, not a file") from None
        raise ConfigError(f"{p}: cannot read ({exc.strerror or exc})") from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise ConfigError(
            f"{p}:{line}: not a text file: byte 0x{raw[exc.start]:02x} at offset {exc.start} "
            "is not UTF-8 (a settings file is YAML text)"
        ) from None


def load_yaml(path: str | Path) -> YamlDoc:
    """Read and parse a YAML file; a file that cannot be read or breaks a bound raises
    :class:`ConfigError`."""
    return parse_yaml(read_yaml_text(path), str(Path(path)))


def read_yaml_data(path: str | Path) -> Any:
    """The plain data of a YAML file (None if it holds no document), read and parsed within
    the bounds."""
    doc = load_yaml(path)
    return None if doc.empty else doc.data


def _shown(value: Any, limit: int = 60) -> str:
    """``value`` as it reads in a one-line message (YAML's spelling of booleans, cut short)."""
    if isinstance(value, bool):
        text = "true" if value else "false"
    else:
        text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def validate(doc: YamlDoc, model: type[M], context: dict[str, Any] | None = None) -> M:
    """Validate ``doc.data`` against ``model``; the first error becomes a one-line
    :class:`ConfigError` naming the file, the line and the field.

    An unknown key is reported before anything else (a misspelt key also leaves its field
    missing), with the closest allowed key at that place (``unknown key 'frequncy'; did you
    mean 'f_center'?``); of a union (a list or a mapping), the errors of the branch that
    matches the written value are reported."""
    if not isinstance(doc.data, dict):
        raise doc.error((), "the file must hold a mapping of keys to values")
    try:
        return model.model_validate(doc.data, context=context)
    except ValidationError as exc:
        errors = exc.errors()
        err = min(errors, key=_rank)
        raw_loc = tuple(err["loc"])
        loc = _data_loc(doc.data, raw_loc)
        msg = str(err["msg"])
        for prefix in ("Value error, ", "Assertion failed, "):
            msg = msg.removeprefix(prefix)
        if err["type"] == "extra_forbidden":
            msg = unknown_key_message(doc.data, model, raw_loc, errors)
        elif err["type"] == "missing":
            msg = "missing (required)"
        msg = msg.splitlines()[0]
        if err["type"] not in ("value_error", "assertion_error", "extra_forbidden", "missing"):
            msg += f", got {_shown(err.get('input'))}"  # pydantic's own checks omit the value
        if err["type"] == "literal_error" and isinstance(err.get("input"), str):
            msg += _did_you_mean(err["input"], re.findall(r"'([^']*)'", str(err["msg"])))
        # a model-level check names its field at the start of the message: "field: why"
        head, sep, tail = msg.partition(": ")
        if sep and " " not in head and isinstance(doc.data, dict):
            sub = tuple(head.split("."))
            if (*loc, sub[0]) in doc.lines:
                loc, msg = [*loc, *sub], tail
        raise doc.error(loc, msg) from None


#: errors that say only that a value is not of one branch's type (a union's other branches)
_TYPE_ERRORS = frozenset(
    {"list_type", "dict_type", "model_type", "model_attributes_type", "string_type", "tuple_type"}
)


def _rank(err: Any) -> int:
    """Which error to report: an unknown key first, then what is wrong with a value, then
    the type errors of a union's branches that do not match the written value."""
    if err["type"] == "extra_forbidden":
        return 0
    return 2 if err["type"] in _TYPE_ERRORS else 1


def _data_loc(data: Any, loc: Sequence[str | int]) -> list[str | int]:
    """``loc`` as a path in the data: without pydantic's union tags (``AmplitudeRange``,
    ``list[str]``), keeping a last part that is not there (a missing key)."""
    out: list[str | int] = []
    node = data
    for i, part in enumerate(loc):
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
            node = node[part]
        elif i < len(loc) - 1 or (isinstance(part, str) and "[" in part):
            continue  # a tag of a union's branch
        out.append(part)
    return out


def _did_you_mean(word: str, allowed: Sequence[str]) -> str:
    close = difflib.get_close_matches(word, list(allowed), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


def unknown_key_message(
    data: Any, model: type[BaseModel], loc: Sequence[str | int], errors: Sequence[Any]
) -> str:
    """For pydantic's ``extra_forbidden`` error at ``loc`` (``errors``: all of the validation's
    errors): ``unknown key 'frequncy'; did you mean 'f_center'?`` (the closest allowed key not
    written yet, else the one required key missing beside it, else a close one written too),
    or the keys allowed there when none is close."""
    key = str(loc[-1])
    allowed = _keys_at(model, loc[:-1])
    if not allowed:
        return f"unknown key {key!r}"
    written = _written_keys(data, loc[:-1])
    free = [k for k in allowed if k not in written]
    hint = _did_you_mean(key, free)
    if not hint:
        missing = [
            str(e["loc"][-1])
            for e in errors
            if e["type"] == "missing" and tuple(e["loc"][:-1]) == tuple(loc[:-1])
        ]
        if len(missing) == 1:
            hint = f"; did you mean {missing[0]!r}?"
    if not hint:
        close = difflib.get_close_matches(key, sorted(written & set(allowed)), n=1, cutoff=0.6)
        if close:
            hint = f"; did you mean {close[0]!r}? (already set: give that name to change it)"
    return f"unknown key {key!r}" + (hint or f" (allowed here: {', '.join(allowed)})")


def _written_keys(data: Any, loc: Sequence[str | int]) -> set[str]:
    node = data
    for part in loc:
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
            node = node[part]
    return {str(k) for k in node} if isinstance(node, dict) else set()


def _keys_at(model: type[BaseModel], loc: Sequence[str | int]) -> list[str]:
    """The field names of the model(s) found by following ``loc`` from ``model`` (union tags
    select a branch; list indices and mapping keys step into the item type)."""
    current: list[Any] = [model]
    for part in loc:
        reached = [a for ann in current for leaf in _leaves(ann) for a in _step(leaf, part)]
        if reached:
            current = reached
    names: list[str] = []
    for ann in current:
        for leaf in _leaves(ann):
            if isinstance(leaf, type) and issubclass(leaf, BaseModel):
                names += [n for n in leaf.model_fields if n not in names]
    return names


def _leaves(ann: Any) -> list[Any]:
    """The members of a union (or the type inside ``Annotated``), recursively."""
    origin = get_origin(ann)
    if origin is Annotated:
        return _leaves(get_args(ann)[0])
    if origin is Union or origin is types.UnionType:
        return [leaf for a in get_args(ann) for leaf in _leaves(a)]
    return [ann]


def _step(ann: Any, part: str | int) -> list[Any]:
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        if isinstance(part, str) and part in ann.model_fields:
            return [ann.model_fields[part].annotation]
        return [ann] if part == ann.__name__ else []
    origin, args = get_origin(ann), get_args(ann)
    if origin in (list, tuple, set, frozenset) and isinstance(part, int) and args:
        return [args[min(part, len(args) - 1)] if origin is tuple else args[0]]
    if origin is dict and len(args) == 2:
        return [args[1]]
    return []
