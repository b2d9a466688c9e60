"""Files written whole or not at all: write to a temporary name beside the target, then rename.

The one implementation of write-to-temp-then-rename for every package (it lives in the
lowest one, ``geometry``, so that ``fem``, ``calibration`` and ``validation`` may all import
it under the arrows of docs/architecture.md). The temporary name is fresh but not created
here: the writer creates it, so the file gets the permissions of any new file (the process
umask), not mkstemp's 0600. ``os.replace`` is atomic within one file system, so a reader sees
the old file or the new one, never a part; a failed or interrupted write leaves the target
as it was and removes the temporary.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import uuid
from pathlib import Path
from typing import Iterator

__all__ = ["atomic_path"]


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, suffix: str | None = None) -> Iterator[Path]:
    """A fresh temporary path beside ``path``, renamed onto ``path`` when the block succeeds,
    removed otherwise (a file or a folder).

    suffix: the temporary's last suffix (default ``path``'s own, so that writers which pick
    the format from the name still work). An ``OSError`` of the rename or of a writer that
    names no file (ENOSPC from a stream) is raised with ``path`` as its file name.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{uuid.uuid4().hex[:12]}.tmp{path.suffix if suffix is None else suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as error:
        _remove(tmp)
        if error.errno is None or error.filename is not None:
            raise
        raise type(error)(error.errno, error.strerror, str(path)) from error
    except BaseException:
        _remove(tmp)
        raise


def _remove(tmp: Path) -> None:
    if tmp.is_dir() and not tmp.is_symlink():
        shutil.rmtree(tmp, ignore_errors=True)
    else:
        tmp.unlink(missing_ok=True)
