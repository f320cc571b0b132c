"""One safe way to read the YAML files a user passes around (configs, suites, run folders).

:func:`load_yaml_file` reads a file only when it is a regular file no larger than
``max_bytes`` (checked with ``os.stat`` before it is opened, so a FIFO, ``/dev/zero`` or a
link to them is refused without blocking or reading), decodes it as UTF-8 and parses it
with a subclass of PyYAML's ``SafeLoader`` (no code is ever executed) that also refuses

- anchors and aliases (``&a`` / ``*a``): an alias can expand a file of a few hundred bytes
  into a document of billions of nodes ("billion laughs"); no file this project ships or
  writes uses them, so any anchor or alias is an error;
- nesting deeper than :data:`MAX_YAML_DEPTH` levels (50 thousand ``[`` would otherwise end
  in a ``RecursionError``).

Every problem is one :class:`YamlFileError` (a ``ValueError``) whose message names the
file (and the line, for a syntax error), ready to print as one line of a command's error.
PyYAML is imported on first use; without it the error names the pip command.
"""

from __future__ import annotations

import functools
import os
import stat
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

__all__ = ["YamlFileError", "MAX_YAML_BYTES", "MAX_YAML_DEPTH", "YAML_PIP", "load_yaml_file",
           "load_yaml_text"]

#: Largest YAML file read [bytes]: 256 KiB. The files of this project (configs, suites,
#: a run's config.yml/args.yml) are a few kB; PyYAML's pure-Python safe parser reads about
#: 0.2 MB/s, so the cap also bounds the time one file can take to about a second.
MAX_YAML_BYTES = 256 * 1024
#: Deepest nesting of sequences/mappings accepted [levels]; the files of this project nest
#: at most 5 deep.
MAX_YAML_DEPTH = 50
#: How to install PyYAML where only the environment is installed.
YAML_PIP = 'pip install -e ".[train]" (in a clone of tether_gym) or pip install "pyyaml>=6"'


class YamlFileError(ValueError):
    """A YAML file or text that cannot be read safely; the message names the file."""


@functools.lru_cache(maxsize=1)
def _loader_class():
    """The SafeLoader subclass with the alias and depth limits (PyYAML imported here)."""
    import yaml
    from yaml.events import AliasEvent, CollectionStartEvent, ScalarEvent

    class LimitedSafeLoader(yaml.SafeLoader):
        """SafeLoader that refuses anchors, aliases and deep nesting while composing."""

        depth = 0

        def compose_node(self, parent, index):
            event = self.peek_event()
            if isinstance(event, AliasEvent) or (
                    isinstance(event, (ScalarEvent, CollectionStartEvent))
                    and event.anchor is not None):
                raise yaml.composer.ComposerError(
                    None, None, "YAML anchors and aliases (&name, *name) are not accepted "
                    "(an alias can expand a small file into a huge document)",
                    event.start_mark)
            if isinstance(event, CollectionStartEvent):
                self.depth += 1
                if self.depth > MAX_YAML_DEPTH:
                    raise yaml.composer.ComposerError(
                        None, None, f"nested deeper than {MAX_YAML_DEPTH} levels",
                        event.start_mark)
            try:
                return super().compose_node(parent, index)
            finally:
                if isinstance(event, CollectionStartEvent):
                    self.depth -= 1

    return LimitedSafeLoader


def _with_constructors(constructors: Mapping[str, Callable] | None):
    """The limited loader class, or a subclass of it that also builds ``constructors``."""
    base = _loader_class()
    if not constructors:
        return base
    cls: Any = type("ExtendedSafeLoader", (base,), {})
    for tag, constructor in constructors.items():
        cls.add_constructor(tag, constructor)  # PyYAML copies the table for the subclass
    return cls


def _describe(exc) -> str:
    """One line from a yaml.YAMLError: the problem and its line number (1-based)."""
    if hasattr(exc, "character") and hasattr(exc, "position"):  # yaml.reader.ReaderError
        char = exc.character if isinstance(exc.character, int) else ord(exc.character[:1] or " ")
        return (f"character {exc.position + 1}: #x{char:04x} is not allowed in YAML "
                "(a control character or NUL byte; is it a text file?)")
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    problem = getattr(exc, "problem", None)
    context = getattr(exc, "context", None)
    if problem is None:
        text = str(exc)
    else:
        text = f"{context}, {problem}" if context else str(problem)
    text = " ".join(text.split())
    if mark is not None:
        return f"line {mark.line + 1}, column {mark.column + 1}: {text}"
    return text


def load_yaml_text(text: str, *, source: str, max_bytes: int = MAX_YAML_BYTES,
                   constructors: Mapping[str, Callable] | None = None) -> Any:
    """The document of YAML ``text``, read safely (no code run, no aliases, bounded depth).

    Parameters
    ----------
    text : str
        The YAML document.
    source : str
        What the text is, for the messages (e.g. ``"suite file runs/x.yml"``).
    max_bytes : int
        Longest text accepted [bytes of its UTF-8 encoding].
    constructors : mapping of str to callable, optional
        Extra tags and their PyYAML constructors (``constructor(loader, node)``), for a
        format with tags of its own that build plain data (rl_zoo3's ``OrderedDict``);
        the limits above hold for them too.

    Returns
    -------
    Any
        The document (``None`` for an empty one): dicts, lists, str, int, float, bool,
        None (and the few other safe YAML types: dates, bytes, sets).

    Raises
    ------
    YamlFileError
        When the text is longer than ``max_bytes``, is not valid YAML, holds an anchor or
        alias, or nests deeper than :data:`MAX_YAML_DEPTH`; also when PyYAML is missing.
    """
    if not isinstance(text, str):
        raise YamlFileError(f"{source}: YAML text must be a str, got {type(text).__name__}")
    if len(text) > max_bytes or len(text.encode("utf-8", "surrogatepass")) > max_bytes:
        raise YamlFileError(f"{source}: larger than {max_bytes} bytes; a YAML file of this "
                            "project is a few kB")
    try:
        import yaml
    except ImportError:
        raise YamlFileError(f"{source}: reading YAML needs PyYAML: {YAML_PIP}") from None
    try:
        # the reader refuses characters YAML does not allow (NUL bytes...) while built
        loader = _with_constructors(constructors)(text)
    except yaml.YAMLError as exc:
        raise YamlFileError(f"{source}: not valid YAML: {_describe(exc)}") from None
    try:
        return loader.get_single_data()
    except yaml.YAMLError as exc:
        raise YamlFileError(f"{source}: not valid YAML: {_describe(exc)}") from None
    except RecursionError:  # belt and braces: the depth limit comes first
        raise YamlFileError(f"{source}: nested too deeply") from None
    finally:
        loader.dispose()


def load_yaml_file(path, *, what: str = "YAML file", max_bytes: int = MAX_YAML_BYTES,
                   constructors: Mapping[str, Callable] | None = None) -> Any:
    """The document of the YAML file ``path``, read safely.

    The file must be a regular file (a link to one is followed) of at most ``max_bytes``,
    checked before it is opened: a folder, FIFO, device or socket is refused without
    being opened, so nothing blocks or reads without end.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    what : str
        What the file is, for the messages (e.g. ``"suite file"``, ``"--sweep file"``).
    max_bytes : int
        Largest file accepted [bytes] (default :data:`MAX_YAML_BYTES`).
    constructors : mapping of str to callable, optional
        Extra tags, as :func:`load_yaml_text` takes them.

    Returns
    -------
    Any
        The document, as :func:`load_yaml_text` returns it.

    Raises
    ------
    YamlFileError
        Naming the file: when it does not exist, is not a regular file, is larger than
        ``max_bytes``, cannot be read, is not UTF-8 text, or is not accepted by
        :func:`load_yaml_text`.
    """
    path = Path(path)
    source = f"{what} {path}"
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise YamlFileError(f"{source} does not exist") from None
    except OSError as exc:
        raise YamlFileError(f"{source} cannot be read: {exc.strerror or exc}") from None
    _check_regular(info, source, max_bytes)
    try:
        # O_NONBLOCK: should the path have been swapped for a FIFO since the stat, opening
        # it does not wait for a writer; the fstat below then refuses it
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)
                     | getattr(os, "O_NOCTTY", 0))
    except OSError as exc:
        raise YamlFileError(f"{source} cannot be read: {exc.strerror or exc}") from None
    with os.fdopen(fd, "rb") as fh:
        try:
            _check_regular(os.fstat(fh.fileno()), source, max_bytes)
            data = fh.read(max_bytes + 1)
        except OSError as exc:
            raise YamlFileError(f"{source} cannot be read: {exc.strerror or exc}") from None
    if len(data) > max_bytes:
        raise YamlFileError(f"{source}: larger than {max_bytes} bytes; a YAML file of this "
                            "project is a few kB")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise YamlFileError(f"{source}: not UTF-8 text (byte {exc.start} is "
                            f"{data[exc.start:exc.start + 1]!r}); is it a YAML file?") from None
    return load_yaml_text(text, source=source, max_bytes=max_bytes, constructors=constructors)


def _check_regular(info: os.stat_result, source: str, max_bytes: int) -> None:
    """Raise YamlFileError unless ``info`` is a regular file of at most ``max_bytes``."""
    if stat.S_ISDIR(info.st_mode):
        raise YamlFileError(f"{source} is a folder, not a file")
    if not stat.S_ISREG(info.st_mode):
        kind = ("a FIFO" if stat.S_ISFIFO(info.st_mode) else
                "a device" if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode) else
                "a socket" if stat.S_ISSOCK(info.st_mode) else "a special file")
        raise YamlFileError(f"{source} is not a regular file ({kind})")
    if info.st_size > max_bytes:
        raise YamlFileError(f"{source}: larger than {max_bytes} bytes ({info.st_size} bytes); "
                            "a YAML file of this project is a few kB")
