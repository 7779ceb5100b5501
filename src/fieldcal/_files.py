"""Writing files without losing any: never over an input, never a fragment.

Every file fieldcal writes goes through :func:`replacing`: the content is written to a hidden
temporary file in the target's folder (``.<name>.<random>.part``), flushed to disk and renamed
over the target with :func:`os.replace`. A crash, an error half-way or Ctrl-C therefore leaves
the old file or the new one, never a fragment, and the temporary file is removed.

:func:`check_outputs` is what a command asks before any work: no output may be one of its
inputs (compared by file identity, so hard links and symbolic links are caught, not by path),
and an existing output is replaced only when the caller says so (``--force``).

:func:`write_together` writes files that are only right together (the C library's ``.h`` and
``.c``): each is written in full to its temporary file first, so a full disk or an error leaves
every old file as it was; then, holding a lock on the folder (``flock``: a concurrent export waits
its turn) and with Ctrl-C held back, each is renamed into place. Only a power cut between two
renames (microseconds) can leave a mixed pair, and the C library refuses to build one (#error).

:func:`record` collects the files completed while it is active, so a command interrupted after
writing some of its files can say which.
"""

from __future__ import annotations

import contextvars
import os
import secrets
import shutil
import signal
import stat
import threading
from collections.abc import Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager, suppress
from pathlib import Path
from types import FrameType

from .errors import InputError

__all__ = [
    "check_outputs",
    "fsync_folder",
    "make_folder",
    "record",
    "replacing",
    "same_file",
    "write_bytes",
    "write_text",
    "write_together",
]

#: The suffix of a temporary file (``.<name>.<8 hex digits>.part`` beside the target).
TEMP_SUFFIX = ".part"

_DONE: contextvars.ContextVar[list[Path] | None] = contextvars.ContextVar(
    "fieldcal_files_done", default=None
)


def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """Whether ``a`` and ``b`` are the same file on disk (same device and inode).

    Hard links and symbolic links to one file are the same file; a path that does not exist
    is no file's twin.

    Parameters
    ----------
    a, b : str or path

    Returns
    -------
    bool
    """
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def check_outputs(
    outputs: Sequence[str | os.PathLike[str]],
    inputs: Mapping[str, str | os.PathLike[str]],
    *,
    force: bool,
    folders_made: bool = False,
) -> None:
    """Refuse, in one line, outputs that would destroy an input or replace a file unasked.

    Parameters
    ----------
    outputs : sequence of paths
        The files the command will write.
    inputs : mapping of role -> path
        The files it reads (``{"log": "session.csv", "calibration": "cal.json"}``).
    force : bool
        Whether an existing output may be replaced (``--force``). An input is never replaced.
    folders_made : bool
        The caller creates the outputs' folders (``report --png``, ``demo --out``); otherwise a
        missing folder is an error.

    Raises
    ------
    InputError
        An output is an input (by identity), is given twice, is a folder, lies in a folder that
        does not exist, or exists and ``force`` is false.
    """
    seen: dict[Path, str] = {}
    for output in outputs:
        path = Path(output)
        for role, given in inputs.items():
            if same_file(path, given):
                what = (
                    f"is the input {role} itself"
                    if str(path) == str(given)
                    else f"is the same file as the input {role} {given}"
                )
                raise InputError(
                    f"{path}: {what}; write the output to another file (--force never "
                    "replaces an input)"
                )
        key = path.resolve()
        if key in seen:
            raise InputError(f"{path}: given twice as an output; give each output its own file")
        seen[key] = str(path)
        if path.is_dir():
            raise InputError(f"{path}: is a folder; give a file name")
        parent = path.parent
        if parent.exists() and not parent.is_dir():
            raise InputError(f"{path}: {parent} is a file, not a folder; give another path")
        if not folders_made and not parent.is_dir():
            raise InputError(f"{path}: the folder {parent} does not exist; create it first")
        if _special(path):
            continue  # a device or a pipe (/dev/stdout): written into, nothing replaced
        if not force and (path.exists() or path.is_symlink()):
            raise InputError(f"{path} exists; pass --force to replace it")


def _special(path: Path) -> bool:
    """Whether ``path`` is an existing device, pipe or socket rather than a file or folder."""
    try:
        mode = path.stat().st_mode
    except (OSError, ValueError):
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def make_folder(path: str | os.PathLike[str]) -> Path:
    """Create the output folder ``path`` (and its parents) unless it exists; one line naming
    the problem when it cannot be: a file there, or a symbolic link to nowhere.

    Parameters
    ----------
    path : str or path

    Returns
    -------
    Path
    """
    folder = Path(path)
    if folder.is_symlink() and not folder.exists():
        raise InputError(
            f"{folder} is a symbolic link to {os.readlink(folder)}, which does not exist; "
            "create that folder or give another one"
        )
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder} is a file, not a folder; give a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:  # a parent is a file or a dangling link
        raise InputError(f"{folder}: a part of the path is not a folder; give another") from None
    return folder


@contextmanager
def record() -> Iterator[list[Path]]:
    """Collect the files :func:`replacing` completes inside this block (in order).

    Yields
    ------
    list of Path
        Filled as files are completed.
    """
    done: list[Path] = []
    token = _DONE.set(done)
    try:
        yield done
    finally:
        _DONE.reset(token)


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDWR if os.name == "nt" else os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_folder(folder: Path) -> None:
    """Make the rename itself durable (POSIX; other systems have no folder handles)."""
    if os.name != "posix":  # pragma: no cover
        return
    with suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextmanager
def replacing(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path to write; renamed over ``path`` when the block ends without an error.

    The temporary file is created (empty) in ``path``'s folder, so the rename is atomic; a
    symbolic link at ``path`` stays and the file it points to is replaced. A device or a pipe
    (``/dev/stdout``) is written directly: there is no file to replace. The new file keeps
    the permissions of the one it replaces. On any exception, ``KeyboardInterrupt`` included,
    the temporary file is removed and ``path`` is untouched.

    Parameters
    ----------
    path : str or path
        The file to (re)place.

    Yields
    ------
    Path
        The temporary file: write it by name (it may be opened and truncated).
    """
    if _special(Path(path)):  # /dev/stdout, a named pipe: no file to replace, written directly
        yield Path(path)
        return
    target = Path(os.path.realpath(path))
    folder = target.parent
    temp = folder / f".{target.name}.{secrets.token_hex(4)}{TEMP_SUFFIX}"
    try:
        os.close(os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    except FileNotFoundError:
        raise InputError(f"{path}: the folder {folder} does not exist; create it first") from None
    try:
        yield temp
        if target.is_file():
            shutil.copymode(target, temp)
        _fsync(temp)
        os.replace(temp, target)
    except BaseException:
        with suppress(OSError):
            temp.unlink()
        raise
    fsync_folder(folder)
    done = _DONE.get()
    if done is not None:
        done.append(Path(path))


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`replacing`).

    Parameters
    ----------
    path : str or path
    text : str
    """
    with replacing(path) as temp:
        temp.write_text(text, encoding="utf-8")


def write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (:func:`replacing`).

    Parameters
    ----------
    path : str or path
    data : bytes
    """
    with replacing(path) as temp:
        temp.write_bytes(data)


def _write(temp: Path, data: bytes) -> None:
    """Write ``data`` to ``temp`` and flush it to disk (one place a full disk shows)."""
    with open(temp, "wb") as stream:
        stream.write(data)
        stream.flush()
        os.fsync(stream.fileno())


@contextmanager
def _folder_lock(folder: Path) -> Iterator[None]:
    """An exclusive ``flock`` on ``folder`` itself (no lock file is left behind); a no-op where
    folders cannot be locked."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


@contextmanager
def _no_interrupt() -> Iterator[None]:
    """Hold Ctrl-C back until the block ends (then raise it): renames are not cut in half."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []

    def hold(signum: int, frame: FrameType | None) -> None:
        caught.append(signum)

    previous = signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt


def write_together(files: Mapping[str | os.PathLike[str], bytes]) -> None:
    """Write files that belong together: all of them replaced, or none (see the module).

    Parameters
    ----------
    files : mapping of path -> bytes
        The files, in one folder or several (each folder is locked while its files are
        renamed). Symbolic links stay; the files they point to are replaced.
    """
    temps: dict[Path, Path] = {}
    try:
        for path, data in files.items():
            target = Path(os.path.realpath(path))
            temp = target.parent / f".{target.name}.{secrets.token_hex(4)}{TEMP_SUFFIX}"
            temps[target] = temp
            try:
                _write(temp, data)
            except FileNotFoundError:
                raise InputError(
                    f"{path}: the folder {target.parent} does not exist; create it first"
                ) from None
            except OSError as exc:  # a full disk: named by the file the user asked for
                raise OSError(
                    exc.errno, f"{exc.strerror}; no file was replaced", str(path)
                ) from None
        folders = sorted({t.parent for t in temps})
        with _locked(folders), _no_interrupt():
            for target, temp in temps.items():
                if target.is_file():
                    shutil.copymode(target, temp)
                os.replace(temp, target)
    finally:
        for temp in temps.values():
            with suppress(OSError):
                temp.unlink()
    for folder in {t.parent for t in temps}:
        fsync_folder(folder)
    done = _DONE.get()
    if done is not None:
        done.extend(Path(p) for p in files)


@contextmanager
def _locked(folders: Sequence[Path]) -> Iterator[None]:
    """Every folder's lock, taken in a fixed (sorted) order so two writers never deadlock."""
    with ExitStack() as stack:
        for folder in folders:
            stack.enter_context(_folder_lock(folder))
        yield
