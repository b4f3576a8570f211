"""Writing files safely: every output is written to a temporary name beside its
destination and renamed into place, so an interrupted or failed run never
leaves a half-written file; a file that several processes rewrite (a run's
recording) is rewritten under a lock, from an unnamed temporary file.

A destination that is a symbolic link is written through it (the link stays,
its target is replaced, as a shell's ``>`` would write it); one that exists and
is no regular file - a device such as ``/dev/null`` or ``/dev/stdout``, a named
pipe - is written into once the output is complete, never replaced."""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
import stat
import tempfile
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Callable

from .errors import InputError

try:
    import fcntl
except ImportError:  # Windows: no advisory locks; writes stay atomic
    fcntl = None


def check_writable(path: str | Path, what: str = "output", make: bool = True) -> None:
    """Raise InputError, before any work, when a file cannot be written at ``path``
    (its folder cannot be made or written, or it is a folder; a stream, when it is
    not writable); leaves nothing behind but the folders it made - none, without
    ``make``: then the nearest folder that exists is tried instead."""
    try:
        _check_writable(path, what, make)
    except OSError as exc:  # a folder on the way that cannot be entered: even stat fails
        raise InputError(f"cannot write the {what} '{path}': {exc.strerror or exc}") from None


def _check_writable(path: str | Path, what: str, make: bool) -> None:
    path = destination(path)
    if path.is_dir():
        raise InputError(f"the {what} '{path}' is a folder")
    if is_stream(path):
        if not os.access(path, os.W_OK):
            raise InputError(f"cannot write the {what} '{path}': permission denied")
        return
    _check_folder_below(path.parent, path, what, make)


def check_folder(path: str | Path, what: str = "output folder") -> None:
    """Raise InputError, before any work, when files cannot be written into the
    folder ``path`` (it is a file, or neither it nor the folder that would hold it
    can be written); makes nothing."""
    path = Path(path)
    try:
        _check_folder_below(path, path, what, make=False)
    except OSError as exc:
        raise InputError(f"cannot write the {what} '{path}': {exc.strerror or exc}") from None


def _check_folder_below(folder: Path, path: Path, what: str, make: bool) -> None:
    """Whether a file can be written in ``folder`` (made with ``make``, else its
    nearest existing folder is tried); ``path`` and ``what`` name it in the error."""
    above = next((f for f in (folder, *folder.parents) if f.exists()), None)
    if above is not None and not above.is_dir():
        raise InputError(f"cannot write the {what} '{path}': '{above}' is a file, not a folder")
    try:
        if make:
            folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder if make else above):
            pass
    except OSError as exc:
        raise InputError(f"cannot write the {what} '{path}': {exc.strerror or exc}") from None


def destination(path: str | Path) -> Path:
    """The file that writing ``path`` replaces: a symbolic link's target, else ``path``
    (a stream, :func:`is_stream`, as given: opening it follows the links, which
    ``/dev/stdout``'s may not name a path)."""
    path = Path(path)
    if is_stream(path) or not path.is_symlink():
        return path
    return Path(os.path.realpath(path))


def is_stream(path: str | Path) -> bool:
    """Whether ``path`` exists and is neither a regular file nor a folder (a device,
    a named pipe, a socket): written into, it cannot be replaced."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


@contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path in the destination's folder; rename it to ``path``
    when the block succeeds, delete it when it fails. A stream ``path``
    (:func:`is_stream`) gets the temporary file's bytes written into it instead
    (the temporary file then lies in the system's temporary folder)."""
    path = destination(path)
    if is_stream(path):
        with _staged_for_stream(path) as tmp:
            yield tmp
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create folder '{path.parent}': {exc}") from None
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes it private; a plain open would not
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


@contextmanager
def _staged_for_stream(path: Path):
    """A temporary path in the system's temporary folder whose bytes go into the stream
    ``path`` when the block succeeds."""
    fd, tmp = tempfile.mkstemp(prefix=".tendon-taichi.", suffix=path.suffix)
    os.close(fd)
    try:
        yield Path(tmp)
        with open(tmp, "rb") as src, open(path, "wb") as dst:
            shutil.copyfileobj(src, dst)
    finally:
        os.unlink(tmp)


@contextmanager
def locked(path: str | Path, on_wait: Callable[[], None] | None = None):
    """Hold an exclusive lock (flock) on the existing file ``path`` for the block;
    ``on_wait`` is called once if another process holds it. The lock follows the
    name: when the holder replaced the file meanwhile, the new file is locked."""
    path = Path(path)
    if fcntl is None:
        yield
        return
    waited = False
    while True:
        fd = os.open(path, os.O_RDONLY)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                if on_wait is not None and not waited:
                    on_wait()
                waited = True
                fcntl.flock(fd, fcntl.LOCK_EX)
            if os.fstat(fd).st_ino == os.stat(path).st_ino:
                break
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)
    try:
        yield
    finally:
        os.close(fd)  # releases the lock


def replace_with_bytes(path: str | Path, data: bytes) -> None:
    """Replace the file ``path`` by one holding ``data``, atomically: a process
    killed at any moment leaves the old file or the new one. The data go to an
    unnamed file (O_TMPFILE) that gets a name only to be renamed over ``path``
    (elsewhere, a named temporary file); leftovers of killed writers are removed.
    A stream ``path`` (:func:`is_stream`) has ``data`` written into it."""
    path = destination(path)
    if is_stream(path):
        with open(path, "wb") as fh:
            fh.write(data)
        return
    _remove_stale_temporaries(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.{uuid.uuid4().hex[:8]}{path.suffix}")
    fd = _unnamed_file(path.parent)
    unnamed = fd is not None
    if not unnamed:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
        if unnamed:
            _link_unnamed(fd, tmp)
        os.replace(tmp, path)
    finally:
        os.close(fd)
        if tmp.exists():
            tmp.unlink()


def _unnamed_file(folder: Path) -> int | None:
    """A writable O_TMPFILE file in ``folder``, or None where the system or the
    filesystem has none (or /proc, through which it gets its name)."""
    if not hasattr(os, "O_TMPFILE") or not os.path.isdir("/proc/self/fd"):
        return None
    try:
        return os.open(folder, os.O_TMPFILE | os.O_WRONLY, 0o666)
    except OSError as exc:
        if exc.errno in (errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL):
            return None
        raise


def _link_unnamed(fd: int, name: Path) -> None:
    """Give the O_TMPFILE file ``fd`` the name ``name`` (linkat following the
    /proc/self/fd link; os.link calls linkat only when given a dir fd)."""
    folder = os.open(name.parent, os.O_RDONLY)
    try:
        os.link(f"/proc/self/fd/{fd}", name, src_dir_fd=folder, follow_symlinks=True)
    finally:
        os.close(folder)


def _remove_stale_temporaries(path: Path) -> None:
    """Delete the temporary files of :func:`replace_with_bytes` beside ``path``
    whose writer is no longer running."""
    for f in path.parent.glob(f".{path.stem}.*{path.suffix}"):
        parts = f.name[len(path.stem) + 2:].split(".")
        if len(parts) == 3 and parts[0].isdigit() and not _running(int(parts[0])):
            f.unlink(missing_ok=True)


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        pass
    return True


def file_stem(name: str) -> str:
    """``name`` (a scene's or sweep's, from its file) made safe to name one file
    or folder: characters other than letters, digits, ``.``, ``_`` and ``-``
    become ``_`` and leading dots are dropped, so a default output path never
    leaves its folder, makes folders or hides a file."""
    return re.sub(r"[^\w.-]", "_", name).lstrip(".") or "unnamed"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json(data: dict, path: str | Path) -> None:
    """``data`` as indented JSON at ``path``, written atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2) + "\n")
