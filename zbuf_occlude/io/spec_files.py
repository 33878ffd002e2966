"""Reading scene and sensor files (JSON, YAML): one reader, bounded in size, depth and expansion.

A scene file (:func:`~zbuf_occlude.sensors.scene.files.load_scene`) or a sensor file
(:func:`~zbuf_occlude.sensors.kinds.sensor_from_name`) may come from anyone.  Before a field
is looked at (:mod:`zbuf_occlude.sensors.checks`), :func:`read_spec_file` makes sure that the
file is small and that its parse is small:

* only a regular file of at most :data:`~zbuf_occlude.io.caps.MAX_SPEC_FILE_BYTES` is read (a FIFO would block);
* JSON goes through the project's one JSON reader (:func:`zbuf_occlude.io.json_files.loads_json`:
  nesting at most :data:`~zbuf_occlude.io.json_files.MAX_JSON_DEPTH` levels);
* YAML is read by :class:`SpecYamlLoader`, a ``yaml.SafeLoader`` that refuses **aliases**
  (``*name``) and nesting deeper than the same limit while it composes the document, so
  nothing is ever expanded: nine anchors of nine aliases each (the "billion laughs") name
  9**10 values in 500 bytes.  A scene never needs to repeat a node by reference.

Every error is one line naming the file.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any

from zbuf_occlude._version import install_hint
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.caps import MAX_SPEC_FILE_BYTES
from zbuf_occlude.io.file_errors import without_quotes
from zbuf_occlude.io.json_files import MAX_JSON_DEPTH, loads_json
from zbuf_occlude.io.regular_files import read_regular_file

__all__ = ["SCENE_SUFFIXES", "read_spec_file", "yaml_loader"]

#: Suffixes of a scene file: JSON or YAML (a sensor file is JSON only).
SCENE_SUFFIXES = (".json", ".yaml", ".yml")


@functools.cache
def yaml_loader() -> type:
    """The YAML loader of scene files: ``yaml.SafeLoader`` without aliases, at most
    :data:`~zbuf_occlude.io.json_files.MAX_JSON_DEPTH` levels deep (PyYAML is imported on first use).

    Raises
    ------
    InvalidInputError
        PyYAML is not installed (the extra to install is named).
    """
    try:
        import yaml
    except ImportError:
        raise InvalidInputError(f"YAML files need PyYAML: {install_hint('yaml')}") from None

    class SpecYamlLoader(yaml.SafeLoader):
        """``yaml.SafeLoader`` that refuses aliases and deep nesting while composing (module docstring)."""

        def __init__(self, stream) -> None:
            super().__init__(stream)
            self._depth = 0

        def compose_node(self, parent, index):
            if self.check_event(yaml.AliasEvent):
                event = self.peek_event()
                raise yaml.composer.ComposerError(
                    None, None, "found an alias (*name): aliases are not allowed (write the value out)", event.start_mark
                )
            self._depth += 1
            try:
                if self._depth > MAX_JSON_DEPTH and self.check_event(yaml.CollectionStartEvent):
                    raise yaml.composer.ComposerError(
                        None, None, f"nests lists or mappings deeper than {MAX_JSON_DEPTH} levels", self.peek_event().start_mark
                    )
                return super().compose_node(parent, index)
            finally:
                self._depth -= 1

    return SpecYamlLoader


def _yaml_problem(exc: Exception) -> str:
    """One line from a PyYAML error: its problem and where (``found ... at line 3, column 5``), never what it quotes
    of the file (a tag, a character: :func:`~zbuf_occlude.io.file_errors.without_quotes`), nor its snippet of the line."""
    problem, mark = getattr(exc, "problem", None), getattr(exc, "problem_mark", None)
    if problem and mark is not None:
        return f"{without_quotes(problem)} at line {mark.line + 1}, column {mark.column + 1}"
    return f"{type(exc).__name__} from the parser"  # str(exc) shows the line of the file


def read_spec_file(path: str | os.PathLike, *, what: str = "file", yaml_ok: bool = True) -> Any:
    """The parsed content of a scene or sensor file: ``.json``, or ``.yaml``/``.yml`` when ``yaml_ok``.

    Parameters
    ----------
    path : path
    what : str
        What the file is, for messages (``"scene"``).
    yaml_ok : bool
        Whether YAML is read (scene files) or only JSON (sensor files).

    Raises
    ------
    InvalidInputError
        Naming the file: missing, not a regular file, over :data:`~zbuf_occlude.io.caps.MAX_SPEC_FILE_BYTES`, not
        UTF-8, an unknown suffix, not JSON/YAML, nested too deep, or a YAML alias.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    formats = SCENE_SUFFIXES if yaml_ok else (".json",)
    if suffix not in formats:
        raise InvalidInputError(f"{path}: unknown {what} format {path.suffix!r}; use {', '.join(formats)}")
    data = read_regular_file(path, max_bytes=MAX_SPEC_FILE_BYTES, error=InvalidInputError)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InvalidInputError(f"{path}: a {what} file must be UTF-8 text ({exc.reason} at byte {exc.start})") from None
    if suffix == ".json":
        return loads_json(text, what=str(path))
    try:
        loader = yaml_loader()  # says which extra to install when PyYAML is missing
    except InvalidInputError as exc:
        raise InvalidInputError(f"{path}: {exc}") from None
    import yaml

    try:
        return yaml.load(text, Loader=loader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        raise InvalidInputError(f"{path}: cannot parse {what} YAML: {_yaml_problem(exc)}") from None
    except ValueError as exc:  # an integer of over 4,300 digits (Python's int() limit)
        raise InvalidInputError(f"{path}: cannot parse {what} YAML: {without_quotes(str(exc))}") from None
