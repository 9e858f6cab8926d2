"""Outputs claimed before anything is written: never reused silently, never an input, never half-written.

The rules (every command that writes follows them, docs/cli.md repeats them):

1. **Checked first.** :meth:`OutputDir.check` / :meth:`OutputFile.check` run with
   the other input checks, before anything is created: a directory that holds
   files, or a file that exists, is refused unless ``overwrite``; an output
   that is one of the command's inputs is refused always.
2. **Locked.** Entering the claim creates the directory and takes a lock
   (``filelock``, a ``.pneu.lock`` file inside it, or ``.NAME.pneu.lock``
   beside a file, removed when done), without waiting: a second command on the
   same output is refused at once, and the check is repeated under the lock.
3. **Temporary names.** Every file is written as ``NAME.partial`` and renamed
   to ``NAME`` (:func:`os.replace`, atomic) when complete: a directory holds
   finished artefacts, or partial ones that say so (after a hard kill:
   ``pneu recover run.mcap.partial --out run.mcap``).
4. With ``overwrite``, the artefacts this command writes (and their partials)
   are removed when the claim is taken; other files are left alone. A claim left by an
   exception (a failed write) removes its partial files.
5. **Writable, and not anything else.** The check refuses an empty path, a
   location under a file, one that cannot be written (permissions, a read-only
   file system) or is full (less than :data:`MIN_FREE_BYTES` free), and an
   existing output that is not a regular file (a device such as ``/dev/full``,
   a pipe, a directory): ``--overwrite`` replaces a file pneu could have written,
   nothing else. So a long command (a fit, a sweep) never finds out at its end.
6. **Never an input.** Besides the inputs a command names, every file it has read
   (:mod:`pneu_msgs_py.params.inputs`: config files, waypoint tables, bags, tasks) is refused as an
   output, by identity (a link or another spelling is the same file).
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable
from pathlib import Path

from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.inputs import is_input

__all__ = [
    "LOCK_NAME",
    "MIN_FREE_BYTES",
    "PARTIAL",
    "OutputDir",
    "OutputFile",
    "check_writable_dir",
    "is_same_path",
]

LOCK_NAME = ".pneu.lock"
PARTIAL = ".partial"
MIN_FREE_BYTES = 2**20  # a location with less free space is full (the smallest output is kB)


def _check_text(path: str | os.PathLike, field: str) -> None:
    if not os.fspath(path).strip():
        raise ParamError(field, os.fspath(path), "a path (not empty: '' is not '.')")


def _check_names(p: Path, q: Path, field: str, shown: str, longest: str = "") -> None:
    """Every name of ``p`` to be created under ``q`` (and ``longest``, the longest file name
    to be written in ``p``) fits the file system's name length."""
    try:
        name_max = os.pathconf(q, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    new = [part for part in p.relative_to(q).parts] if p != q else []
    for name in (*new, longest):
        if len(os.fsencode(name)) > name_max:
            raise ParamError(
                field, shown, f"names of at most {name_max} bytes ({name[:40]}... is longer)"
            )


def _check_fits(p: Path, field: str, shown: str, longest: str = "") -> None:
    """Before anything looks at ``p``: its new names (and ``longest``) fit the file system (a
    look at a longer name fails with ENAMETOOLONG, an error, not "it does not exist")."""
    q = p
    while not os.path.lexists(q) and q != q.parent:
        q = q.parent
    _check_names(p, q, field, shown, longest)


def _check_location(p: Path, field: str, shown: str, longest: str = "") -> None:
    """``p`` (a directory to write in, existing or to be created) can be written, and its new
    names (with ``longest``, the longest file name written in it) are not too long."""
    q = p
    while not os.path.lexists(q) and q != q.parent:
        q = q.parent
    if not q.is_dir():
        what = "is a file" if q.is_file() else "is not a directory"
        raise ParamError(field, shown, f"a location under a directory ({q} {what})")
    _check_names(p, q, field, shown, longest)
    try:
        fs = os.statvfs(q)
    except OSError:
        fs = None
    # a read-only file system first: access() fails there too (EROFS), whoever asks
    if fs is not None and fs.f_flag & os.ST_RDONLY:
        raise ParamError(field, shown, f"a writable location ({q} is on a read-only file system)")
    if not os.access(q, os.W_OK | os.X_OK):
        raise ParamError(field, shown, f"a writable location ({q}: permission denied)")
    if fs is None:
        return
    free = fs.f_bavail * fs.f_frsize
    if free < MIN_FREE_BYTES:
        raise ParamError(
            field,
            shown,
            f"a location with free space (at least {MIN_FREE_BYTES // 2**20} MiB; "
            f"{free} bytes free on {q}'s file system)",
        )


def check_writable_dir(path: str | os.PathLike, field: str) -> None:
    """A directory another tool fills (``pneu security``'s keystore): rule 5 before anything is
    created (not empty, names that fit, under a directory, writable, not full)."""
    p = Path(path)
    _check_text(p, field)
    _check_fits(p, field, str(p))
    _check_location(p, field, str(p))


def _check_replaceable(f: Path, field: str, shown: str) -> None:
    """An existing output ``f`` is a file pneu could have written (or a link): never a
    device, pipe, socket or directory."""
    try:
        mode = os.lstat(f).st_mode
    except OSError:
        return
    if not (stat.S_ISREG(mode) or stat.S_ISLNK(mode)):
        kind = "a directory" if stat.S_ISDIR(mode) else "a device, pipe or socket"
        raise ParamError(field, shown, f"a path for a regular file ({f} is {kind}: never replaced)")


def _input_named(f: Path, inputs: Iterable[str | os.PathLike]) -> str | None:
    """The input (named, or read by the command) ``f`` is, if any."""
    for inp in inputs:
        if is_same_path(f, inp):
            return str(inp)
    return is_input(f)


def _resolved(p: str | os.PathLike) -> Path:
    return Path(os.path.abspath(os.path.expanduser(os.fspath(p))))


def is_same_path(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Do ``a`` and ``b`` name the same file (also through links)?"""
    try:
        if os.path.exists(a) and os.path.exists(b):
            return os.path.samefile(a, b)
    except OSError:
        pass
    return _resolved(a).resolve() == _resolved(b).resolve()


def _lock(path: Path, field: str, what: str):
    from filelock import FileLock, Timeout

    lock = FileLock(str(path), is_singleton=False)
    try:
        lock.acquire(timeout=0)
    except Timeout:
        raise ParamError(
            field,
            what,
            f"an output no other pneu command is writing (locked by another process: {path})",
        ) from None
    except OSError as err:
        raise ParamError(field, what, f"a writable location ({err.strerror or err})") from None
    return lock


def _release(lock, path: Path) -> None:
    """Remove the lock file while still holding it, then release (a waiter re-checks)."""
    try:
        path.unlink()
    except OSError:
        pass
    lock.release()


class OutputDir:
    """A run directory claimed for ``artefacts`` (file names written into it)."""

    def __init__(
        self,
        path: str | os.PathLike,
        artefacts: Iterable[str],
        *,
        overwrite: bool = False,
        inputs: Iterable[str | os.PathLike | None] = (),
        field: str = "--out",
    ) -> None:
        self.path = Path(path)
        self.artefacts = tuple(artefacts)
        self.overwrite = overwrite
        self.inputs = [i for i in inputs if i]
        self.field = field
        self._lock = None
        self._created: list[Path] = []

    def __str__(self) -> str:
        return str(self.path)

    def _holdings(self) -> list[str]:
        try:
            return sorted(e.name for e in os.scandir(self.path) if e.name != LOCK_NAME)
        except OSError:
            return []

    def check(self) -> OutputDir:
        """Refuse (ParamError naming the option) before anything is created."""
        p = self.path
        _check_text(p, self.field)
        longest = max((a + PARTIAL for a in self.artefacts), key=len, default="")
        _check_fits(p, self.field, str(p), longest)
        if p.exists() and not p.is_dir():
            raise ParamError(self.field, str(p), "a directory (this is a file)")
        for name in (*self.artefacts, *(a + PARTIAL for a in self.artefacts)):
            inp = _input_named(p / name, self.inputs)
            if inp is not None:
                raise ParamError(
                    self.field,
                    str(p),
                    f"a directory whose outputs are not inputs of the command ({inp} would "
                    f"be replaced by {name})",
                )
            _check_replaceable(p / name, self.field, str(p))
        _check_location(p, self.field, str(p), longest)
        held = self._holdings() if p.is_dir() else []
        if held and not self.overwrite:
            listed = ", ".join(held[:6]) + (", ..." if len(held) > 6 else "")
            raise ParamError(
                self.field,
                str(p),
                f"a new or empty directory, or --overwrite to replace its pneu outputs "
                f"({', '.join(self.artefacts)}); it holds {listed}",
            )
        return self

    def __enter__(self) -> OutputDir:
        self.check()
        missing = []
        q = self.path
        while not q.exists():
            missing.append(q)
            q = q.parent
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ParamError(
                self.field, str(self.path), f"a directory that can be created ({err.strerror})"
            ) from None
        self._created = missing
        self._lock = _lock(self.path / LOCK_NAME, self.field, str(self.path))
        try:
            self.check()  # again, under the lock: another command may have finished meanwhile
            if self.overwrite:
                for name in self.artefacts:
                    for f in (self.path / name, self.path / (name + PARTIAL)):
                        if f.is_file() or f.is_symlink():
                            f.unlink()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        if exc and exc[0] is not None:  # a failed write (a full disk): no half-written file
            self.discard()
        if self._lock is not None:
            _release(self._lock, self.path / LOCK_NAME)
            self._lock = None

    def final(self, name: str) -> Path:
        return self.path / name

    def partial(self, name: str) -> Path:
        """Where ``name`` is written until it is complete."""
        return self.path / (name + PARTIAL)

    def publish(self, *names: str) -> None:
        """Rename each complete ``NAME.partial`` to ``NAME`` (atomic)."""
        for name in names:
            os.replace(self.partial(name), self.final(name))

    def discard(self) -> None:
        """Remove this claim's partial files, and the directories it created if left empty."""
        for name in self.artefacts:
            try:
                self.partial(name).unlink()
            except FileNotFoundError:
                pass
        for d in self._created:
            try:
                if d.is_dir() and not [e for e in os.listdir(d) if e != LOCK_NAME]:
                    (d / LOCK_NAME).unlink(missing_ok=True)
                    d.rmdir()
            except OSError:
                break


class OutputFile:
    """One output file claimed (written as ``NAME.partial``, renamed when complete)."""

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        overwrite: bool = False,
        inputs: Iterable[str | os.PathLike | None] = (),
        field: str = "--out",
        suffixes: tuple[str, ...] = (),
    ) -> None:
        self.path = Path(path)
        self.overwrite = overwrite
        self.inputs = [i for i in inputs if i]
        self.field = field
        self.suffixes = suffixes
        self._lock = None
        self._lock_path = self.path.parent / f".{self.path.name}{LOCK_NAME}"

    def __str__(self) -> str:
        return str(self.path)

    def check(self) -> OutputFile:
        p = self.path
        _check_text(p, self.field)
        longest = max((self._lock_path.name, self.partial.name), key=len)
        _check_fits(p.parent, self.field, str(p), longest)
        if not p.name or p.is_dir() or str(p).endswith(os.sep):
            raise ParamError(self.field, str(p), "a file name (this is a directory)")
        if self.suffixes and p.suffix.lower() not in self.suffixes:
            raise ParamError(
                self.field, str(p), "a file name ending in " + " or ".join(self.suffixes)
            )
        for f in (p, self.partial):
            inp = _input_named(f, self.inputs)
            if inp is not None:
                raise ParamError(
                    self.field, str(p), f"a file that is not one of the command's inputs ({inp})"
                )
            _check_replaceable(f, self.field, str(p))
        if (p.exists() or p.is_symlink()) and not self.overwrite:
            raise ParamError(self.field, str(p), "a new file, or --overwrite to replace it")
        if os.path.lexists(self.partial) and not self.overwrite:  # a killed command's
            raise ParamError(
                self.field,
                str(p),
                f"a new file, or --overwrite ({self.partial.name} is left by a command that did "
                "not finish: pneu recover it, or --overwrite removes it)",
            )
        _check_location(p.parent, self.field, str(p), longest)
        return self

    def __enter__(self) -> OutputFile:
        self.check()
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ParamError(
                self.field,
                str(self.path),
                f"a file in a directory that can be created ({err.strerror})",
            ) from None
        self._lock = _lock(self._lock_path, self.field, str(self.path))
        try:
            self.check()
            if self.overwrite and os.path.lexists(self.partial):  # a killed command's
                self.partial.unlink()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        if exc and exc[0] is not None:  # a failed write (a full disk): no half-written file
            self.discard()
        if self._lock is not None:
            _release(self._lock, self._lock_path)
            self._lock = None

    @property
    def partial(self) -> Path:
        """Where the file is written until complete: ``NAME.partial``, or ``NAME.new.partial``
        when ``NAME.partial`` is an input (``pneu recover run.mcap.partial --out run.mcap``:
        the cut bag is read, never replaced)."""
        own = self.path.parent / (self.path.name + PARTIAL)
        if any(is_same_path(own, i) for i in self.inputs):
            return self.path.parent / (self.path.name + ".new" + PARTIAL)
        return own

    def publish(self) -> Path:
        os.replace(self.partial, self.path)
        return self.path

    def discard(self) -> None:
        try:
            self.partial.unlink()
        except FileNotFoundError:
            pass
