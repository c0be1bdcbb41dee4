"""Writing files atomically: every file ti_cloth writes (frames, meshes, study tables and plots)
goes to a temporary name beside its target and is renamed when complete, so an interrupted run
never leaves half a file."""

from __future__ import annotations

import errno
from contextlib import contextmanager
from pathlib import Path

from ..errors import OutputError

# what the system says when a file cannot be written where it was asked to be
UNWRITABLE = {errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC), errno.EACCES, errno.EPERM,
              errno.EROFS, errno.EIO, errno.EFBIG}


@contextmanager
def atomic_path(path):
    """Yield a hidden temporary name beside `path` (same extension: writers pick the format
    from it); rename it to `path` when the block succeeds, delete it when it fails. A write
    the system refuses (UNWRITABLE: disk full, no permission, read-only) is an
    errors.OutputError naming `path`; what was at `path` before is left as it was."""
    path = Path(path)
    tmp = temporary_name(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        yield tmp
        tmp.replace(path)
    except OutputError:
        raise
    except OSError as err:
        if err.errno not in UNWRITABLE:
            raise                  # not the target's disk (a frame an MP4 reads went missing)
        raise OutputError(path, err) from err
    finally:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass                   # a folder that cannot be written holds no temporary either


def temporary_name(path: Path) -> Path:
    """The temporary name atomic_path writes `path` under."""
    return path.with_name(f".{path.stem}.tmp{path.suffix}")


def remove_temporaries(folder) -> list[Path]:
    """Delete the temporary files an earlier process killed mid-write (SIGKILL, power loss)
    left in `folder`; returns them."""
    stale = [p for p in Path(folder).glob(".*.tmp*") if p.is_file()
             and temporary_name(p.with_name(p.name[1:].replace(".tmp", "", 1))) == p]
    for p in stale:
        p.unlink(missing_ok=True)
    return stale
