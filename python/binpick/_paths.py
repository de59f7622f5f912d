"""The files a user names: what binpick says when one is not there (and which file of a close
name they may have meant) and when one is there but empty. Every reader of a user's file checks
it here before reading it."""

from __future__ import annotations

import difflib
import os
from pathlib import Path
from typing import Any, Optional

from .errors import MeshFileError, MeshFileNotFoundError

#: A folder with more entries than this is not searched for a close name (the search is linear).
MAX_NAMES_SEARCHED = 10_000


def close_match(path: Any) -> Optional[str]:
    """The existing path whose names are nearest those of the missing ``path``: each part of it
    that does not exist replaced by the closest name in its folder (:func:`difflib.get_close_matches`,
    ignoring case); None when ``path`` exists or a missing part has no close name."""
    p = Path(os.fspath(path))
    current = Path(p.anchor) if p.is_absolute() else Path()
    changed = False
    for part in p.parts[1:] if p.is_absolute() else p.parts:
        candidate = current / part
        if not os.path.lexists(candidate):
            named = _close_name(current, part)
            if named is None:
                return None
            candidate, changed = current / named, True
        current = candidate
    return str(current) if changed else None


def _close_name(folder: Path, name: str) -> Optional[str]:
    try:
        with os.scandir(folder) as entries:
            names = [e.name for _, e in zip(range(MAX_NAMES_SEARCHED + 1), entries)]
    except (OSError, ValueError):
        return None
    if len(names) > MAX_NAMES_SEARCHED:
        return None
    lowered: dict[str, str] = {}
    for n in sorted(names):
        lowered.setdefault(n.lower(), n)
    found = difflib.get_close_matches(name.lower(), list(lowered), n=1, cutoff=0.6)
    return lowered[found[0]] if found else None


def no_such_file(path: Any, what: str, *, folder: bool = False, fix: str = "") -> str:
    """The message for a ``path`` that does not exist, the ``what`` (the scene file, the cell file)
    that it should have been, ``fix`` (what to do otherwise) and, where one is found
    (:func:`close_match`), the path of a close name: ``did you mean …?``."""
    close = close_match(path)
    text = f"{os.fspath(path)}: no such {'folder' if folder else 'file'}, the {what} does not exist"
    text += f"; {fix}" if fix else ""
    return text + (f"; did you mean {close}?" if close else "")


def check_file(path: Any, what: str, *, give: str = "", fix_empty: str = "write it again") -> None:
    """Raises for a ``path`` binpick cannot read as the file ``what``: MeshFileNotFoundError when it does
    not exist (:func:`no_such_file`), MeshFileError for a folder (naming what to ``give``) and for an
    empty file (0 bytes, which no scene or mesh format is: whatever wrote it stopped before writing
    anything), naming ``fix_empty``."""
    p = os.fspath(path)
    try:
        size = os.stat(p).st_size
    except FileNotFoundError:
        raise MeshFileNotFoundError(no_such_file(p, what)) from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL byte in the path
        raise MeshFileNotFoundError(f"{p}: cannot open the {what} ({getattr(exc, 'strerror', None) or exc})") from None
    if os.path.isdir(p):
        raise MeshFileError(f"{p}: is a folder, not a {what}" + (f"; give {give}" if give else ""))
    if size == 0:
        raise MeshFileError(f"{p}: the {what} is empty (0 bytes); {fix_empty}")
