"""The one strict YAML reader for every config file (plant, controllers, safety, rig, faults).

- syntax errors: ``file:line:col: what is wrong`` (one line);
- a key given twice in one mapping is refused (YAML's "last one wins" would
  hide a typo): ``file:line:col: key 'M' given twice (first at line 5)``;
- the mappings it returns remember where each key was written
  (:class:`MarkedDict`), so a refused value is reported at its place:
  :func:`located` turns a :class:`~pneu_msgs_py.params.core.ParamError`
  ``linear.M: -0.28 refused; allowed: (0, 100] kg`` into
  ``config/plant.yaml:12:5: linear.M: -0.28 refused; allowed: (0, 100] kg``.

Lines and columns are 1-based, as editors show them.

Plain scalars are read as the user typed them: the YAML 1.2 core schema, not
PyYAML's YAML 1.1 (ROS 2's own YAML reader is 1.2 as well). ``010`` is the
decimal 10 (YAML 1.1: octal 8), ``0o10`` 8, ``0x10`` 16, ``1e5`` a float; ``1:00``
(1.1: sexagesimal 60), ``1_000``, ``yes``/``on``/``off`` (1.1: booleans) and
dates stay strings, which a number or boolean field then refuses.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, ClassVar

import yaml

from pneu_msgs_py.params.core import ParamError

__all__ = ["ConfigFileError", "MarkedDict", "from_option", "load_yaml", "located", "read_scalar"]


class ConfigFileError(ParamError):
    """A config file cannot be read or parsed; ``str(err)`` is ``file[:line:col]: problem``."""

    def __init__(self, path: str | os.PathLike, problem: str, line: int = 0, col: int = 0):
        self.path = str(path)
        self.line, self.col, self.problem = line, col, problem
        where = f"{self.path}:{line}:{col}" if line else self.path
        ValueError.__init__(self, f"{where}: {problem}")
        self.key, self.value, self.allowed = where, None, problem

    def __str__(self) -> str:
        return self.args[0]


@contextlib.contextmanager
def from_option(option: str | None) -> Iterator[None]:
    """Name the command-line option a file came from in its read/parse errors
    (``--plant: run.mcap: not UTF-8 text``); ``None``: the default file, named by its path."""
    try:
        yield
    except ConfigFileError as err:
        if option is None:
            raise
        new = ConfigFileError(err.path, err.problem, err.line, err.col)
        new.args = (f"{option}: {err}",)
        raise new from None
    except ParamError as err:  # a value refused, located in the file
        if option is None:
            raise
        new = type(err).__new__(type(err))
        ParamError.__init__(new, f"{option}: {err.key}", err.value, err.allowed)
        raise new from None


class MarkedDict(dict):
    """A YAML mapping that remembers the (line, col) of each key (1-based)."""

    __slots__ = ("mark", "marks")

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.marks: dict[Any, tuple[int, int]] = {}
        self.mark: tuple[int, int] = (0, 0)


def _pos(mark: Any) -> tuple[int, int]:
    return (mark.line + 1, mark.column + 1) if mark is not None else (0, 0)


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that refuses duplicate keys, returns :class:`MarkedDict` mappings and reads
    plain scalars by the YAML 1.2 core schema (see the module docstring)."""

    path = ""
    yaml_implicit_resolvers: ClassVar[dict] = {}  # filled below: the core schema, not YAML 1.1's

    def construct_document(self, node: yaml.Node) -> Any:
        _check_expansion(node, self.path)
        return super().construct_document(node)

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> MarkedDict:
        if not isinstance(node, yaml.MappingNode):
            raise yaml.constructor.ConstructorError(
                None, None, f"expected a mapping, found {node.id}", node.start_mark
            )
        seen: dict[Any, Any] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.get(key)
            except TypeError:
                line, col = _pos(key_node.start_mark)
                raise ConfigFileError(
                    self.path,
                    "a mapping key must be a plain value, not a list or mapping",
                    line,
                    col,
                ) from None
            if first is not None:
                line, col = _pos(key_node.start_mark)
                raise ConfigFileError(
                    self.path,
                    f"key {key!r} given twice (first at line {first.line + 1}); each key once",
                    line,
                    col,
                )
            seen[key] = key_node.start_mark
        self.flatten_mapping(node)
        out = MarkedDict()
        out.mark = _pos(node.start_mark)
        for key_node, value_node in node.value:
            key = self.construct_object(key_node, deep=True)
            out[key] = self.construct_object(value_node, deep=deep)
            out.marks[key] = _pos(key_node.start_mark)
        return out


MAX_EXPANSION = 10  # aliases may repeat a document's values, not multiply them ("YAML bomb")
MIN_EXPANDED = 100_000  # values a document always may expand to


def _check_expansion(root: yaml.Node, path: str) -> None:
    """Refuse a document whose aliases (``*name``) expand it to more than :data:`MAX_EXPANSION`
    times its own nodes (nine aliases of nine aliases of ...: a billion values from a
    kilobyte, which every reader after this one would walk)."""
    expanded: dict[int, int] = {}
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:  # post-order, each node once: the size of its expanded tree
        node, done = stack.pop()
        if id(node) in expanded:
            continue
        kids = (
            [k for pair in node.value for k in pair]
            if isinstance(node, yaml.MappingNode)
            else (node.value if isinstance(node, yaml.SequenceNode) else [])
        )
        if done:
            expanded[id(node)] = 1 + sum(expanded.get(id(k), 1) for k in kids)
            continue
        stack.append((node, True))
        stack.extend((k, False) for k in kids if id(k) not in expanded)
    total, distinct = expanded.get(id(root), 1), len(expanded)
    if total > max(MIN_EXPANDED, MAX_EXPANSION * distinct):
        line, col = _pos(root.start_mark)
        raise ConfigFileError(
            path,
            f"its aliases (*name) expand {distinct} values to {total}; allowed: at most "
            f"{MAX_EXPANSION} times the document's own (or {MIN_EXPANDED}) values",
            line,
            col,
        )


def _construct_map(loader: _StrictLoader, node: yaml.MappingNode) -> Iterator[MarkedDict]:
    data = MarkedDict()
    yield data
    built = loader.construct_mapping(node)
    data.update(built)
    data.marks, data.mark = built.marks, built.mark


_StrictLoader.add_constructor("tag:yaml.org,2002:map", _construct_map)

# the YAML 1.2 core schema (https://yaml.org/spec/1.2.2/#1032-tag-resolution)
_CORE = (
    ("tag:yaml.org,2002:null", r"^(?:~|null|Null|NULL|)$", "~nN"),
    ("tag:yaml.org,2002:bool", r"^(?:true|True|TRUE|false|False|FALSE)$", "tTfF"),
    ("tag:yaml.org,2002:int", r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$", "-+0123456789"),
    (
        "tag:yaml.org,2002:float",
        r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
        r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$",
        "-+.0123456789",
    ),
    ("tag:yaml.org,2002:merge", r"^<<$", "<"),
)
for _tag, _regexp, _first in _CORE:
    _StrictLoader.add_implicit_resolver(_tag, re.compile(_regexp), list(_first))
_StrictLoader.add_implicit_resolver("tag:yaml.org,2002:null", re.compile(r"^$"), [""])


def _construct_int(loader: _StrictLoader, node: yaml.ScalarNode) -> int:
    """Decimal as typed (``010`` is 10), ``0o`` octal, ``0x`` hexadecimal."""
    text = loader.construct_scalar(node)
    if text.startswith("0o"):
        return int(text[2:], 8)
    if text.startswith("0x"):
        return int(text[2:], 16)
    return int(text, 10)


def _construct_float(loader: _StrictLoader, node: yaml.ScalarNode) -> float:
    text = loader.construct_scalar(node).lower()
    if text.endswith(".inf"):
        return float(text.replace(".inf", "inf"))
    if text == ".nan":
        return float("nan")
    return float(text)


_StrictLoader.add_constructor("tag:yaml.org,2002:int", _construct_int)
_StrictLoader.add_constructor("tag:yaml.org,2002:float", _construct_float)
# a tree read here can be written back (an identified plant.yaml keeps the base file's leaves)
yaml.SafeDumper.add_representer(MarkedDict, yaml.SafeDumper.represent_dict)


def load_yaml(path: str | os.PathLike) -> Any:
    """Parse ``path`` strictly (see the module docstring); ``None`` for an empty file.

    Raises :class:`ConfigFileError` (a :class:`ParamError`) for a missing or
    unreadable file, a directory, device or pipe, a file over 64 MiB, text that is not UTF-8, a syntax error or a duplicate key.
    """
    from pneu_msgs_py.params.inputs import UnreadableInput, read_input

    p = Path(path)
    try:
        text = read_input(p)  # a regular file of bounded size, remembered as an input
    except UnreadableInput as err:
        raise ConfigFileError(p, err.problem) from None
    try:
        decoded = text.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ConfigFileError(p, f"not UTF-8 text (byte {err.start})") from None
    loader = None
    try:
        loader = _StrictLoader(decoded)  # its reader refuses control characters at once
        loader.path = str(p)
        return loader.get_single_data()
    except ConfigFileError:
        raise
    except yaml.reader.ReaderError as err:  # a control character (NUL, ...): not text
        at = err.position
        line, col = decoded.count("\n", 0, at) + 1, at - decoded.rfind("\n", 0, at)
        raise ConfigFileError(
            p, f"control character {err.character:#04x}; allowed: text", line, col
        ) from None
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        line, col = _pos(mark)
        problem = " ".join(x for x in (err.context, err.problem) if x) or "invalid YAML"
        raise ConfigFileError(p, _one_line(problem), line, col) from None
    except yaml.YAMLError as err:
        raise ConfigFileError(p, _one_line(str(err))) from None
    except RecursionError:
        raise ConfigFileError(p, "nested too deeply") from None
    finally:
        if loader is not None:
            loader.dispose()


def read_scalar(text: str) -> Any:
    """One value as this reader reads it in a file (YAML 1.2 core schema: ``010`` is 10,
    ``1:00`` a string); text YAML cannot parse (``a: b: c``) is the string itself."""
    loader = None
    try:
        loader = _StrictLoader(text)
        return loader.get_single_data()
    except (yaml.YAMLError, ConfigFileError, RecursionError):
        return text.strip()
    finally:
        if loader is not None:
            loader.dispose()


def _one_line(text: str) -> str:
    return re.sub(r"\s+", " ", text).strip()


_INDEX = re.compile(r"\[(\d+)\]$")


def _where(data: Any, key: str) -> tuple[int, int]:
    """(line, col) of the dotted ``key`` in ``data`` (the deepest part that exists)."""
    node, best = data, getattr(data, "mark", (0, 0))
    for part in key.split("."):
        idx = _INDEX.search(part)
        name = part[: idx.start()] if idx else part
        if not isinstance(node, MarkedDict) or name not in node:
            break
        best = node.marks.get(name, best)
        node = node[name]
        if idx and isinstance(node, list):
            i = int(idx.group(1))
            node = node[i] if i < len(node) else None
    return best


@contextlib.contextmanager
def located(path: str | os.PathLike, data: Any, root: str = "") -> Iterator[None]:
    """Re-raise a :class:`ParamError` from loading ``data`` with ``file:line:col:`` in front.

    ``root`` is the dotted path of the mapping the parameter keys are relative
    to (e.g. ``linear_controller.ros__parameters``); the key keeps the name
    the user wrote.
    """
    try:
        yield
    except ConfigFileError:
        raise
    except ParamError as err:
        node = data
        for part in filter(None, root.split(".")):
            node = node.get(part) if isinstance(node, Mapping) else None
        line, col = _where(node, str(err.key)) if node is not None else (0, 0)
        where = f"{path}:{line}:{col}" if line else str(path)
        new = type(err).__new__(type(err))
        ParamError.__init__(new, f"{where}: {err.key}", err.value, err.allowed)
        raise new from None
