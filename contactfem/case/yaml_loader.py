"""One YAML document as Python data, composed under a count.

At most :data:`~contactfem.case.limits.MAX_YAML_VALUES` values and
:data:`~contactfem.case.limits.MAX_YAML_DEPTH` levels, every alias counted at each of its
uses; a key given twice in one mapping is refused. Every refusal is one line.
"""

from __future__ import annotations

from typing import Any

import yaml

from contactfem.case import limits
from contactfem.case.messages import key_path, shortened
from contactfem.errors import CaseError


try:  # libyaml's parser: the events in C, an order of magnitude faster than PyYAML's own
    from yaml._yaml import CParser as _Events
except ImportError:  # pragma: no cover - PyYAML built without libyaml
    from yaml.parser import Parser
    from yaml.reader import Reader
    from yaml.scanner import Scanner

    class _Events(Reader, Scanner, Parser):  # type: ignore[no-redef]
        def __init__(self, stream: str) -> None:
            Reader.__init__(self, stream)
            Scanner.__init__(self)
            Parser.__init__(self)


class _Limit(Exception):
    """Raised from inside the composer: the message, with the file name still to prepend."""


class _CaseLoader(yaml.composer.Composer, _Events, yaml.constructor.SafeConstructor, yaml.resolver.Resolver):
    """PyYAML's safe loader, with composition counted and mappings checked for repeated keys.

    Each node is composed with its expanded size (the values it stands for once every
    alias in it is replaced by a copy) and height; an alias adds its target's size to the
    running count at every use. The count is the size of the document as any consumer
    walking it would see it, and composing stops as soon as it passes limits.MAX_YAML_VALUES, or
    the expanded nesting passes limits.MAX_YAML_DEPTH. An alias to a node still being composed
    (a recursive structure) is refused: its target has no size yet.
    """

    def __init__(self, text: str) -> None:
        _Events.__init__(self, text)
        yaml.composer.Composer.__init__(self)
        yaml.constructor.SafeConstructor.__init__(self)
        yaml.resolver.Resolver.__init__(self)
        self._measure: dict[int, tuple[int, int]] = {}  # id(node) -> (expanded values, height)
        self._values = 0
        self._path: list[str] = []
        self._mapping_paths: dict[int, str] = {}
        self.keys_at: dict[tuple[int, int], str] = {}  # (line, column) where a node starts -> its key path

    def _key(self) -> str:
        return "".join(self._path).lstrip(".")

    def _where(self) -> str:
        return self._key() or "the document"

    def compose_node(self, parent: Any, index: Any) -> Any:
        self._path.append(_path_step(parent, index))
        try:
            if self.check_event(yaml.AliasEvent):
                return self._compose_alias(parent, index)
            if len(self._path) > limits.MAX_YAML_DEPTH:
                raise _Limit(f"{self._where()}: nested more than {limits.MAX_YAML_DEPTH} levels deep (line "
                             f"{self.peek_event().start_mark.line + 1}); expected the case format's few levels")
            self._values += 1
            if self._values > limits.MAX_YAML_VALUES:
                where = self._where()
                # A long outline or profile listed inline is what reaches the bound in practice.
                hint = (" (list a long outline in a file: geometry.polygon.file, or geometry.profile.file)"
                        if where.startswith("geometry.") else "")
                raise _Limit(f"{where}: the document holds more than {limits.MAX_YAML_VALUES} values (line "
                             f"{self.peek_event().start_mark.line + 1}); expected a case of at most that many{hint}")
            start = self.peek_event().start_mark
            self.keys_at.setdefault((start.line, start.column), self._key())
            node = super().compose_node(parent, index)
            if isinstance(node, yaml.ScalarNode):
                self._measure[id(node)] = (1, 1)
                try:
                    node.value.encode("utf-8")
                except UnicodeEncodeError:
                    raise _Limit(f"{self._where()}: line {node.start_mark.line + 1}: a lone surrogate escape "
                                 "is not a character; expected Unicode text") from None
                return node
            is_mapping = isinstance(node, yaml.MappingNode)
            children = [c for pair in node.value for c in pair] if is_mapping else node.value
            sizes = [self._measure[id(c)] for c in children]
            self._measure[id(node)] = (1 + sum(n for n, _ in sizes), 1 + max((h for _, h in sizes), default=0))
            return node
        finally:
            self._path.pop()

    def compose_mapping_node(self, anchor: Any) -> Any:
        path = self._key()
        node = super().compose_mapping_node(anchor)
        self._mapping_paths[id(node)] = path
        return node

    def _compose_alias(self, parent: Any, index: Any) -> Any:
        event = self.peek_event()
        target = self.anchors.get(event.anchor)
        if target is not None and id(target) not in self._measure:
            raise _Limit(f"{self._where()} = *{shortened(event.anchor, 40)}: line {event.start_mark.line + 1}: the "
                         "alias refers to a node that contains it; expected a value that does not contain itself")
        node = super().compose_node(parent, index)  # the target; refuses an undefined alias
        size, height = self._measure[id(node)]
        self._values += size
        if self._values > limits.MAX_YAML_VALUES:
            raise _Limit(f"{self._where()} = *{shortened(event.anchor, 40)}: line {event.start_mark.line + 1}: with "
                         f"its aliases expanded the document holds more than {limits.MAX_YAML_VALUES} values; expected at "
                         "most that many (an alias counts as a copy at every use)")
        if len(self._path) - 1 + height > limits.MAX_YAML_DEPTH:
            raise _Limit(f"{self._where()} = *{shortened(event.anchor, 40)}: line {event.start_mark.line + 1}: with "
                         f"its aliases expanded the document is nested more than {limits.MAX_YAML_DEPTH} levels deep; "
                         "expected the case format's few levels")
        return node

    def construct_yaml_int(self, node: Any) -> Any:
        # int() of a long decimal text is quadratic (Python refuses past 4300 digits) and a
        # sexagesimal one (1:2:3) is parsed digit group by digit group: no coordinate needs 100.
        if len(str(node.value)) > 100:
            where = self.keys_at.get((node.start_mark.line, node.start_mark.column)) or "the document"
            raise _Limit(f"{where} = {shortened(str(node.value), 40)}: line {node.start_mark.line + 1}: an integer of "
                         f"{len(str(node.value))} characters; expected a number of at most 100")
        return super().construct_yaml_int(node)

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: dict[Any, Any] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.setdefault(key, key_node)
                except TypeError:
                    continue  # unhashable: PyYAML refuses it below
                if first is not key_node:
                    where = key_path(self._mapping_paths.get(id(node), ""), shortened(str(key), 64))
                    raise _Limit(f"{where}: the key appears twice in one mapping (lines {first.start_mark.line + 1} "
                                 f"and {key_node.start_mark.line + 1}); expected each key once")
        return super().construct_mapping(node, deep=deep)


_CaseLoader.add_constructor("tag:yaml.org,2002:int", _CaseLoader.construct_yaml_int)


def _path_step(parent: Any, index: Any) -> str:
    """The key path step to a node composed under ``parent`` at ``index`` (PyYAML's resolver arguments)."""
    if isinstance(parent, yaml.SequenceNode):
        return f"[{index}]"
    if isinstance(parent, yaml.MappingNode):
        if index is None:
            return ".<key>"
        if isinstance(index, yaml.ScalarNode):
            return "." + shortened(str(index.value), 64)
        return ".<key>"
    return ""


def load_yaml(text: str, filename: str) -> Any:
    """One YAML document of ``text`` as Python data, counted while composed (see :class:`_CaseLoader`)."""
    loader = _CaseLoader(text)
    try:
        return loader.get_single_data()
    except _Limit as limit:
        raise CaseError(f"{filename}: {limit}") from None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        key = loader.keys_at.get((mark.line, mark.column)) if mark is not None else None
        raise CaseError(f"{filename}: {key + ': ' if key else ''}{_yaml_problem(error, text)}") from None
    except RecursionError:
        raise CaseError(f"{filename}: not valid YAML: nested too deeply") from None
    finally:
        loader.dispose()


def _yaml_problem(error: yaml.YAMLError, text: str) -> str:
    """A one-line reason for PyYAML's error, with the line and column where it has them."""
    character = getattr(error, "character", None)  # a ReaderError: where in the text is not kept
    if isinstance(character, int):
        at = text.find(chr(character))
        where = ""
        if at >= 0:
            line = text.count("\n", 0, at) + 1
            where = f" at line {line}, column {at - (text.rfind(chr(10), 0, at) + 1) + 1}"
        return (f"not valid YAML{where}: character U+{character:04X} is not allowed in YAML text "
                "(control characters must be written as escapes in double quotes)")
    mark = getattr(error, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    problem = getattr(error, "problem", None) or str(error).splitlines()[0] or "invalid YAML"
    context = getattr(error, "context", None)
    if context == "expected a single document in the stream":
        return (f"holds more than one YAML document (another one starts{where}); "
                "expected a single mapping")
    if mark is not None:
        lines = text.split("\n")
        if mark.line < len(lines) and "\t" in lines[mark.line][: mark.column + 1]:
            return f"not valid YAML{where}: {problem} (a tab: YAML indents with spaces only)"
    reason = f"{context}: {problem}" if context and context not in problem else problem
    return f"not valid YAML{where}: {reason}"
