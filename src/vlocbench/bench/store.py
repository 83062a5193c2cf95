"""The results store: one SQLite file and one folder of Parquet tables per episode, in the output
folder; no server.

- ``results.sqlite``: the experiment this folder belongs to, one row per run (a resolved spec and
  its hash), one row per episode (its key, resolved config and hash, metrics or error, the id of
  the platform it ran on), which episodes each run asked for, and each platform's record
  (:mod:`vlocbench.bench.platform`).
- ``episodes/KEY/trajectory.parquet`` (per simulation step: time, true pose, EKF pose, speed) and
  ``localizations.parquet`` (per query: estimate, truth, EKF pose, errors, compute time).

An episode is written in two steps: its tables go to a temporary folder that is renamed into place,
then its row is committed in one transaction. A kill at any moment leaves either no row (the
episode reruns; a leftover folder is replaced) or a complete episode. Only the driver writes; a
lock file keeps a second driver out.
"""

from __future__ import annotations

import dataclasses
import errno
import fcntl
import json
import os
import shutil
import sqlite3
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from vlocbench.bench.metrics import EpisodeMetrics
from vlocbench.bench.platform import Platform
from vlocbench.bench.records import EpisodeResult, localization_columns
from vlocbench.config import config_hash
from vlocbench.errors import MachineError, VlocbenchError

DB_FILE = "results.sqlite"
LOCK_FILE = ".lock"
EPISODES_DIR = "episodes"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    run_hash TEXT PRIMARY KEY, started REAL NOT NULL, spec TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS episodes (
    key TEXT PRIMARY KEY, kind TEXT NOT NULL, town TEXT NOT NULL, method TEXT NOT NULL,
    setup TEXT NOT NULL, repetition INTEGER NOT NULL, seed INTEGER NOT NULL,
    config TEXT NOT NULL, status TEXT NOT NULL, error TEXT, metrics TEXT,
    wall_s REAL, attempts INTEGER NOT NULL, finished REAL NOT NULL, platform TEXT);
CREATE TABLE IF NOT EXISTS run_episodes (
    run_hash TEXT NOT NULL, key TEXT NOT NULL, PRIMARY KEY (run_hash, key));
CREATE TABLE IF NOT EXISTS platforms (id TEXT PRIMARY KEY, record TEXT NOT NULL);
"""
EPISODE_COLUMNS = (
    "key",
    "kind",
    "town",
    "method",
    "setup",
    "repetition",
    "seed",
    "config",
    "status",
    "error",
    "metrics",
    "wall_s",
    "attempts",
    "finished",
    "platform",
)


class StoreError(VlocbenchError, RuntimeError):
    """The output folder cannot take or give these results (another experiment's, not a store)."""


class StoreUnavailableError(StoreError, MachineError):
    """The machine stops the store: the folder cannot be written, is full or another run holds it."""


@dataclass(frozen=True, kw_only=True)
class EpisodeRow:
    key: str
    kind: str
    town: str
    method: str
    setup: str
    repetition: int
    seed: int
    config: dict[str, Any]
    status: str  # "ok" or "error"
    error: str | None
    metrics: EpisodeMetrics | None  # None: the episode ended in an error
    wall_s: float | None
    attempts: int
    platform: str | None = None  # the id of the platform it ran on; None: not recorded (older)


def run_hash(keys: Iterable[str]) -> str:
    """A run's identity: the set of its episodes' keys. The same experiment with a setting, or
    EPISODE_VERSION, changed is another run, so its report never mixes in the other's episodes
    (its own rows are still in the store, found by key)."""
    return config_hash(sorted(set(keys)), 16)


def strict_json(value: Any) -> str:
    """``value`` as strict JSON (keys sorted): NaN and infinities become null, so that SQLite's
    ``json_extract``, DuckDB and other JSON readers accept every stored row."""
    return json.dumps(_finite(value), sort_keys=True, allow_nan=False)


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if np.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def _nan_for_null(value: Any) -> Any:
    """Metrics hold only numbers, flags and names: a null in them was a NaN (see strict_json)."""
    if value is None:
        return float("nan")
    if isinstance(value, dict):
        return {k: _nan_for_null(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_nan_for_null(v) for v in value]
    return value


def _episode_row(
    key: str,
    kind: str,
    town: str,
    method: str,
    setup: str,
    repetition: int,
    seed: int,
    config: str,
    status: str,
    error: str | None,
    metrics: str | None,
    wall_s: float | None,
    attempts: int,
    finished: float,
    platform: str | None = None,  # a store written before platforms were recorded has no column
) -> EpisodeRow:
    """An ``episodes`` table row (its columns in schema order) as an EpisodeRow."""
    return EpisodeRow(
        key=key,
        kind=kind,
        town=town,
        method=method,
        setup=setup,
        repetition=repetition,
        seed=seed,
        config=json.loads(config),
        status=status,
        error=error,
        metrics=EpisodeMetrics.from_stored(_nan_for_null(json.loads(metrics))) if metrics else None,
        wall_s=wall_s,
        attempts=attempts,
        platform=platform,
    )


def _latest_run(db: sqlite3.Connection) -> tuple[str, str] | None:
    """(run hash, resolved spec JSON) of the most recently started run."""
    return db.execute("SELECT run_hash, spec FROM runs ORDER BY started DESC LIMIT 1").fetchone()


def _run_rows(db: sqlite3.Connection, run_hash: str) -> list[EpisodeRow]:
    """The episodes a run asked for that have a result, by key."""
    cur = db.execute(
        "SELECT e.* FROM episodes e JOIN run_episodes r ON e.key = r.key "
        "WHERE r.run_hash = ? ORDER BY e.key",
        (run_hash,),
    )
    return [_episode_row(*row) for row in cur]


@contextmanager
def _read_only(output_dir: str | Path) -> Iterator[sqlite3.Connection]:
    """The store of ``output_dir``, read-only and without the lock (a run may be writing
    meanwhile)."""
    db_path = Path(output_dir) / DB_FILE
    if not db_path.is_file():
        raise StoreError(f"{output_dir} holds no vlocbench results ({DB_FILE} is missing)")
    try:
        db = sqlite3.connect(f"file:{db_path}?mode=ro", uri=True)
        try:
            yield db
        finally:
            db.close()
    except sqlite3.DatabaseError as exc:
        raise StoreError(f"{db_path} is not a vlocbench store: {exc}") from None


def read_latest_run(output_dir: str | Path) -> tuple[dict[str, Any], list[EpisodeRow]]:
    """The latest run's resolved spec and episodes."""
    with _read_only(output_dir) as db:
        last = _latest_run(db)
        if last is None:
            raise StoreError(f"{output_dir} has no run yet")
        return json.loads(last[1]), _run_rows(db, last[0])


def count_episodes(output_dir: str | Path) -> int:
    """How many episodes are stored, whichever run asked for them (none read)."""
    with _read_only(output_dir) as db:
        return int(db.execute("SELECT COUNT(*) FROM episodes").fetchone()[0])


def read_episodes(output_dir: str | Path) -> list[EpisodeRow]:
    """Every stored episode, whichever run asked for it, by key."""
    with _read_only(output_dir) as db:
        return [_episode_row(*row) for row in db.execute("SELECT * FROM episodes ORDER BY key")]


def read_platforms(output_dir: str | Path) -> dict[str, dict[str, Any]]:
    """The record of each platform the store's episodes ran on (``Platform.to_dict``), by id."""
    with _read_only(output_dir) as db:
        tables = {n for (n,) in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if "platforms" not in tables:  # written before platforms were recorded
            return {}
        return {i: json.loads(r) for i, r in db.execute("SELECT id, record FROM platforms")}


def count_platforms(output_dir: str | Path) -> dict[str | None, int]:
    """The finished episodes by the id of the platform they ran on (None: not recorded)."""
    with _read_only(output_dir) as db:
        return _platform_counts(db)


def _map_dirs(db: sqlite3.Connection) -> dict[str, str]:
    query = "SELECT key, json_extract(config, '$.map_dir') FROM episodes WHERE status='ok'"
    return {k: m for k, m in db.execute(query) if m}


def read_map_dirs(output_dir: str | Path) -> dict[str, str]:
    """The map folder each finished episode was driven with, by key (those with a map)."""
    with _read_only(output_dir) as db:
        return _map_dirs(db)


def _table_columns(db: sqlite3.Connection, table: str) -> set[str]:
    return {c for _, c, *_ in db.execute(f"PRAGMA table_info({table})")}


def _platform_counts(db: sqlite3.Connection) -> dict[str | None, int]:
    # a store from before platforms were recorded, read-only, has no column
    column = "platform" if "platform" in _table_columns(db, "episodes") else "NULL"
    query = f"SELECT {column}, count(*) FROM episodes WHERE status='ok' GROUP BY 1"
    return dict(db.execute(query).fetchall())


def _columns(result: EpisodeResult) -> tuple[dict[str, Any], dict[str, Any]]:
    import pyarrow as pa

    tr = result.trajectory
    trajectory = {f.name: getattr(tr, f.name) for f in dataclasses.fields(tr)}
    localizations = localization_columns(result.localizations)
    if "stage_s" in localizations:  # a map column: parquet cannot hold a struct without fields
        stages = [list(d.items()) for d in localizations["stage_s"]]
        localizations["stage_s"] = pa.array(stages, pa.map_(pa.string(), pa.float64()))
    return trajectory, localizations


def _make_strict(db: sqlite3.Connection) -> None:
    """Rewrite as strict JSON the rows that a store written before ``strict_json`` holds with
    NaN in them (SQLite's JSON functions stop at such a row)."""
    for table, key, column in (
        ("episodes", "key", "config"),
        ("episodes", "key", "metrics"),
        ("runs", "run_hash", "spec"),
    ):
        bad = db.execute(
            f"SELECT {key}, {column} FROM {table} WHERE {column} NOTNULL AND NOT json_valid({column})"
        ).fetchall()
        for k, text in bad:  # Python's json reads NaN
            db.execute(
                f"UPDATE {table} SET {column}=? WHERE {key}=?", (strict_json(json.loads(text)), k)
            )


class ResultStore:
    """The results of one experiment in ``root``; use as a context manager (holds the lock)."""

    def __init__(self, root: str | Path, experiment: str) -> None:
        self.root = Path(root)
        self.experiment = experiment
        self._lock: Any = None
        self.db: sqlite3.Connection | None = None

    def __enter__(self) -> ResultStore:
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            self._lock = open(self.root / LOCK_FILE, "w")  # held until close()
        except OSError as exc:
            raise StoreUnavailableError(
                f"cannot use {self.root} as an output folder: {exc}"
            ) from None
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._lock.close()
            raise StoreUnavailableError(f"{self.root} is in use by another vlocbench run") from None
        try:
            self.db = sqlite3.connect(self.root / DB_FILE, isolation_level=None)
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=FULL")
            self.db.executescript(_SCHEMA)
            if "platform" not in _table_columns(self.db, "episodes"):  # a store from before
                self.db.execute("ALTER TABLE episodes ADD COLUMN platform TEXT")
            row = self.db.execute("SELECT value FROM meta WHERE key='experiment'").fetchone()
        except sqlite3.DatabaseError as exc:
            self.close()
            raise StoreError(f"{self.root / DB_FILE} is not a vlocbench store: {exc}") from None
        _make_strict(self.db)
        if row is None:
            self.db.execute("INSERT INTO meta VALUES ('experiment', ?)", (self.experiment,))
        elif row[0] != self.experiment:
            other = row[0]
            self.close()
            raise StoreError(
                f"{self.root} holds results of experiment {other!r}, not {self.experiment!r}; "
                "choose another output folder"
            )
        for orphan in (self.root / EPISODES_DIR).glob("*.tmp-*"):  # from a killed driver
            shutil.rmtree(orphan, ignore_errors=True)
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self.db is not None:
            self.db.close()
            self.db = None
        if self._lock is not None:
            self._lock.close()
            self._lock = None

    @property
    def _conn(self) -> sqlite3.Connection:
        if self.db is None:
            raise StoreError("the store is closed")
        return self.db

    @contextmanager
    def _transaction(self, what: str) -> Iterator[sqlite3.Connection]:
        db = self._conn
        try:
            db.execute("BEGIN IMMEDIATE")
            yield db
            db.execute("COMMIT")
        except sqlite3.OperationalError as exc:
            if db.in_transaction:
                db.execute("ROLLBACK")
            raise StoreUnavailableError(f"could not write {what} to {self.root}: {exc}") from None

    def start_run(self, run_hash: str, spec: dict[str, Any], keys: list[str]) -> None:
        """Record a run (its resolved spec) and the episodes it consists of."""
        with self._transaction("the run") as db:
            db.execute(
                "INSERT INTO runs VALUES (?, ?, ?) "
                "ON CONFLICT(run_hash) DO UPDATE SET started = excluded.started",
                (run_hash, time.time(), strict_json(spec)),
            )
            db.executemany(
                "INSERT OR IGNORE INTO run_episodes VALUES (?, ?)", [(run_hash, k) for k in keys]
            )

    def done_keys(self) -> set[str]:
        """Keys of the episodes finished without error."""
        return {k for (k,) in self._conn.execute("SELECT key FROM episodes WHERE status='ok'")}

    def platform_counts(self) -> dict[str | None, int]:
        """The finished episodes by the id of the platform they ran on (None: not recorded)."""
        return _platform_counts(self._conn)

    def stored_map_dirs(self) -> dict[str, str]:
        """The map folder each finished episode was driven with, by key (those with a map)."""
        return _map_dirs(self._conn)

    def episode_dir(self, key: str) -> Path:
        return self.root / EPISODES_DIR / key

    def write_episode(
        self,
        row: EpisodeRow,
        result: EpisodeResult | None,
        platform: Platform | None = None,
    ) -> None:
        """Write one episode atomically (its tables first, then its row and its platform's
        record, whose id ``row.platform`` names)."""
        if result is not None:
            self._place_folder(row.key, lambda tmp: _write_tables(tmp, result))
        with self._transaction(f"episode {row.key}") as db:
            if platform is not None:
                _insert_platform(db, platform.id, strict_json(platform.to_dict()))
            _insert_episode(
                db,
                {
                    "key": row.key,
                    "kind": row.kind,
                    "town": row.town,
                    "method": row.method,
                    "setup": row.setup,
                    "repetition": row.repetition,
                    "seed": row.seed,
                    "config": strict_json(row.config),
                    "status": row.status,
                    "error": row.error,
                    "metrics": None if row.metrics is None else strict_json(asdict(row.metrics)),
                    "wall_s": row.wall_s,
                    "attempts": row.attempts,
                    "finished": time.time(),
                    "platform": row.platform,
                },
            )

    def adopt(self, source: str | Path, keys: Iterable[str]) -> list[str]:
        """Copy from the store in ``source`` (another experiment's, read without its lock) the
        episodes among ``keys`` that it finished and this store has not: each as
        :meth:`write_episode` writes one (its tables, then its row with the platform's record),
        unchanged (where and when it ran included). A key hashes everything that determines an
        episode's result, so another experiment's episode of the same key is this one's. Returns
        the keys copied."""
        source = Path(source)
        if source.resolve() == self.root.resolve():
            raise StoreError(f"{source} is this run's own output folder: nothing to take from it")
        wanted = sorted(set(keys) - self.done_keys())
        with _read_only(source) as src:
            have = _table_columns(src, "episodes")
            # a store from before platforms were recorded has no column for them
            select = ", ".join(c if c in have else f"NULL AS {c}" for c in EPISODE_COLUMNS)
            rows = [
                dict(zip(EPISODE_COLUMNS, r, strict=True))
                for k in wanted
                for r in src.execute(
                    f"SELECT {select} FROM episodes WHERE key=? AND status='ok'", (k,)
                )
            ]
            ids = {r["platform"] for r in rows} - {None}
            platforms = dict(src.execute("SELECT id, record FROM platforms")) if ids else {}
        # a row whose folder is missing (a damaged store) is driven here instead
        rows = [r for r in rows if (source / EPISODES_DIR / r["key"]).is_dir()]
        for row in rows:
            key = row["key"]
            for column in ("config", "metrics"):  # an older store's NaN as null (strict_json)
                row[column] = strict_json(json.loads(row[column]))
            self._place_folder(key, partial(shutil.copytree, source / EPISODES_DIR / key))
            with self._transaction(f"episode {key}") as db:
                if row["platform"] in platforms:
                    _insert_platform(db, row["platform"], platforms[row["platform"]])
                _insert_episode(db, row)
        return [r["key"] for r in rows]

    def _place_folder(self, key: str, fill: Callable[[Path], object]) -> None:
        """An episode's folder, made whole under a temporary name by ``fill(tmp)`` (which creates
        ``tmp``), then renamed into place."""
        final = self.episode_dir(key)
        tmp = final.with_name(f"{key}.tmp-{os.getpid()}")
        try:
            shutil.rmtree(tmp, ignore_errors=True)
            fill(tmp)
            if final.exists():  # left by an attempt killed before its row was committed
                shutil.rmtree(final)
            os.replace(tmp, final)
        except OSError as exc:
            shutil.rmtree(tmp, ignore_errors=True)
            full = exc.errno in (errno.ENOSPC, errno.EDQUOT)
            raise StoreUnavailableError(
                f"could not write episode {key} to {self.root}"
                + (" (disk full)" if full else "")
                + f": {exc}; finished episodes are intact, rerun to resume"
            ) from None

    def rows(self, run_hash: str | None = None) -> list[EpisodeRow]:
        """Episodes of ``run_hash`` (default: the latest run), finished or failed."""
        if run_hash is None:
            last = _latest_run(self._conn)
            if last is None:
                return []
            run_hash = last[0]
        return _run_rows(self._conn, run_hash)

    def read_table(self, key: str, name: str) -> dict[str, np.ndarray]:
        """One episode's ``trajectory`` or ``localizations`` table as numpy columns."""
        return read_episode_table(self.root, key, name)


def _write_tables(folder: Path, result: EpisodeResult) -> None:
    """``folder`` (new) with the episode's trajectory and localizations as Parquet."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    trajectory, localizations = _columns(result)
    folder.mkdir(parents=True)
    pq.write_table(
        pa.table({k: np.asarray(v) for k, v in trajectory.items()}),
        folder / "trajectory.parquet",
    )
    pq.write_table(pa.table(localizations), folder / "localizations.parquet")


def _insert_platform(db: sqlite3.Connection, platform_id: str, record: str) -> None:
    db.execute("INSERT OR IGNORE INTO platforms VALUES (?, ?)", (platform_id, record))


def _insert_episode(db: sqlite3.Connection, columns: dict[str, Any]) -> None:
    """An episode's row (:data:`EPISODE_COLUMNS`), replacing a failed attempt's."""
    db.execute(
        f"INSERT OR REPLACE INTO episodes ({', '.join(EPISODE_COLUMNS)}) "
        f"VALUES ({', '.join(':' + c for c in EPISODE_COLUMNS)})",
        columns,
    )


def read_episode_table(output_dir: str | Path, key: str, name: str) -> dict[str, np.ndarray]:
    """One stored episode's ``trajectory`` or ``localizations`` table as numpy columns, without
    the lock (a committed episode's tables never change)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(output_dir) / EPISODES_DIR / key / f"{name}.parquet"
    if not path.is_file():
        raise StoreError(f"{output_dir} has no {name} table for episode {key}")
    table = pq.read_table(path)
    columns = {}
    for column_name, column in zip(table.column_names, table.columns, strict=True):
        if pa.types.is_map(column.type):  # e.g. stage_s: a dict a row
            rows = [dict(row) for row in column.to_pylist()]
            columns[column_name] = np.array(rows, dtype=object)
        else:
            columns[column_name] = column.to_numpy(zero_copy_only=False)
    return columns
