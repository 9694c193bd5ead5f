"""The one atomic file writer of the application: readers see the old file or the whole new one.

:func:`atomic_write` opens a temporary file in the target's folder and, when the ``with``
block ends without an error, flushes it to disk and renames it over the target
(:func:`os.replace`, atomic on one file system); on an error the temporary file is removed
and the target is untouched. :func:`write_json_atomic` is the JSON case (the protocol's run
files, ``results.json``).
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

__all__ = ["atomic_write", "write_json_atomic", "default_cache_dir"]


@contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
    """Write ``path`` through a temporary file that replaces it only when the block succeeds.

    Args:
        path: the file to write; its folder is created.
        mode: ``"w"`` (text) or ``"wb"`` (bytes).

    Example:
        >>> import tempfile
        >>> folder = Path(tempfile.mkdtemp())
        >>> with atomic_write(folder / "a.txt") as handle:
        ...     _ = handle.write("whole")
        >>> (folder / "a.txt").read_text(), sorted(p.name for p in folder.iterdir())
        ('whole', ['a.txt'])
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def write_json_atomic(path: str | os.PathLike[str], obj: Any) -> None:
    """Write ``obj`` as JSON (indented by 2) to ``path`` with :func:`atomic_write`.

    Example:
        >>> import tempfile
        >>> target = Path(tempfile.mkdtemp()) / "sub" / "unit.json"
        >>> write_json_atomic(target, {"mse": 0.5})
        >>> json.loads(target.read_text())
        {'mse': 0.5}
    """
    with atomic_write(path) as handle:
        json.dump(obj, handle, indent=2)


def default_cache_dir() -> Path:
    """``$EVENT_TRANSFORMS_CACHE``, else ``$XDG_CACHE_HOME/event-transforms``, else
    ``~/.cache/event-transforms``."""
    if os.environ.get("EVENT_TRANSFORMS_CACHE"):
        return Path(os.environ["EVENT_TRANSFORMS_CACHE"])
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]) / "event-transforms"
    return Path.home() / ".cache" / "event-transforms"
