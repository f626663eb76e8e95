"""Claiming an output before writing it: one writer at a time, never over an input, never
over a file of another kind unless forced, and the temporaries of dead writers removed.

:func:`claim_output` is the one place every writing verb goes through (the command line
claims each verb's ``-o`` output; :func:`cfbmarkov.simulate.run.simulate` claims its output
and checkpoint folder itself). The lock is an OS advisory lock (``fcntl.flock``) on a hidden
file ``.NAME.lock`` beside the output, held for the life of the claim: the kernel releases it
when the process dies, so a ``kill -9`` leaves no stale lock (the file left behind is reused
and removed by the next writer). Where ``fcntl`` is missing (Windows) the lock file is created
exclusively and holds the writer's pid; it is taken over when that process is gone.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import glob
import json
import os
import re
import shutil
import socket
from pathlib import Path

from cfbmarkov._names import check_output_name, helper_stem, named_output, parts_folder
from cfbmarkov.errors import InputError

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

#: kinds of output: what an existing file must hold to be replaced without --force
KINDS = ("trajectory", "model", "png", "folder")
_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_FORMATS = {"trajectory": "cfbmarkov.trajectories", "model": "cfbmarkov.model"}
#: the ``source`` of a trajectory file that a Monte Carlo prediction wrote: a prediction
#: may replace a prediction, but a simulated or imported run only with ``force``
PREDICTION_SOURCE = "markov-prediction"

#: locks held by this process: lock file -> [fd, count]
_HELD: dict[str, list] = {}


def lock_path(target: str | os.PathLike) -> Path:
    """The lock file of an output: ``.NAME.lock`` beside it (``NAME`` is
    :func:`~cfbmarkov._names.helper_stem` of the output's name)."""
    target = Path(target)
    return target.parent / f".{helper_stem(target.name)}.lock"


def _holder_text(lock: Path) -> str:
    try:
        info = json.loads(lock.read_text() or "{}")
    except (OSError, ValueError):
        info = {}
    if not info:
        return "another process"
    return (f"pid {info.get('pid', '?')} on {info.get('host', '?')} "
            f"(cfbmarkov {info.get('verb', '?')} since {info.get('since', '?')})")


def _busy(target: Path, lock: Path) -> InputError:
    return InputError(f"{target}: being written by {_holder_text(lock)}; wait for it to "
                      "end or choose another output")


def _acquire(target: Path, verb: str) -> None:
    lock = lock_path(target)
    key = str(lock.absolute())
    if key in _HELD:
        _HELD[key][1] += 1
        return
    info = json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "verb": verb,
                       "since": _dt.datetime.now().astimezone().isoformat(timespec="seconds")})
    for _ in range(50):
        try:
            if fcntl is None:  # pragma: no cover - Windows
                fd = _acquire_exclusive(target, lock)
            else:
                fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as exc:
            raise InputError(f"{target}: cannot write in {target.parent} "
                             f"({exc.strerror or exc})") from None
        if fcntl is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                os.close(fd)
                raise _busy(target, lock) from None
            try:        # the previous holder may have removed the file meanwhile
                same = os.path.samestat(os.fstat(fd), os.stat(lock))
            except OSError:
                same = False
            if not same:
                os.close(fd)
                continue
        os.ftruncate(fd, 0)
        os.write(fd, info.encode())
        _HELD[key] = [fd, 1]
        return
    raise _busy(target, lock)  # pragma: no cover


def _acquire_exclusive(target: Path, lock: Path) -> int:  # pragma: no cover - Windows
    """Lock without fcntl: create the lock file exclusively; take over a dead holder's."""
    while True:
        try:
            return os.open(lock, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            try:
                info = json.loads(lock.read_text() or "{}")
            except (OSError, ValueError):
                info = {}
            if info.get("host") == socket.gethostname() and not _alive(int(info.get("pid", 0))):
                lock.unlink(missing_ok=True)
                continue
            raise _busy(target, lock) from None


def _alive(pid: int) -> bool:  # pragma: no cover - Windows
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _release(target: Path) -> None:
    lock = lock_path(target)
    key = str(lock.absolute())
    held = _HELD.get(key)
    if held is None:
        return
    held[1] -= 1
    if held[1] > 0:
        return
    del _HELD[key]
    with contextlib.suppress(OSError):
        lock.unlink()           # unlinked while still locked: no one can take a stale file
    with contextlib.suppress(OSError):
        os.close(held[0])


#: a file name to suggest for an output of each kind
_EXAMPLE_NAME = {"model": "model.h5", "prediction": "prediction.h5", "trajectory": "run.h5",
                 "png": "maps.png"}


def remove_free_locks(folder: str | os.PathLike, depth: int = 2) -> list[Path]:
    """Remove the lock files (``.NAME.lock``) in ``folder`` and its sub-folders down to
    ``depth`` that no process holds: those of workers stopped outright (a process pool's
    workers terminated on Ctrl-C), whose lock the system released with them. A lock still
    held is left; where ``fcntl`` is missing nothing is removed.

    Parameters
    ----------
    folder : str or os.PathLike
    depth : int, optional
        How many levels of sub-folders to look in.

    Returns
    -------
    list of pathlib.Path
        The lock files removed.
    """
    removed: list[Path] = []
    if fcntl is None:  # pragma: no cover - Windows
        return removed
    folder = Path(folder)
    patterns = [".*.lock"] + ["/".join(["*"] * k + [".*.lock"]) for k in range(1, depth + 1)]
    for lock in (p for pattern in patterns for p in folder.glob(pattern)):
        if str(lock.absolute()) in _HELD:
            continue
        try:
            fd = os.open(lock, os.O_RDWR)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            if os.path.samestat(os.fstat(fd), os.stat(lock)):
                lock.unlink()       # unlinked while locked, as _release does
                removed.append(lock)
        except OSError:
            pass                    # held by a running process, or gone meanwhile
        finally:
            os.close(fd)
    return removed


def remove_dead_temporaries(folder: str | os.PathLike, depth: int = 2) -> list[Path]:
    """Remove the temporaries in ``folder`` and its sub-folders down to ``depth`` left by
    writers that are gone (a process pool's workers terminated on Ctrl-C): for each
    temporary found, :func:`remove_stale_temporaries` of the output it was for. Call only
    where no live writer works in ``folder`` (the caller holds its lock, the workers are
    joined).

    Parameters
    ----------
    folder : str or os.PathLike
    depth : int, optional
        How many levels of sub-folders to look in.

    Returns
    -------
    list of pathlib.Path
        What was removed.
    """
    folder = Path(folder)
    hidden = re.compile(rf"^\.(?P<name>.+)\.{_RANDOM}\.tmp(\.\w+)?$")
    aside = re.compile(r"^(?P<name>.+)\.(tmp|old)-[0-9a-f]{8}$")
    targets: set[Path] = set()
    folders = [folder]
    for level in range(depth + 1):
        found = []
        for current in folders:
            with contextlib.suppress(OSError):
                for entry in current.iterdir():
                    match = hidden.match(entry.name) or aside.match(entry.name)
                    if match:
                        targets.add(current / match.group("name"))
                    elif level < depth and entry.is_dir() and not entry.is_symlink():
                        found.append(entry)
        folders = found
    removed: list[Path] = []
    for target in sorted(targets):
        removed += remove_stale_temporaries(target)
    return removed


def release_all() -> None:
    """Release every lock of this process (before ``os._exit``)."""
    for key in list(_HELD):
        lock = Path(key)
        with contextlib.suppress(OSError):
            lock.unlink()
        with contextlib.suppress(OSError):
            os.close(_HELD.pop(key)[0])


def _describe(path: Path) -> str:
    """What an existing path holds, in words."""
    import stat

    try:
        mode = path.stat().st_mode
    except OSError as exc:
        return f"unreadable ({exc.strerror or exc})"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if not stat.S_ISREG(mode):
        return "not a regular file"
    if path.stat().st_size == 0:
        return "empty"
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        return f"unreadable ({exc.strerror or exc})"
    if head == _PNG_MAGIC:
        return "png"
    if head != _HDF5_MAGIC:
        return "a file of another format"
    try:
        import h5py

        with h5py.File(path, "r") as f:
            fmt = f.attrs.get("format")
            source = f.attrs.get("source")
    except (OSError, RuntimeError):
        return "a damaged or locked HDF5 file"
    fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
    source = source.decode() if isinstance(source, bytes) else source
    if fmt == _FORMATS["trajectory"] and source == PREDICTION_SOURCE:
        return "prediction"
    for kind, name in _FORMATS.items():
        if fmt == name:
            return kind
    return "an HDF5 file of another format"


_KIND_TEXT = {"trajectory": "a trajectory file", "model": "a model file", "png": "a PNG image",
              "folder": "a folder", "prediction": "a prediction (a trajectory file)"}


#: what :func:`_describe` calls paths that are no regular file nor folder
_SPECIAL = ("a FIFO (named pipe)", "a device", "a socket", "not a regular file")


def _check_kind(target: Path, kind: str, force: bool) -> None:
    """Refuse an existing ``target`` of another kind than ``kind`` unless ``force``
    (which removes it; a non-empty folder is never removed)."""
    if not (target.exists() or target.is_symlink()):
        return
    what = _describe(target)
    if what == kind or what == "empty" and kind != "folder" or (
            kind == "folder" and what == "a folder") or (
            kind == "trajectory" and what == "prediction"):
        return
    if what == "a folder":
        if not force:
            raise InputError(f"{target}: is a folder, not {_KIND_TEXT[kind]}; give another "
                             "output name (or add --force, in Python force=True, to replace "
                             "an empty folder)")
        try:
            target.rmdir()
        except OSError:
            raise InputError(f"{target}: is a folder that is not empty; --force replaces "
                             "only an empty folder") from None
        return
    if what in _SPECIAL:        # never replaced, even with --force (as root: /dev/null)
        raise InputError(f"{target}: is {what}, not a file; the output is written as a file "
                         "(and never replaces a device, pipe or socket): give a file name")
    shown = _KIND_TEXT.get(what, what)
    if kind == "prediction" and what == "trajectory":
        shown = "a simulated or imported trajectory file"
    if not force:
        raise InputError(f"{target}: exists and is {shown}, not {_KIND_TEXT[kind]}; add --force "
                         "(in Python force=True) to replace it, or give another output name")
    if kind == "folder":
        try:
            target.unlink()
        except OSError as exc:
            raise InputError(f"{target}: cannot remove ({exc.strerror or exc})") from None


def _check_inputs(target: Path, inputs) -> None:
    for source in inputs:
        if source is None:
            continue
        names = glob.glob(str(source)) if glob.has_magic(str(source)) else [str(source)]
        for name in names:
            with contextlib.suppress(OSError):
                if target.exists() and os.path.samefile(target, name):
                    raise InputError(f"{target}: is one of the inputs ({name}); the output "
                                     "would overwrite it: give another output name")


#: mkstemp's random part (see :func:`cfbmarkov._atomic.temporary_path`)
_RANDOM = r"[a-z0-9_]{8}"


def temporary_patterns(target: Path) -> list[re.Pattern]:
    """Name patterns of the temporaries of ``target`` in its folder: files of
    :func:`~cfbmarkov._atomic.temporary_path` and the VTK export's folders."""
    name = re.escape(helper_stem(target.name))
    return [re.compile(rf"^\.{name}\.{_RANDOM}\.tmp(\.\w+)?$"),
            re.compile(rf"^{name}\.(tmp|old)-[0-9a-f]{{8}}$")]


_ANY_TEMPORARY = re.compile(rf"^\..+\.{_RANDOM}\.tmp(\.\w+)?$")


def remove_stale_temporaries(target: str | os.PathLike) -> list[Path]:
    """Remove what dead writers of ``target`` left: its temporaries beside it, and inside
    the output folder or its ``.parts`` checkpoint folder, every hidden temporary file.
    Call only while holding the output's lock (no live writer).

    Returns
    -------
    list of pathlib.Path
        What was removed.
    """
    target = Path(target)
    removed = []
    patterns = temporary_patterns(target)
    # a previous output moved aside by a writer that died before the new one took its
    # place: put back, not deleted (the output itself is missing)
    if not target.exists() and not target.is_symlink():
        with contextlib.suppress(OSError):
            aside = sorted(entry for entry in target.parent.iterdir()
                           if re.match(rf"^{re.escape(helper_stem(target.name))}\.old-"
                                       r"[0-9a-f]{8}$", entry.name) and entry.is_dir())
            if aside:
                os.replace(aside[-1], target)
    with contextlib.suppress(OSError):
        for entry in target.parent.iterdir():
            if any(p.match(entry.name) for p in patterns):
                removed.append(entry)
                if entry.is_dir() and not entry.is_symlink():
                    shutil.rmtree(entry, ignore_errors=True)
                else:
                    with contextlib.suppress(OSError):
                        entry.unlink()
    for folder in (target, parts_folder(target)):
        if not folder.is_dir() or folder.is_symlink():
            continue
        for root, _dirs, files in os.walk(folder):
            for name in files:
                if _ANY_TEMPORARY.match(name):
                    path = Path(root) / name
                    with contextlib.suppress(OSError):
                        path.unlink()
                        removed.append(path)
    return removed


def foreign_entries(folder: str | os.PathLike, belongs) -> list[str]:
    """The names in ``folder`` that are not part of an output written there.

    Parameters
    ----------
    folder : str or os.PathLike
        An existing folder (a missing one holds nothing).
    belongs : callable
        Called with each entry's :class:`pathlib.Path`; true where the entry is part of the
        output (one of its files, or a lock or temporary of one).

    Returns
    -------
    list of str
        The other entries' names, sorted.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(p.name for p in folder.iterdir() if not belongs(p))


def refuse_foreign(folder: str | os.PathLike, belongs, what: str, action: str) -> None:
    """Refuse, in one line, to write into a folder holding what another writer put there.

    Parameters
    ----------
    folder : str or os.PathLike
        The output folder.
    belongs : callable
        As for :func:`foreign_entries`.
    what : str
        The output, in words (e.g. "a comparison").
    action : str
        What is refused and the fix (e.g. "replace it (give a new or empty folder)").

    Raises
    ------
    InputError
        "FOLDER: folder holds 'NAME', which is not part of WHAT; refusing to ACTION", naming
        the first three foreign entries ("'A', 'B' and 'C' (and 2 more), which are not ...").
    """
    foreign = foreign_entries(folder, belongs)
    if foreign:
        shown = [repr(name) for name in foreign[:3]]
        names = shown[0] if len(shown) == 1 else f"{', '.join(shown[:-1])} and {shown[-1]}"
        more = f" (and {len(foreign) - 3} more)" if len(foreign) > 3 else ""
        verb = "is" if len(foreign) == 1 else "are"
        raise InputError(f"{folder}: folder holds {names}{more}, which {verb} not part of "
                         f"{what}; refusing to {action}")


def output_helper(entry: str | os.PathLike, names) -> bool:
    """Whether ``entry`` is the lock or a temporary of one of the outputs ``names`` beside
    it (:func:`lock_path`, :func:`temporary_patterns`)."""
    entry = Path(entry)
    for name in names:
        target = entry.parent / name
        if entry.name == lock_path(target).name or any(
                p.match(entry.name) for p in temporary_patterns(target)):
            return True
    return False


def describe(path: str | os.PathLike) -> str:
    """What an existing path holds: one of :data:`KINDS` but ``"folder"`` for a cfbmarkov
    file or a PNG, ``"a folder"``, ``"empty"``, or words for anything else."""
    return _describe(Path(path))


#: file name suffixes that say a file is of another format than the HDF5 file or PNG
#: image a verb writes (a name without a suffix, or another one, is taken as given)
_FOREIGN_SUFFIXES = {
    "hdf5": {".csv", ".txt", ".tsv", ".json", ".png", ".jpg", ".jpeg", ".pdf", ".svg",
             ".vtk", ".vtp", ".pvd", ".dump", ".toml", ".xlsx", ".dat"},
    "png": {".h5", ".hdf5", ".csv", ".txt", ".json", ".jpg", ".jpeg", ".pdf", ".svg",
            ".vtk"},
    "folder": {".h5", ".hdf5", ".png", ".csv", ".txt", ".json", ".vtk", ".vtp", ".vtu",
               ".pvd", ".pdf", ".svg", ".toml", ".dump"},
}
_WRITES = {"trajectory": "hdf5", "prediction": "hdf5", "model": "hdf5", "png": "png",
           "folder": "folder"}


def check_suffix(target: str | os.PathLike, kind: str) -> None:
    """Refuse an output name whose suffix says another format than the one written (a
    model written as ``model.txt``, a map as ``maps.h5``, a folder as ``vtk.h5``).

    Raises
    ------
    InputError
        Naming the suffix and the one to use.
    """
    written = _WRITES.get(kind)
    suffix = Path(target).suffix.lower()
    if written is None or suffix not in _FOREIGN_SUFFIXES[written]:
        return
    if written == "folder":
        raise InputError(f"{target}: the output is a folder of files, not a {suffix} file; "
                         f"name the folder without the suffix (e.g. "
                         f"{Path(target).with_suffix('').name})")
    what, right = (("an HDF5 file", ".h5") if written == "hdf5" else ("a PNG image", ".png"))
    raise InputError(f"{target}: the output is {what}, not a {suffix} file; name it "
                     f"{Path(target).with_suffix(right).name}")


@contextlib.contextmanager
def claim_output(target: str | os.PathLike, verb: str, kind: str, inputs=(),
                 force: bool = False):
    """Claim ``target`` for writing for the duration of the block.

    In order: a name longer than the file system allows is refused (the helper names built
    from a long one are shortened, :func:`~cfbmarkov._names.helper_stem`); the folder is
    created if missing (and removed again, if still empty, when the block fails); ``target``
    must not be one of ``inputs`` (same file, also through links); the lock is taken
    (refused naming the holder: pid, host, verb, since when); an existing ``target`` of
    another kind is refused unless ``force``; the temporaries of dead writers of ``target``
    are removed. Re-entrant within a process.

    Parameters
    ----------
    target : str or os.PathLike
        The output file or folder.
    verb : str
        The writing verb, recorded in the lock.
    kind : {"trajectory", "prediction", "model", "png", "folder"}
        What is written: a prediction may replace a prediction; a trajectory file (a run)
        a run or a prediction.
    inputs : iterable of str or os.PathLike, optional
        The verb's input files (glob patterns are expanded).
    force : bool, optional
        Replace an existing output of another kind.

    Raises
    ------
    InputError
        When the output cannot be claimed.
    """
    check_output_name(target)           # before Path(): Path("") is "."
    if kind != "folder" and os.fspath(target).endswith(("/", os.sep)):
        raise InputError(f"{os.fspath(target)}: a folder's name, where this verb writes one "
                         f"file; give the file's name (e.g. {os.fspath(target)}"
                         f"{_EXAMPLE_NAME.get(kind, 'out.h5')}: the folder is created)")
    target = named_output(target)       # "-o ." is refused, not replaced
    if kind == "folder" and Path(os.path.realpath(Path.cwd())).is_relative_to(
            os.path.realpath(target)):
        raise InputError(f"{target}: holds the current folder, which a verb cannot replace "
                         "whole when its output is complete; give a new folder by name "
                         "(e.g. -o results)")
    check_suffix(target, kind)
    key = str(lock_path(target).absolute())
    if key in _HELD:        # claimed by this process already (the command line, then the API)
        _HELD[key][1] += 1
        try:
            yield target
        finally:
            _release(target)
        return
    _check_inputs(target, inputs)
    new = [p for p in target.absolute().parents if not p.exists()]
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        blocking = next((p for p in reversed(target.parent.parents) if p.is_file()), None)
        if blocking is None and target.parent.is_file():
            blocking = target.parent
        if blocking is not None:        # a file where a folder of the path should be
            raise InputError(f"{target}: {blocking} is a file, not a folder: give an output "
                             "name beside it, not inside it") from None
        raise InputError(f"{target}: cannot create its folder {target.parent} "
                         f"({exc.strerror or exc})") from None
    created = False
    try:
        _acquire(target, verb)
        try:
            _check_kind(target, kind, force)
            remove_stale_temporaries(target)
            created = kind == "folder" and not target.exists()
            yield target
        except BaseException:
            if created:
                with contextlib.suppress(OSError):
                    target.rmdir()          # only if the failed verb left it empty
            raise
        finally:
            _release(target)
    except BaseException:
        for folder in new:                  # deepest first, only if empty
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise


__all__ = ["KINDS", "claim_output", "describe", "foreign_entries", "lock_path",
           "output_helper", "refuse_foreign", "release_all", "remove_dead_temporaries",
           "remove_stale_temporaries",
           "temporary_patterns"]
