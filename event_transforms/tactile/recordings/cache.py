"""The recordings' cache: content hashes of the files, cache keys, atomic writes, unreadable
files named and rebuilt."""

from __future__ import annotations

__all__ = ["content_hash"]

import hashlib
import json
import os
import warnings
from pathlib import Path
from typing import Any

import torch

_CACHE_FORMAT = 1


def content_hash(path: str | os.PathLike[str], *, chunk: int = 2**22) -> str:
    """SHA-256 of a file's bytes (hex).

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "a.txt"
        >>> _ = path.write_bytes(b"abc")
        >>> content_hash(path)[:12]
        'ba7816bf8f01'
    """
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while block := handle.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def _key(description: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(description, sort_keys=True, default=str).encode()).hexdigest()[:24]


def _cache_dir(cache: str | os.PathLike[str] | None) -> Path:
    from .._files import default_cache_dir

    return Path(cache) if cache is not None else default_cache_dir() / "recordings"


def _save_atomic(obj: object, path: Path) -> None:
    from .._files import atomic_write

    with atomic_write(path, "wb") as handle:
        torch.save(obj, handle)


def _load_cached(path: Path) -> dict[str, Any] | None:
    """A cache file's contents, or ``None`` (the file named, deleted) when it cannot be read."""
    if not path.exists():
        return None
    try:
        data = torch.load(path, mmap=True, weights_only=True)
        if not isinstance(data, dict) or data.get("format") != _CACHE_FORMAT:
            raise ValueError("not a recording cache file of this version")
        return data
    except Exception as error:  # noqa: BLE001 - any unreadable file is rebuilt, named
        warnings.warn(f"discarded the unreadable cache file {path} ({type(error).__name__}: "
                      f"{str(error).splitlines()[0] if str(error) else ''}); rebuilding it", stacklevel=3)
        path.unlink(missing_ok=True)
        return None


def _hashes(root: Path, table: list[Any], cache: Path) -> dict[int, tuple[str, str | None]]:
    """Content hashes of each row's files (a file's hash is remembered by its size and mtime)."""
    memo_path = cache / "hashes.json"
    try:
        memo = json.loads(memo_path.read_text()) if memo_path.exists() else {}
        if not isinstance(memo, dict):
            memo = {}
    except (OSError, ValueError):
        memo = {}
    changed = False

    def digest(path: Path) -> str:
        nonlocal changed
        stat = path.stat()
        key = f"{path.resolve()}:{stat.st_size}:{stat.st_mtime_ns}"
        if key not in memo:
            memo[key] = content_hash(path)
            changed = True
        return memo[key]

    out = {r.row: (digest(r.events), digest(r.force) if r.force is not None else None) for r in table}
    if changed:
        from ..training import write_json_atomic

        try:
            write_json_atomic(memo_path, memo)
        except OSError:
            pass
    return out
