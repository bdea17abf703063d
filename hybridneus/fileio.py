"""Atomic file output: nothing half-written is ever left under the final name."""

from __future__ import annotations

import contextlib
import glob
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from hybridneus.errors import OutputError


def _mode(base: int) -> int:
    """``base`` under the process umask: mkstemp/mkdtemp create 0600/0700 entries, but
    finished outputs should get the modes a plain open()/mkdir() would give them."""
    mask = os.umask(0)
    os.umask(mask)
    return base & ~mask


def check_output(path: str | os.PathLike, folder: bool = False) -> Path:
    """Fail before any work when ``path`` cannot become an output file (or ``folder``):
    a folder (a file) stands there, a file stands where one of its folders should be, or
    the nearest existing folder is not writable. Nothing is created.

    Raises:
        OutputError: naming ``path`` and the fault.
    """
    final = Path(path)
    if final.is_dir() and not folder:
        raise OutputError(f"{final}: is a folder; give a file name")
    if final.exists() and folder and not final.is_dir():
        raise OutputError(f"{final}: is a file; give a folder name")
    fault = creation_fault(final.absolute().parent)
    if fault is not None:
        raise OutputError(f"{final}: cannot be created, {fault}")
    return final


def creation_fault(folder: str | os.PathLike) -> str | None:
    """Why ``folder`` (existing or not) could not be created or written into, e.g.
    ``"/data is a file"`` or ``"/data is not writable"``; ``None`` when it could. Judged on
    its nearest existing ancestor; nothing is created."""
    parent = Path(folder)
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        return f"{parent} is a file"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"{parent} is not writable"
    return None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def remove_orphans(folder: Path, prefix: str, suffix: str) -> list[Path]:
    """Delete the temporaries (``<prefix><pid>-<random><suffix>``) that killed writers left
    in ``folder``: those whose process is gone. Writers still running keep theirs."""
    removed = []
    for p in folder.glob(f"{glob.escape(prefix)}*{glob.escape(suffix)}"):
        pid = p.name[len(prefix):].split("-", 1)[0]
        if not pid.isdigit() or _alive(int(pid)):
            continue
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
        removed.append(p)
    return removed


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only on success.

    The temporary file keeps the final suffix (or ``suffix``) so that libraries that pick a
    format from the extension (numpy, OpenCV, trimesh) still work. On an exception the
    temporary file is removed and ``path`` is left untouched.

    Example:
        >>> with atomic_path("mesh.ply") as tmp:  # doctest: +SKIP
        ...     mesh.export(tmp)
    """
    final = check_output(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    ext = suffix if suffix is not None else "".join(final.suffixes[-1:])
    remove_orphans(final.parent, f".{final.stem}.", f".tmp{ext}")
    fd, tmp_name = tempfile.mkstemp(prefix=f".{final.stem}.{os.getpid()}-", suffix=f".tmp{ext}",
                                    dir=final.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.chmod(tmp, _mode(0o666))
        os.replace(tmp, final)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary directory beside ``path``; move it onto ``path`` only on success.

    An existing directory at ``path`` is replaced only after the new one is complete.
    """
    final = check_output(path, folder=True)
    final.parent.mkdir(parents=True, exist_ok=True)
    remove_orphans(final.parent, f".{final.name}.", ".tmp")
    shutil.rmtree(final.with_name(f".{final.name}.old"), ignore_errors=True)  # a killed swap's
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.{os.getpid()}-", suffix=".tmp",
                                dir=final.parent))
    try:
        yield tmp
        os.chmod(tmp, _mode(0o777))
        if final.exists():
            old = final.with_name(f".{final.name}.old")
            shutil.rmtree(old, ignore_errors=True)
            os.replace(final, old)
            os.replace(tmp, final)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
