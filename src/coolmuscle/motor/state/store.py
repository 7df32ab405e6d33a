"""The persistent store: what survives a power cycle (CML 2.1.2 ``$``, ch. 3).

Two things persist, per motor ID:

* the **snapshot** written by ``$`` ("saves Parameters, Data Commands, Program
  Banks and Ladder Logic Banks", 2.1.2): one JSON document, replaced whole in
  one transaction by :meth:`Store.save_snapshot`;
* **K values** written on their own by every accepted K change (ch. 3: "The
  changed value is saved automatically"), :meth:`Store.save_param`.  They are
  an overlay on the snapshot; the next ``$`` folds them in and clears them.

:meth:`Store.load` returns what a power cycle restores: the snapshot with the
overlay applied.

The file is SQLite in WAL mode with ``synchronous=FULL`` and every write is one
``BEGIN IMMEDIATE`` transaction, so a crash at any instant (kill -9, power loss
on a disk that honours fsync) leaves the previous or the new state, never a
mixture; a committed ``$`` is durable before ``saved.`` is printed.

Concurrency: one writer process (the simulator); callers serialise access from
several threads themselves (the coolmuscle:// port holds a lock).  Other processes may read.
The writer holds a ``flock`` on ``PATH.lock``, a regular file opened without following
a symbolic link (:func:`open_lock_file`).  A store that cannot be opened because the
disk is full says so (:func:`disk_full`), not that the store is unusable.

Snapshot shape (the motor decides the content; the store only requires JSON
data with string keys, except ``params`` whose keys may be ints)::

    {"firmware": "cm2", "params": {20: 0, ...}, "memory": Memory.to_dict(),
     "banks": {"1": ["S1.1, A1.1, P1.1", ...]}, "ladders": {"1": [...]}}
"""

from __future__ import annotations

import errno
import json
import os
import stat
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import DamagedStoreError, StoreError

if TYPE_CHECKING:
    import sqlite3  # imported where a store is opened: a run without one never needs it

try:
    import fcntl
except ImportError:       # Windows: the writer lock is SQLite's own (_sqlite_lock)
    fcntl = None  # type: ignore[assignment]

#: ``PRAGMA application_id`` of a coolmuscle store ("CMST").
APPLICATION_ID = 0x434D5354
#: ``PRAGMA user_version``: schema version this code writes and reads.
SCHEMA_VERSION = 1
#: File name inside :func:`default_state_dir`.
DEFAULT_FILENAME = "coolmuscle.sqlite3"
#: How long to wait for another connection's lock (seconds, SQLite's own timer).
BUSY_TIMEOUT_S = 5.0

_SCHEMA = (
    "CREATE TABLE IF NOT EXISTS snapshot (motor_id INTEGER PRIMARY KEY,"
    " generation INTEGER NOT NULL, data TEXT NOT NULL)",
    "CREATE TABLE IF NOT EXISTS param (motor_id INTEGER NOT NULL, k INTEGER NOT NULL,"
    " value INTEGER NOT NULL, PRIMARY KEY (motor_id, k))",
)


def default_state_dir() -> Path:
    """``$XDG_DATA_HOME/coolmuscle``, or ``~/.local/share/coolmuscle``.

    A relative ``XDG_DATA_HOME`` is ignored, as the XDG base directory spec says.
    """
    xdg = os.environ.get("XDG_DATA_HOME", "")
    base = Path(xdg) if xdg and os.path.isabs(xdg) else Path.home() / ".local" / "share"
    return base / "coolmuscle"


class Store:
    """SQLite store at ``path`` (default: :func:`default_state_dir` /
    ``coolmuscle.sqlite3``).  Opening a file that is not a coolmuscle store,
    or is damaged, raises :class:`StoreError`; so does every failed operation.
    """

    def __init__(self, path: str | os.PathLike[str] | None = None, *,
                 writer: bool = False) -> None:
        """``writer``: this store belongs to a running chain, the one process that
        writes it; a second writer on the same file is refused (:class:`StoreError`)
        until the first closes or exits (docs/fidelity.md "Saving")."""
        if path is None:
            try:
                path = default_state_dir() / DEFAULT_FILENAME
            except RuntimeError as exc:  # no home directory
                raise StoreError(f"no state directory: {exc}") from exc
        self._path = str(path)
        self._lock: Callable[[], None] | None = _writer_lock(self._path) if writer else None
        try:
            self._conn: sqlite3.Connection | None = _open(self._path)
        except BaseException:
            self._unlock()
            raise

    @property
    def path(self) -> str:
        """The database file."""
        return self._path

    # -- writes ----------------------------------------------------------------

    def save_snapshot(self, motor_id: int, snapshot: Mapping[str, Any]) -> int:
        """Replace the snapshot of ``motor_id`` atomically (``$``).

        Clears the K overlay (the snapshot carries the current K values).
        Returns the store's save count for this motor (1 for the first save).
        ``ValueError`` if ``snapshot`` is not JSON data that loads back equal.
        """
        motor_id = _motor(motor_id)
        text = _encode(snapshot)
        with self._write() as conn:
            row = conn.execute("SELECT generation FROM snapshot WHERE motor_id = ?",
                               (motor_id,)).fetchone()
            generation = (row[0] if row else 0) + 1
            conn.execute("INSERT OR REPLACE INTO snapshot (motor_id, generation, data)"
                         " VALUES (?, ?, ?)", (motor_id, generation, text))
            conn.execute("DELETE FROM param WHERE motor_id = ?", (motor_id,))
        return generation

    def save_param(self, motor_id: int, k: int, value: int) -> None:
        """Persist one accepted K change (ch. 3, automatic saving)."""
        motor_id = _motor(motor_id)
        if not (_is_int(k) and _is_int(value)):
            raise ValueError(f"K{k}={value!r}: K number and value must be integers")
        with self._write() as conn:
            conn.execute("INSERT OR REPLACE INTO param (motor_id, k, value) VALUES (?, ?, ?)",
                         (motor_id, k, value))

    def delete(self, motor_id: int) -> None:
        """Forget everything saved for ``motor_id`` (factory state at power-up)."""
        motor_id = _motor(motor_id)
        with self._write() as conn:
            conn.execute("DELETE FROM snapshot WHERE motor_id = ?", (motor_id,))
            conn.execute("DELETE FROM param WHERE motor_id = ?", (motor_id,))

    # -- reads -----------------------------------------------------------------

    def load(self, motor_id: int) -> dict[str, Any] | None:
        """What a power cycle restores, or ``None`` if nothing was ever saved.

        The saved snapshot with the automatically persisted K values applied to
        its ``params`` (int keys).  Only K values saved, no ``$``: a dict with
        just ``params``.
        """
        motor_id = _motor(motor_id)
        with self._read() as conn:
            row = conn.execute("SELECT data FROM snapshot WHERE motor_id = ?",
                               (motor_id,)).fetchone()
            overlay = conn.execute("SELECT k, value FROM param WHERE motor_id = ?"
                                   " ORDER BY k", (motor_id,)).fetchall()
        if row is None and not overlay:
            return None
        snapshot = _decode(row[0], motor_id, self._path) if row is not None else {}
        for k, v in overlay:
            if not (_is_int(k) and _is_int(v)):
                raise StoreError(self._bad(motor_id, f"saved K{k!r}={v!r} (automatic K save) "
                                                     "is not an integer K value"))
        if overlay:
            params = snapshot.setdefault("params", {})
            params.update((int(k), int(v)) for k, v in overlay)
        return snapshot

    def _bad(self, motor_id: int, problem: str) -> str:
        return bad_state_message(self._path, motor_id, problem)

    def motors(self) -> list[int]:
        """Motor IDs with anything saved."""
        with self._read() as conn:
            rows = conn.execute("SELECT motor_id FROM snapshot UNION"
                                " SELECT motor_id FROM param ORDER BY 1").fetchall()
        return [int(r[0]) for r in rows]

    def integrity_check(self) -> str:
        """SQLite ``PRAGMA integrity_check``: ``"ok"`` or the problems found."""
        import sqlite3
        try:
            rows = self._connection().execute("PRAGMA integrity_check").fetchall()
        except sqlite3.Error as exc:
            raise StoreError(f"{self._path}: integrity check failed: {exc}") from exc
        return "\n".join(str(r[0]) for r in rows)

    # -- lifetime --------------------------------------------------------------

    def close(self) -> None:
        """Close the file (idempotent); a writer lets the file go."""
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        self._unlock()

    def _unlock(self) -> None:
        if self._lock is not None:
            self._lock()                   # the lock goes with its file or connection
            self._lock = None

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- transactions ----------------------------------------------------------

    def _connection(self) -> sqlite3.Connection:
        if self._conn is None:
            raise StoreError(f"{self._path}: store is closed")
        return self._conn

    @contextmanager
    def _write(self) -> Iterator[sqlite3.Connection]:
        with self._transaction("BEGIN IMMEDIATE") as conn:
            yield conn

    @contextmanager
    def _read(self) -> Iterator[sqlite3.Connection]:
        with self._transaction("BEGIN") as conn:
            yield conn

    @contextmanager
    def _transaction(self, begin: str) -> Iterator[sqlite3.Connection]:
        import sqlite3
        conn = self._connection()
        try:
            conn.execute(begin)
            try:
                yield conn
                conn.execute("COMMIT")
            except BaseException:
                if conn.in_transaction:
                    conn.execute("ROLLBACK")
                raise
        except sqlite3.Error as exc:
            raise StoreError(f"{self._path}: {exc}") from exc


# -- opening -----------------------------------------------------------------------

def bad_state_message(path: str, motor_id: int, problem: str) -> str:
    """One message naming the file, the entry and how to recover."""
    return (f"{path}: saved state of motor {motor_id}: {problem}; move the file aside "
            f"(mv {path} {path}.bad) to start with defaults, or start with --no-state")


def _writer_lock(path: str) -> Callable[[], None] | None:
    """The lock of this writer on ``PATH`` (held until the function returned is called,
    or until the process ends however it ends), or :class:`StoreError` naming the
    holder.  Two chains saving into one store would each overwrite the other's
    snapshots.  ``PATH.lock`` holds the writer's process ID.

    Where there is ``flock`` (POSIX) ``PATH.lock`` is the locked file; elsewhere
    (Windows) the lock is an exclusive transaction of SQLite on ``PATH.writer``, held
    open (:func:`_sqlite_lock`: SQLite takes the system's own file locks, which the
    system releases when the process ends)."""
    if path == ":memory:":
        return None
    lock_path = path + ".lock"
    try:
        Path(lock_path).parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StoreError(f"cannot lock {path}: {exc.strerror or exc}") from exc
    fd = open_lock_file(lock_path)
    release: Callable[[], None] | None
    if fcntl is not None:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            release = None
        else:
            def release() -> None:
                os.close(fd)                   # the flock goes with its file description
    else:
        release = _sqlite_lock(path + ".writer")
        if release is not None:
            held = release

            def release() -> None:
                os.close(fd)
                held()
    if release is None:
        try:
            holder = os.read(fd, 32).decode("ascii", "replace").strip() or "?"
        except OSError:
            holder = "?"
        os.close(fd)
        raise StoreError(f"{Path(path).parent} is in use: another coolmuscle (pid {holder}) "
                         "runs a chain on this state; one chain per state directory "
                         "(give this one another --state DIR, or --no-state)") from None
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
    except OSError:
        pass                       # the lock holds; only the pid shown to others is lost
    return release


def _sqlite_lock(path: str) -> Callable[[], None] | None:
    """An exclusive transaction on the SQLite database ``path`` (an empty one serves),
    held until the function returned is called; ``None`` when another connection holds
    it.  The portable lock where ``flock`` is missing."""
    import sqlite3
    try:
        conn = sqlite3.connect(path, timeout=0, isolation_level=None, check_same_thread=False)
    except sqlite3.Error as exc:
        raise StoreError(f"cannot lock {path}: {exc}") from exc
    try:
        conn.execute("BEGIN EXCLUSIVE")
    except sqlite3.OperationalError:         # "database is locked": another writer
        conn.close()
        return None
    except sqlite3.Error as exc:
        conn.close()
        raise StoreError(f"cannot lock {path}: {exc}; remove it (it holds nothing)") from exc
    return conn.close


#: Opening the lock file never follows a symbolic link at its name (``O_NOFOLLOW``,
#: where the system has it) and never waits on a FIFO or a device (``O_NONBLOCK``).
_LOCK_FLAGS = (os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
               | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0))


def open_lock_file(lock_path: str) -> int:
    """``lock_path`` opened for reading and writing (created if missing), only when it
    is a regular file: a symbolic link (whose target start-up would otherwise truncate
    and write a PID into), a directory, a FIFO or a device is refused with one line
    (:class:`StoreError`) and left untouched.  Where ``O_NOFOLLOW`` is missing the name
    is looked at first (``lstat``) as well."""
    if not getattr(os, "O_NOFOLLOW", 0) and os.path.islink(lock_path):
        raise StoreError(_not_a_lock_file(lock_path, "a symbolic link"))
    try:
        fd = os.open(lock_path, _LOCK_FLAGS, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP or os.path.islink(lock_path):
            raise StoreError(_not_a_lock_file(lock_path, "a symbolic link")) from None
        if exc.errno == errno.EISDIR:
            raise StoreError(_not_a_lock_file(lock_path, "a directory")) from None
        raise StoreError(f"cannot lock {lock_path}: {exc.strerror or exc}") from exc
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        raise StoreError(_not_a_lock_file(lock_path, _kind(mode)))
    return fd


def _not_a_lock_file(lock_path: str, kind: str) -> str:
    return (f"{lock_path} is {kind}, not the store's lock file: left as it is; remove it "
            f"(rm {lock_path}) and start again, or give another --state DIR")


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _open(path: str) -> sqlite3.Connection:
    import sqlite3
    if path != ":memory:":
        try:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StoreError(f"cannot create the state directory for {path}: {exc}") from exc
        try:
            size = os.stat(path).st_size
        except FileNotFoundError:
            _create(path)
        except OSError as exc:
            raise StoreError(f"cannot open store {path}: {exc.strerror or exc}") from exc
        else:
            if size == 0:    # never written by us (a new store appears whole): truncated
                raise _damaged(path, "is empty (0 bytes), not a coolmuscle store")
    try:
        conn = sqlite3.connect(path, timeout=BUSY_TIMEOUT_S, isolation_level=None,
                               check_same_thread=False)
    except sqlite3.Error as exc:
        if disk_full(path, exc):
            raise StoreError(full_disk_message(path, "open")) from exc
        raise StoreError(f"cannot open store {path}: {exc}") from exc
    try:
        _prepare(conn, path)
    except StoreError:
        conn.close()
        raise
    except sqlite3.Error as exc:
        conn.close()
        if disk_full(path, exc):
            raise StoreError(full_disk_message(path, "open")) from exc
        raise _damaged(path, f"is not a usable coolmuscle store: {exc}") from exc
    return conn


#: Free bytes below which an I/O error of SQLite is read as a full disk: opening a
#: store in WAL mode makes its 32 KiB shared-memory file and writes WAL pages.
FULL_DISK_MARGIN = 1 << 20


def disk_full(path: str, exc: Exception) -> bool:
    """Whether ``exc`` (an SQLite or OS error on ``path``) comes from a full disk: SQLite
    says so (``SQLITE_FULL``, ``ENOSPC``), or says only "disk I/O error" (it does when
    it cannot size its shared-memory file) while the disk has almost no room left."""
    if getattr(exc, "sqlite_errorname", "") == "SQLITE_FULL" or \
            getattr(exc, "errno", None) == errno.ENOSPC:
        return True
    if not str(getattr(exc, "sqlite_errorname", "")).startswith("SQLITE_IOERR"):
        return False
    return free_bytes(os.path.dirname(os.path.abspath(path))) < FULL_DISK_MARGIN


def free_bytes(directory: str) -> int:
    """Bytes free for this user in ``directory``'s file system (huge when unknown)."""
    import shutil
    try:
        return shutil.disk_usage(directory).free
    except OSError:
        return 1 << 62


def full_disk_message(path: str, doing: str) -> str:
    """One line for a store that cannot be opened or created because the disk is full."""
    directory = os.path.dirname(os.path.abspath(path))
    return (f"cannot {doing} store {path}: the disk is full ({free_bytes(directory)} bytes "
            f"free in {directory}); the store was not changed: free some space and start "
            "again, or start with --no-state")


def _damaged(path: str, problem: str) -> DamagedStoreError:
    """The error for a store file nothing can be read from, saying what to do."""
    return DamagedStoreError(f"{path} {problem}; move it aside (mv {path} {path}.bad) to "
                             "start with defaults, or start coolmuscle sim with --reset "
                             "(it keeps the file aside)", problem=problem)


def set_aside(path: str | os.PathLike[str]) -> str:
    """Move a damaged store (with its ``-wal`` and ``-shm``) aside, as ``PATH.bad`` (or
    ``PATH.bad.1``, ... when that is taken), under the writer lock: never a store a
    running chain holds.  Returns where it went; the next open starts a new store."""
    path = str(path)
    lock = _writer_lock(path)
    try:
        kept = path + ".bad"
        n = 0
        while any(os.path.exists(kept + tail) for tail in ("", "-wal", "-shm")):
            n += 1
            kept = f"{path}.bad.{n}"
        try:
            os.replace(path, kept)
            for tail in ("-wal", "-shm"):
                if os.path.exists(path + tail):
                    os.replace(path + tail, kept + tail)
        except OSError as exc:
            raise StoreError(f"cannot move {path} aside: {exc.strerror or exc}") from exc
        return kept
    finally:
        if lock is not None:
            lock()                          # released with its file or connection


def _create(path: str) -> None:
    """A new store appears whole: built under a temporary name, then renamed, so a
    crash while creating it never leaves a 0-byte or half-made file at ``path``."""
    import sqlite3
    tmp = f"{path}.{os.getpid()}.new"
    try:
        for leftover in (tmp, tmp + "-wal", tmp + "-shm"):
            if os.path.exists(leftover):
                os.unlink(leftover)
        conn = sqlite3.connect(tmp, isolation_level=None)
        try:
            _prepare(conn, tmp)
        finally:
            conn.close()
        os.replace(tmp, path)
    except (sqlite3.Error, OSError) as exc:
        if disk_full(path, exc):
            raise StoreError(full_disk_message(path, "create")) from exc
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise StoreError(f"cannot create store {path}: {reason}") from exc


def _prepare(conn: sqlite3.Connection, path: str) -> None:
    """Check the file is ours (or new), set WAL + FULL, create the schema."""
    app_id = conn.execute("PRAGMA application_id").fetchone()[0]
    version = conn.execute("PRAGMA user_version").fetchone()[0]
    objects = conn.execute("SELECT count(*) FROM sqlite_master").fetchone()[0]
    fresh = app_id == 0 and version == 0 and objects == 0
    if not fresh and app_id != APPLICATION_ID:
        raise _damaged(path, "is an SQLite file but not a coolmuscle store")
    if not fresh and not 1 <= version <= SCHEMA_VERSION:
        raise StoreError(f"{path}: store schema {version} is not supported "
                         f"(this version reads 1..{SCHEMA_VERSION})")
    mode = conn.execute("PRAGMA journal_mode=WAL").fetchone()[0]
    if str(mode).lower() != "wal" and path != ":memory:":
        raise StoreError(f"{path}: cannot use write-ahead logging (journal mode {mode})")
    conn.execute("PRAGMA synchronous=FULL")
    if fresh:
        conn.execute("BEGIN IMMEDIATE")
        for statement in _SCHEMA:
            conn.execute(statement)
        conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        conn.execute("COMMIT")
    check = conn.execute("PRAGMA quick_check").fetchone()[0]
    if check != "ok":
        raise _damaged(path, f"is damaged: {check}")


# -- encoding ----------------------------------------------------------------------

def _encode(snapshot: Mapping[str, Any]) -> str:
    if not isinstance(snapshot, Mapping):
        raise ValueError("a snapshot is a mapping")
    data = dict(snapshot)
    if "params" in data:
        data["params"] = {str(int(k)): v for k, v in dict(data["params"]).items()}
    try:
        text = json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"snapshot is not JSON data: {exc}") from exc
    if json.loads(text) != data:
        raise ValueError("snapshot would not load back equal (tuples or non-string keys?)")
    return text


def _decode(text: str, motor_id: int, path: str = "") -> dict[str, Any]:
    try:
        data = json.loads(text)
        if not isinstance(data, dict):
            raise TypeError("the snapshot is not an object")
        if "params" in data:
            if not isinstance(data["params"], dict):
                raise TypeError("'params' is not an object")
            data["params"] = {int(k): v for k, v in data["params"].items()}
    except (ValueError, TypeError) as exc:
        raise StoreError(bad_state_message(path, motor_id,
                                           f"the $ snapshot is unreadable ({exc})")) from exc
    except RecursionError:           # JSON nested deeper than Python decodes
        raise StoreError(bad_state_message(path, motor_id, "the $ snapshot is unreadable "
                                           "(nested too deeply)")) from None
    return data


def snapshot_problem(snapshot: Mapping[str, Any]) -> str:
    """What is wrong with the shape of a loaded motor snapshot (``""``: nothing).

    The store itself keeps any JSON data; this checks the shape the motor writes (module
    docstring): ``params`` K number -> integer, ``memory`` an object of register lists,
    ``banks`` ``{"program"|"ladder": {"N": [line, ...]}}``.  Values are checked by the motor
    as it restores them.
    """
    params = snapshot.get("params", {})
    if not isinstance(params, Mapping):
        return "'params' is not an object"
    for k, v in params.items():
        if not (_is_int(k) and _is_int(v)):
            return f"parameter K{k}={v!r} is not an integer"
    memory = snapshot.get("memory", {})
    if not isinstance(memory, Mapping):
        return f"'memory' is a {type(memory).__name__}, not an object"
    for kind, cells in memory.items():
        if kind != "alloc" and not isinstance(cells, list):
            return f"memory '{kind}' is a {type(cells).__name__}, not a list"
    banks = snapshot.get("banks", {})
    if not isinstance(banks, Mapping):
        return f"'banks' is a {type(banks).__name__}, not an object"
    for kind, table in banks.items():
        if not isinstance(table, Mapping):
            return f"banks '{kind}' is a {type(table).__name__}, not an object"
        for number, lines in table.items():
            if not str(number).isdigit():
                return f"{kind} bank {number!r} is not a bank number"
            if not isinstance(lines, list) or not all(isinstance(t, str) for t in lines):
                return f"{kind} bank {number} is not a list of lines"
    return ""


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _motor(motor_id: int) -> int:
    if not _is_int(motor_id) or not 1 <= motor_id <= 15:
        raise ValueError(f"motor ID {motor_id!r} is not 1..15")
    return motor_id
