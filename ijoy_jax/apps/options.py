"""Option syntax the ``ijoy`` subcommands share: the parser, output paths, sizes and ``--set NAME=VALUE``.

Every refusal of a command line is one line naming the option and what it takes. The parser
(:class:`CommandParser`) raises :class:`UsageError` instead of printing its usage, so ``ijoy`` prints it as
it prints any other bad input (``ijoy: error: ...``, exit status 2). The ``type=`` functions below raise
``argparse.ArgumentTypeError``, which the parser prefixes with the option (``argument --out: ...``); they run
while the command line is parsed, so an output that cannot be written is refused before any work starts.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Iterable
from pathlib import Path

MAX_IMAGE_SIDE = 8192
"""Largest width or height of a rendered image (pixels): an offscreen buffer many renderers refuse beyond it,
and a frame of 8192 x 8192 RGB is 200 MB."""


class UsageError(ValueError):
    """A command line its parser refuses: argparse's message, which names the option, and where to read help."""


class CommandParser(argparse.ArgumentParser):
    """An ``argparse.ArgumentParser`` whose errors raise :class:`UsageError` instead of printing the usage and
    exiting, so that a caller prints them in its own one-line style. Subcommands' parsers are of the same class
    (argparse builds them with their parent's class), so every level refuses alike; ``--help`` still prints
    and exits."""

    def error(self, message: str):
        raise UsageError(f"{message} (see '{self.prog} --help')")


def output_file(text: str) -> str:
    """``type=`` of an option naming a file to write: ``text`` unchanged once its folder exists and is writable
    and it does not name a folder, checked as the command line is parsed (before any compute).

    Raises:
      argparse.ArgumentTypeError: an empty name or one with a NUL, a folder, or a missing, non-folder or
        read-only parent folder.
    """
    _writable_folder(_file_name(text).parent, text)
    return text


def output_folder(text: str) -> str:
    """``type=`` of an option naming a folder to write into (created with its parents): ``text`` unchanged once
    it is a folder or can be made one, checked as the command line is parsed (before any compute).

    Raises:
      argparse.ArgumentTypeError: an empty name or one with a NUL, an existing file, or a nearest existing
        ancestor that is not a writable folder.
    """
    _named(text, "folder")
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a file, not a folder")
    _creatable_folder(path, text)
    return text


def output_file_in_new_folder(text: str) -> str:
    """``type=`` of an option naming a file to write whose writer makes its folder (with parents), e.g. a sweep
    file exported into a ``sweeps/`` folder that does not exist yet: :func:`output_file`'s checks, except that
    the folder may be missing as long as it can be made.

    Raises:
      argparse.ArgumentTypeError: an empty name or one with a NUL, a folder, or a nearest existing ancestor that
        is not a writable folder.
    """
    _creatable_folder(_file_name(text).parent, text)
    return text


def _named(text: str, what: str) -> None:
    """Refuse an output name that no file system takes: empty, blank, or holding a NUL character."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"needs a {what} name, got {text!r}")
    if "\x00" in text:
        raise argparse.ArgumentTypeError(f"a {what} name cannot hold a NUL character, got {text!r}")


def _file_name(text: str) -> Path:
    """``text`` as the path of a file to write; refused when no file system takes the name (:func:`_named`) or
    it names a folder (an existing one, or a name ending in a separator, ``.`` or ``..``)."""
    _named(text, "file")
    path = Path(text)
    if path.is_dir() or text.replace(os.sep, "/").split("/")[-1] in ("", ".", ".."):
        raise argparse.ArgumentTypeError(f"{text!r} is a folder; give a file name in it")
    return path


def _writable_folder(folder: Path, path: str) -> None:
    """Refuse ``path`` unless ``folder`` (its parent) is an existing folder this process may create files in."""
    if not folder.is_dir():
        why = "is not a folder" if folder.exists() else "does not exist"
        raise argparse.ArgumentTypeError(f"no folder for {path!r}: {str(folder)!r} {why}")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"cannot write {path!r}: no permission to write in {str(folder)!r}")


def _creatable_folder(folder: Path, path: str) -> None:
    """Refuse ``path`` unless ``folder`` exists or can be made: its nearest existing ancestor is a folder this
    process may create entries in."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():  # an ancestor is a file (or a dangling link)
        raise argparse.ArgumentTypeError(f"no folder for {path!r}: {str(existing)!r} is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"cannot write {path!r}: no permission to write in {str(existing)!r}")


def positive_int(text: str) -> int:
    """``type=`` of a count of at least 1 (steps, frames, robots).

    Raises:
      argparse.ArgumentTypeError: not an integer, or below 1.
    """
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or value < 1:
        raise argparse.ArgumentTypeError(f"takes an integer >= 1, got {text!r}")
    return value


def positive_ints(text: str) -> tuple[int, ...]:
    """``type=`` of comma-separated counts of at least 1, e.g. batch sizes ``1,64,1024``.

    Raises:
      argparse.ArgumentTypeError: an item that is not an integer >= 1, quoting the whole value.
    """
    try:
        return tuple(positive_int(v) for v in text.split(","))
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"takes comma-separated integers >= 1, e.g. 1,64,1024, got {text!r}") from None


def names_of(text: str, known: Iterable[str], what: str) -> list[str]:
    """A comma-separated list of some of ``known``, for a ``type=`` function that fixes ``known`` and ``what``
    (e.g. ``names_of(text, FAMILIES, "terrain families")``).

    Raises:
      argparse.ArgumentTypeError: an empty list or a name not in ``known``, naming them and the known ones.
    """
    known = list(known)
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown {what} {unknown}; known: {', '.join(known)}")
    return names


def image_size(text: str) -> tuple[int, int]:
    """``type=`` of an image size ``WIDTHxHEIGHT`` in pixels, e.g. ``480x320``: ``(width, height)``, each in
    ``[1, MAX_IMAGE_SIDE]``.

    Raises:
      argparse.ArgumentTypeError: not two integers joined by ``x``, or a side out of range.
    """
    parts = text.strip().lower().split("x")
    try:
        width, height = (int(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"takes WIDTHxHEIGHT in pixels, e.g. 480x320, got {text!r}") from None
    if not (1 <= width <= MAX_IMAGE_SIDE and 1 <= height <= MAX_IMAGE_SIDE):
        raise argparse.ArgumentTypeError(f"takes a width and height in 1..{MAX_IMAGE_SIDE} pixels, got {text!r}")
    return width, height


def assignments(items: Iterable[str] | None, example: str) -> dict[str, str]:
    """``["a.b=1.5", ...]`` as ``{"a.b": "1.5", ...}`` (names stripped, values as written; a later item wins).

    Raises:
      ValueError: an item without ``=`` or without a name, quoting it and ``example`` (a valid item).
    """
    out: dict[str, str] = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"--set takes NAME=VALUE, e.g. {example}; got {item!r}")
        out[name.strip()] = value
    return out


def number_assignments(items: Iterable[str] | None, names: Iterable[str], example: str) -> dict[str, float]:
    """:func:`assignments` whose names must be among ``names`` and whose values must be finite numbers (floats).

    Raises:
      ValueError: a malformed item, an unknown name (listing ``names``), or a value that is not a number or
        not finite (``nan``, ``inf``, ``1e999``: no robot leaf takes one), quoting the item.
    """
    known = list(names)
    out: dict[str, float] = {}
    for name, value in assignments(items, example).items():
        if name not in known:
            raise ValueError(f"--set '{name}={value}': {name!r} is not one of {known}")
        try:
            out[name] = float(value)
        except ValueError:
            raise ValueError(f"--set '{name}={value}': {value!r} is not a number") from None
        if not math.isfinite(out[name]):
            raise ValueError(f"--set '{name}={value}': {name} takes a finite number, got {value!r}")
    return out
