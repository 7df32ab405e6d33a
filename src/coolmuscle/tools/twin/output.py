"""Files the twin writes (reports, plots, machine files): checked before any work is
done, written whole or not at all (a temporary file in the same folder, then renamed)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from ..cli.usage import UsageError

__all__ = ["check_output", "write_atomic"]


def check_output(path: Path, what: str, suffixes: tuple[str, ...]) -> None:
    """Refuse (UsageError, exit 2) a path whose extension is not one of ``suffixes`` or
    whose folder does not exist, before anything runs."""
    if path.suffix.lower() not in suffixes:
        raise UsageError(f"{what} {path}: the extension decides the format; one of "
                         f"{', '.join(suffixes)}")
    folder = path.parent
    if not folder.is_dir():
        raise UsageError(f"{what} {path}: no folder {folder}")
    if path.is_dir():
        raise UsageError(f"{what} {path}: a folder, not a file")


def write_atomic(path: Path, data: bytes) -> Path:
    """Write ``data`` to ``path``: whole or not at all."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
