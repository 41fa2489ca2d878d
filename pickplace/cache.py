"""The user's cache folder: measurements kept on disk so that a second process reuses them.

What is measured once per robot (a gripper's calibration, the chosen home posture, the rows of
``pickplace robots``) takes seconds for a published robot, in every process — every sweep worker
would pay it. Each is kept as a JSON file in :func:`cache_dir` — ``$PICKPLACE_CACHE_DIR``, else
``$XDG_CACHE_HOME/pickplace``, else ``~/.cache/pickplace`` — under a name whose key (computed
by the caller) digests everything the measurement depends on: the content of the files
involved and the source of the code that measures (:func:`source_digest`), so an edit to any
of them measures again.

JSON, not pickle: a cache file is data. A file that cannot be read or parsed reads as absent
(the caller measures again and overwrites it); a folder that cannot be written is skipped
silently — the cache only saves time.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

CACHE_ENV = "PICKPLACE_CACHE_DIR"
"""Environment variable naming the cache folder (tests point it at a temporary one)."""

_PACKAGE = Path(__file__).resolve().parent


def cache_dir() -> Path:
    """The folder cache files are kept in (see the module docstring)."""
    explicit = os.environ.get(CACHE_ENV)
    if explicit:
        return Path(explicit)
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / "pickplace"


def source_digest(modules: Iterable[str]) -> str:
    """SHA-256 of the source of ``modules``, paths relative to the package
    (``"robot/calibration.py"``): part of a key, so that changed code measures again."""
    digest = hashlib.sha256()
    for name in modules:
        digest.update(name.encode())
        digest.update((_PACKAGE / name).read_bytes())
    return digest.hexdigest()


_FILE_DIGESTS: dict[Path, tuple[tuple[int, int], str]] = {}


def file_digest(path: Path) -> str | None:
    """SHA-256 of a file's content, or None if it cannot be read. Remembered per process with
    the file's modification time [ns] and size: asked again while neither changed, the file is
    not read again (a published arm's meshes are tens of MB)."""
    try:
        st = path.stat()
        stamp = (st.st_mtime_ns, st.st_size)
        known = _FILE_DIGESTS.get(path)
        if known is not None and known[0] == stamp:
            return known[1]
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None
    _FILE_DIGESTS[path] = (stamp, digest)
    return digest


def read_json(name: str) -> Any | None:
    """The JSON value kept as ``name`` in the cache folder, or None (absent or unreadable)."""
    try:
        return json.loads((cache_dir() / name).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def write_json(name: str, value: Any) -> None:
    """Keep ``value`` as ``name`` in the cache folder: written to a temporary file and renamed,
    so a reader never sees half a file; silently not if the folder cannot be written."""
    path = cache_dir() / name
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as out:
                json.dump(value, out)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError:
        return
