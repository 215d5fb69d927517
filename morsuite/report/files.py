"""Output files written atomically, and only when their bytes change.

Every report file goes through :func:`write_bytes`: the new content is compared
with the file on disk, and an identical file is left alone (its mtime too), so
re-drawing a figure whose data did not change touches nothing; a different one
is written to a temporary file next to the target and renamed over it, so an
interrupted run leaves the old file or the new one, never a mix.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from ..utils import atomic_path

__all__ = ["write_bytes", "write_text", "sha256_file"]


def write_bytes(path, data: bytes) -> bool:
    """Put ``data`` into ``path`` atomically unless it already holds exactly that; True if written."""
    path = Path(path)
    try:
        if path.stat().st_size == len(data) and path.read_bytes() == data:
            return False
    except OSError:
        pass  # absent or unreadable: write it
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(data)
    return True


def write_text(path, text: str) -> bool:
    """:func:`write_bytes` of ``text`` encoded as UTF-8."""
    return write_bytes(path, text.encode("utf-8"))


def sha256_file(path) -> str | None:
    """SHA-256 of the file's bytes, or None when it cannot be read."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None
