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
   are removed when the claim is taken; other files are left alone.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from pneu_msgs_py.params.core import ParamError

__all__ = ["LOCK_NAME", "PARTIAL", "OutputDir", "OutputFile", "is_same_path"]

LOCK_NAME = ".pneu.lock"
PARTIAL = ".partial"


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
        if p.exists() and not p.is_dir():
            raise ParamError(self.field, str(p), "a directory (this is a file)")
        for inp in self.inputs:
            for name in (*self.artefacts, *(a + PARTIAL for a in self.artefacts)):
                if is_same_path(p / name, inp):
                    raise ParamError(
                        self.field,
                        str(p),
                        f"a directory whose outputs are not inputs of the command ({inp} would "
                        f"be replaced by {name})",
                    )
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
        if not p.name or p.is_dir() or str(p).endswith(os.sep):
            raise ParamError(self.field, str(p), "a file name (this is a directory)")
        if self.suffixes and p.suffix.lower() not in self.suffixes:
            raise ParamError(
                self.field, str(p), "a file name ending in " + " or ".join(self.suffixes)
            )
        for inp in self.inputs:
            if is_same_path(p, inp) or is_same_path(p.parent / (p.name + PARTIAL), inp):
                raise ParamError(
                    self.field, str(p), f"a file that is not one of the command's inputs ({inp})"
                )
        if (p.exists() or p.is_symlink()) and not self.overwrite:
            raise ParamError(self.field, str(p), "a new file, or --overwrite to replace it")
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
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        if self._lock is not None:
            _release(self._lock, self._lock_path)
            self._lock = None

    @property
    def partial(self) -> Path:
        return self.path.parent / (self.path.name + PARTIAL)

    def publish(self) -> Path:
        os.replace(self.partial, self.path)
        return self.path

    def discard(self) -> None:
        try:
            self.partial.unlink()
        except FileNotFoundError:
            pass
