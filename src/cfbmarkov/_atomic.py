"""Atomic file output: write to a temporary name beside the target, then rename.

Every writer of the package (trajectory files, models, reports, figures) goes through
:func:`temporary_path` and :func:`publish`, or the context manager :func:`atomic_path` that
pairs them, so that a failed or interrupted writer never leaves a half-written output
under the final name.
"""

from __future__ import annotations

import contextlib
import functools
import os
import re
import secrets
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Iterator

from cfbmarkov import _interrupt
from cfbmarkov._names import helper_stem
from cfbmarkov.errors import InputError


def temporary_path(target: str | os.PathLike, suffix: str = "") -> Path:
    """Create an empty temporary file beside ``target`` and return its path.

    Parameters
    ----------
    target : str or os.PathLike
        The final output path; its folder is created if missing.
    suffix : str
        Appended after ``.tmp`` (e.g. ``".png"`` for writers that look at the extension).

    Returns
    -------
    pathlib.Path
        A hidden file ``.<name>.<random>.tmp<suffix>`` in the target's folder (same file
        system, so the final rename is atomic).
    """
    target = Path(target)
    catch_late_write_failures()
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{helper_stem(target.name)}.",
                                   suffix=".tmp" + suffix, dir=target.parent)
    except OSError as exc:
        raise write_error(exc, target) from None
    try:
        try:
            os.fchmod(fd, file_mode())      # mkstemp makes 0600 files: give the umask's mode
        except (OSError, AttributeError):   # pragma: no cover - no fchmod (Windows)
            pass
    except BaseException:               # Ctrl-C here: the caller never learns the name
        os.close(fd)
        discard(tmp)
        raise
    os.close(fd)
    return Path(tmp)


def file_mode(folder: bool = False) -> int:
    """The mode a new file (``0o666``) or folder (``0o777``) gets under the current umask.

    Parameters
    ----------
    folder : bool, optional
        For a folder.

    Returns
    -------
    int
    """
    mask = os.umask(0o022)
    os.umask(mask)
    return (0o777 if folder else 0o666) & ~mask


_HDF5_ERRNO = re.compile(r"errno = (\d+)")

#: set once an HDF5 write has failed in this process: the HDF5 library may then crash when
#: the interpreter ends, so the command line leaves with os._exit (see cfbmarkov.cli.main)
HDF5_WRITE_FAILED = False
#: write failures HDF5 reported where Python could not raise them (freeing a dataset)
_LATE_FAILURES: list[BaseException] = []


def error_number(exc: BaseException) -> int | None:
    """The errno of an OSError, or the one HDF5 quotes in the text of an h5py error."""
    number = getattr(exc, "errno", None)
    if isinstance(number, int) and number:
        return number
    match = _HDF5_ERRNO.search(str(exc))
    return int(match.group(1)) if match else None


#: the words of an HDF5 error raised while reading (h5py's "Unable to synchronously read
#: data (...)", "Can't read data", "Unable to synchronously open object (...)")
_HDF5_READ = re.compile(r"(?i)\b(read|open object|get|iterate|determine|decompress|"
                        r"inflate|filter)\b")


def is_write_failure(exc: BaseException) -> bool:
    """Whether ``exc`` is a failed write: an OSError, or an h5py error whose text names an
    errno or a failed write; not an HDF5 error of reading an input (a damaged file), which
    names no errno and says it was reading."""
    if isinstance(exc, OSError):
        return not (exc.errno is None and error_number(exc) is None
                    and _HDF5_READ.search(str(exc)) and "write" not in str(exc).lower())
    return isinstance(exc, RuntimeError) and (
        error_number(exc) is not None or "write failed" in str(exc))


def write_error(exc: BaseException, target: str | os.PathLike) -> InputError:
    """The one-line error for a write of ``target`` that failed with ``exc``.

    Parameters
    ----------
    exc : BaseException
        An OSError, or an h5py OSError/RuntimeError that quotes an errno.
    target : str or os.PathLike
        The output being written.

    Returns
    -------
    InputError
        ``"<target>: cannot write (No space left on device)"`` and the like.
    """
    global HDF5_WRITE_FAILED
    number = error_number(exc)
    if "h5py" in type(exc).__module__ or _HDF5_ERRNO.search(str(exc)) or isinstance(
            exc, RuntimeError):
        HDF5_WRITE_FAILED = True
    if number is not None:
        cause = os.strerror(number)
    else:
        cause = (getattr(exc, "strerror", None) or str(exc).splitlines()[0]
                 if str(exc) else type(exc).__name__)
    return InputError(f"{target}: cannot write ({cause})")


@contextlib.contextmanager
def writing(target: str | os.PathLike):
    """Context manager: a failed write in the body (OSError, or an h5py error quoting an
    errno: no space left, file too large, permission denied, read-only file system ...)
    becomes one :class:`~cfbmarkov.errors.InputError` naming ``target`` and the cause.

    Parameters
    ----------
    target : str or os.PathLike
        The output being written, named in the message.
    """
    try:
        yield
        late = late_write_failure()
    except InputError:
        raise
    except (OSError, RuntimeError) as exc:
        if not is_write_failure(exc):
            raise
        raise write_error(exc, target) from None
    if late is not None:
        raise write_error(late, target) from None


@contextlib.contextmanager
def h5_file(path: str | os.PathLike, target: str | os.PathLike):
    """``h5py.File(path, "w")`` as a context manager that maps a failed write to one
    InputError naming ``target``, and then leaves the file unclosed (HDF5 may crash when it
    closes a file whose writes failed; the command line ends with os._exit)."""
    import h5py

    try:
        f = h5py.File(path, "w")
    except (OSError, RuntimeError) as exc:
        raise write_error(exc, target) from None
    try:
        yield f
        late = late_write_failure()
        if late is None:
            f.close()
    except (OSError, RuntimeError) as exc:
        if not is_write_failure(exc):
            f.close()
            raise
        late = exc
    except BaseException:
        f.close()
        raise
    if late is not None:
        _UNCLOSED.append(f)
        raise write_error(late, target) from None


_UNCLOSED: list = []


def write_method(method):
    """Method decorator for a writer of one output: a failed write in the method (no space
    left, file too large, ...), or one HDF5 reported late (:func:`late_write_failure`),
    calls the writer's ``_fail()`` (which discards the partial output) and becomes one
    :class:`~cfbmarkov.errors.InputError` naming the writer's ``path`` and the cause.

    Parameters
    ----------
    method : callable
        A method of an object with a ``path`` and a ``_fail()`` method.

    Returns
    -------
    callable
        The wrapped method.
    """
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            result = method(self, *args, **kwargs)
            late = late_write_failure()
        except (OSError, RuntimeError) as exc:
            if not is_write_failure(exc):
                raise
            late = exc
        if late is not None:
            self._fail()
            raise write_error(late, self.path) from None
        return result
    return wrapper


def late_write_failure() -> BaseException | None:
    """The first write failure HDF5 reported while freeing an object (where Python could
    not raise it), once; None if there was none."""
    if _LATE_FAILURES:
        exc = _LATE_FAILURES[0]
        _LATE_FAILURES.clear()
        return exc
    return None


def _late_failure(exc) -> bool:
    """Record ``exc`` if it is an HDF5 write failure reported while freeing an object."""
    global HDF5_WRITE_FAILED
    if exc is None or not isinstance(exc, (OSError, RuntimeError)) or not (
            "write failed" in str(exc) or "decrement id ref count" in str(exc)):
        return False
    HDF5_WRITE_FAILED = True
    if not _LATE_FAILURES:
        _LATE_FAILURES.append(exc)
    return True


def _unraisable(hook):
    def handle(info):
        if not _late_failure(info.exc_value):
            hook(info)
    handle.cfbmarkov = True
    return handle


def _excepthook(hook):
    # h5py (Cython) prints a failure in a destructor through sys.excepthook, then as
    # unraisable: both are recorded, not printed
    def handle(exc_type, exc, tb):
        if not _late_failure(exc):
            hook(exc_type, exc, tb)
    handle.cfbmarkov = True
    return handle


def catch_late_write_failures() -> None:
    """Route HDF5 write failures raised while freeing objects (printed by Python as
    "Exception ignored in ...", thousands of times on a full disk) to
    :func:`late_write_failure` instead of stderr. Idempotent."""
    if not getattr(sys.unraisablehook, "cfbmarkov", False):
        sys.unraisablehook = _unraisable(sys.unraisablehook)
    if not getattr(sys.excepthook, "cfbmarkov", False):
        sys.excepthook = _excepthook(sys.excepthook)


def publish(tmp: str | os.PathLike, target: str | os.PathLike) -> Path:
    """Move the finished temporary file ``tmp`` onto ``target`` (atomic rename).

    Parameters
    ----------
    tmp : str or os.PathLike
        The finished temporary file (from :func:`temporary_path`).
    target : str or os.PathLike
        The final name; an existing file of that name is replaced.

    Returns
    -------
    pathlib.Path
        ``target``.

    Raises
    ------
    InputError
        If the rename fails (the temporary file is removed first).
    KeyboardInterrupt
        If Ctrl-C was pressed while the output was written, even where the interrupt was
        swallowed (:mod:`cfbmarkov._interrupt`; the temporary file is removed).
    """
    if _interrupt.requested:          # Ctrl-C swallowed on the way: never publish
        Path(tmp).unlink(missing_ok=True)
        raise KeyboardInterrupt
    try:
        os.replace(tmp, target)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise write_error(exc, target) from None
    return Path(target)


def discard(tmp: str | os.PathLike) -> None:
    """Remove a temporary file if it is still there.

    Parameters
    ----------
    tmp : str or os.PathLike
        The temporary file; nothing happens if it no longer exists.
    """
    with contextlib.suppress(OSError):
        Path(tmp).unlink(missing_ok=True)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike, suffix: str = ""):
    """Yield a temporary path beside ``target``; rename it onto ``target`` on success.

    On any exception the temporary file is removed and ``target`` is left untouched, so a
    failed or interrupted writer never leaves a half-written output file.

    Parameters
    ----------
    target : str or os.PathLike
        The file to write; its folder is created if needed.
    suffix : str, optional
        Added after ``.tmp`` to the temporary name (e.g. ``.png`` for tools that look at it).

    Yields
    ------
    pathlib.Path
        The temporary path to write to.

    Raises
    ------
    InputError
        If the final rename fails.
    """
    tmp = temporary_path(target, suffix)
    try:
        with writing(target):
            yield tmp
    except BaseException:
        discard(tmp)
        raise
    publish(tmp, target)


def write_text_atomic(target: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``target`` atomically (see :func:`atomic_path`).

    Parameters
    ----------
    target : str or os.PathLike
        The file to write.
    text : str
        Its content.

    Raises
    ------
    InputError
        If the final rename fails (the target is then left untouched).
    """
    with atomic_path(target) as tmp:
        tmp.write_text(text)


@contextlib.contextmanager
def atomic_folder(output: Path) -> Iterator[Path]:
    """Yield a new temporary sibling folder ``<output>.tmp-XXXX``; on success it replaces
    ``output`` (a folder output published whole). On any error, an interrupt included, the
    temporary folder and the parent folders created for it are removed, and a previous
    ``output`` is left as it was.

    Parameters
    ----------
    output : pathlib.Path
        The folder to publish.

    Yields
    ------
    pathlib.Path
        The temporary folder to fill.

    Raises
    ------
    InputError
        If the temporary folder cannot be created, or filling or renaming it fails with an
        OS error.
    """
    new_parents = [p for p in output.absolute().parents if not p.exists()]
    try:
        output.parent.mkdir(parents=True, exist_ok=True)
        tmp = _new_folder(output.parent, f"{helper_stem(output.name)}.tmp-")
    except OSError as exc:
        _remove_folders(new_parents)
        raise InputError(f"{output}: cannot create ({exc.strerror or exc})") from None
    try:
        try:
            yield tmp
        except OSError as exc:
            raise InputError(f"{output}: export failed ({exc.strerror or exc})") from None
        _replace(tmp, output)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        _remove_folders(new_parents)
        raise


def _new_folder(parent: Path, prefix: str) -> Path:
    """Create a folder ``prefix`` + random hex in ``parent`` (with the umask's permissions,
    unlike tempfile.mkdtemp, so the renamed export is readable as usual)."""
    for _ in range(100):
        path = parent / f"{prefix}{secrets.token_hex(4)}"
        try:
            path.mkdir()
        except FileExistsError:
            continue
        return path
    raise FileExistsError(f"no free temporary name {prefix}XXXX in {parent}")


@contextlib.contextmanager
def _signals_held():
    """SIGINT and SIGTERM held (blocked) during the block, delivered when it ends (the
    calling thread's mask; where signals cannot be masked, the block runs as it is)."""
    import signal

    held = {signal.SIGINT, signal.SIGTERM}
    try:
        previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    except (AttributeError, OSError, ValueError):
        yield
        return
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _replace(tmp: Path, output: Path) -> None:
    """Move the complete folder ``tmp`` onto ``output``; a previous export there is moved
    aside first and deleted only once the new one is in place (put back on failure)."""
    old = None
    try:
        # the two renames are not cut apart by Ctrl-C or SIGTERM (held until both are
        # done): between them the previous output lies aside and NAME is missing
        with _signals_held():
            if output.is_dir():
                old = _new_folder(output.parent, f"{helper_stem(output.name)}.old-")
                os.replace(output, old)   # rename onto the empty folder
            os.replace(tmp, output)
    except OSError as exc:
        if old is not None and not output.exists():
            with contextlib.suppress(OSError):
                os.replace(old, output)
                old = None
        if old is not None and not any(old.iterdir()):
            old.rmdir()
            old = None
        raise InputError(f"{output}: cannot write ({exc.strerror or exc})") from None
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _remove_folders(folders: list[Path]) -> None:
    for folder in folders:  # deepest first
        with contextlib.suppress(OSError):
            folder.rmdir()
