"""A file that appears at its path only complete, written by one process at a time.

:class:`OutputFile` reserves a temporary file beside the target (same folder, so the same file
system: ``.<name>.<pid>-<random>.tmp``), lets the caller write it, then either renames it onto
the target (:meth:`OutputFile.commit`: fsync, ``os.replace``, fsync of the folder) or deletes it
(:meth:`OutputFile.discard`). An existing file at the target is therefore replaced only by a
complete one, and is left as it was by a run that failed or was killed; a killed run leaves at
most its hidden temporary file, which the next writer of the same path deletes.

One writer per path: :meth:`OutputFile.open` takes an exclusive ``fcntl.flock`` on a lock file
``.<name>.lock`` beside the target and holds it until commit or discard. The kernel drops the
lock when its process dies, so a killed run never blocks later ones. The lock file is deleted
while still locked; a writer that locked a lock file which was deleted meanwhile sees that its
inode is no longer the one at the path and tries again.

The lock file is opened without following a symbolic link (``O_NOFOLLOW``) and used only if it
is a plain file with no other name (one hard link): a link planted at ``.<name>.lock`` makes the
open fail (:func:`lock_problem` says why) instead of overwriting the file it points at.

A name so long that the side files' suffixes would pass the file system's limit on a name
(``NAME_MAX``, 255 bytes) gives them a shortened stem instead: the name's start, ``~`` and 16
hex digits of its SHA-256 (:func:`side_stem`), so every name the file system accepts can be
written.

A symbolic link at the target is followed: the file it points at is replaced, the link stays.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import glob
import hashlib
import os
import secrets
import stat
from pathlib import Path

from pickplace.errors import OutputError

LOCK_ATTEMPTS = 5
# The longest suffix a side file adds to its stem: ".<pid>-<8 hex>.tmp" with a 10-digit pid
# (pid_t is 32 bits), longer than ".lock" [bytes].
SIDE_SUFFIX_BYTES = len(".2147483647-ffffffff.tmp")
DEFAULT_NAME_MAX = 255  # bytes in a file name, where the file system does not say


def resolve_target(path: Path) -> Path:
    """The file that writing ``path`` replaces: ``path`` itself, or where its symlinks lead."""
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def name_max(folder: Path) -> int:
    """The longest file name [bytes] the file system of ``folder`` accepts (255 if unknown)."""
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return DEFAULT_NAME_MAX


def side_stem(target: Path) -> str:
    """The stem of ``target``'s side files (lock, temporary files): ``.<name>``, or when that
    leaves too little room for their suffixes under :func:`name_max`, ``.<start>~<digest>``
    (the name's first characters and 16 hex digits of its SHA-256)."""
    name = target.name
    room = name_max(target.parent) - SIDE_SUFFIX_BYTES
    if len(os.fsencode(f".{name}")) <= room:
        return f".{name}"
    digest = hashlib.sha256(os.fsencode(name)).hexdigest()[:16]
    start = name
    while start and len(os.fsencode(f".{start}~{digest}")) > room:
        start = start[:-1]
    return f".{start}~{digest}"


def lock_path(target: Path) -> Path:
    """Lock file of ``target``: ``.<name>.lock`` in the same folder (see :func:`side_stem`)."""
    return target.with_name(f"{side_stem(target)}.lock")


def lock_problem(lock: Path) -> str | None:
    """Why ``lock`` cannot serve as a lock file (a symbolic link, not a plain file, or a file
    with other names), or None if it is absent or usable. Nothing is opened."""
    try:
        st = os.lstat(lock)
    except OSError:
        return None
    if stat.S_ISLNK(st.st_mode):
        return f"its lock file '{lock}' is a symbolic link; remove the link"
    if not stat.S_ISREG(st.st_mode):
        return f"its lock file '{lock}' is not a plain file; remove it"
    if st.st_nlink > 1:
        return f"its lock file '{lock}' has other names (hard links); remove it"
    return None


def _pid_in(lock: Path) -> str:
    try:
        fd = os.open(lock, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return ""
    try:
        text = os.read(fd, 32).decode(errors="replace").strip()
    except OSError:
        return ""
    finally:
        os.close(fd)
    return f" (pid {text})" if text.isdigit() else ""


class OutputFile:
    """Temporary file beside ``path``, renamed onto it at the end (see the module docstring).

    Args:
        path: The file to produce. Its folder must exist.
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.target = resolve_target(self.path)
        self.temp: Path | None = None
        self._lock_fd: int | None = None

    # ------------------------------------------------------------------ open

    def open(self) -> Path:
        """Take the lock, delete stale temporary files of this path, create the temporary file.

        Returns:
            The temporary file's path (empty, created with the target's permissions, or the
            default ones if there is no target yet).

        Raises:
            OutputError: Another process is writing this path, or the folder is not writable.
        """
        if self.temp is not None:
            return self.temp
        self._lock()
        try:
            self._delete_stale_temps()
            try:  # a replaced file keeps its permissions; a new one gets the default ones
                mode = stat.S_IMODE(self.target.stat().st_mode)
            except OSError:
                mode = 0o666 & ~_umask()
            stem = side_stem(self.target)
            for _ in range(LOCK_ATTEMPTS):
                temp = self.target.with_name(f"{stem}.{os.getpid()}-{secrets.token_hex(4)}.tmp")
                try:
                    fd = os.open(temp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
                except FileExistsError:
                    continue
                try:
                    os.fchmod(fd, mode)
                finally:
                    os.close(fd)
                self.temp = temp
                return temp
            raise OutputError(f"cannot create a temporary file beside '{self.path}'")
        except OSError as exc:
            self._unlock()
            raise OutputError(
                f"cannot create a temporary file beside '{self.path}': {exc.strerror}"
            ) from None
        except BaseException:
            self._unlock()
            raise

    def _lock(self) -> None:
        lock = lock_path(self.target)
        for _ in range(LOCK_ATTEMPTS):
            try:  # never through a link: a planted one would have its target truncated
                fd = os.open(lock, os.O_CREAT | os.O_RDWR | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
            except OSError as exc:
                why = lock_problem(lock) or f"{lock}: {exc.strerror}"
                raise OutputError(f"cannot lock '{self.path}' for writing: {why}") from None
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode) or st.st_nlink > 1:
                os.close(fd)
                why = lock_problem(lock) or f"its lock file '{lock}' changed"
                raise OutputError(f"cannot lock '{self.path}' for writing: {why}")
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise OutputError(
                        f"--record '{self.path}' is being written by another pickplace run"
                        f"{_pid_in(lock)}; wait for it to end or choose another file"
                    ) from None
                raise OutputError(f"cannot lock '{self.path}': {exc.strerror}") from None
            try:
                same = os.fstat(fd).st_ino == os.stat(lock).st_ino
            except FileNotFoundError:
                same = False
            if not same:  # the previous holder deleted it after we opened it: try again
                os.close(fd)
                continue
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
            self._lock_fd = fd
            return
        raise OutputError(f"cannot lock '{self.path}': its lock file keeps changing")

    def _unlock(self) -> None:
        if self._lock_fd is None:
            return
        with contextlib.suppress(OSError):
            lock_path(self.target).unlink()
        with contextlib.suppress(OSError):
            os.close(self._lock_fd)
        self._lock_fd = None

    def _delete_stale_temps(self) -> None:
        """Temporary files of this path left by killed runs (we hold the lock: none is live)."""
        folder = self.target.parent
        for stale in folder.glob(f"{glob.escape(side_stem(self.target))}.*.tmp"):
            with contextlib.suppress(OSError):
                stale.unlink()

    # ------------------------------------------------------------------ end

    @property
    def is_open(self) -> bool:
        """True between :meth:`open` and :meth:`commit` / :meth:`discard`."""
        return self.temp is not None

    def commit(self) -> None:
        """Make the temporary file durable and rename it onto the target; release the lock.

        Raises:
            OutputError: The file could not be synced or renamed (it is then deleted and the
                target left as it was).
        """
        if self.temp is None:
            raise OutputError(f"'{self.path}' was not opened for writing")
        temp = self.temp
        try:
            fd = os.open(temp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(temp, self.target)
            _fsync_folder(self.target.parent)
        except OSError as exc:
            self.discard()
            raise OutputError(
                f"cannot put the recording in place at '{self.path}': {exc.strerror}; "
                "an older file there is unchanged"
            ) from None
        self.temp = None
        self._unlock()

    def discard(self) -> None:
        """Delete the temporary file (the target is left as it was) and release the lock.
        Idempotent."""
        if self.temp is not None:
            with contextlib.suppress(OSError):
                self.temp.unlink()
            self.temp = None
        self._unlock()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _fsync_folder(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems cannot sync a directory; the rename itself is atomic
    finally:
        os.close(fd)


__all__ = ["OutputFile", "lock_path", "lock_problem", "name_max", "resolve_target", "side_stem"]
