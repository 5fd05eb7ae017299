"""The trial ledger: one SQLite file per experiment directory (WAL mode), written by one
process as results arrive, so that an interrupted experiment resumes where it stopped.

Tables (every row keyed by the config hash, so different experiments in one file stay
apart): ``runs`` (config, versions, machine, start and end of each invocation), ``plans``
(one row per scene x realisation x planner), ``analytic`` (the plan's Monte-Carlo P_F),
``trials`` (one row per physics trial). Rows are inserted in one transaction per task
result with ``INSERT OR IGNORE`` on their keys: a result is either wholly in the ledger or
not at all, and nothing is ever counted twice.
"""

from __future__ import annotations

import json
import sqlite3
from datetime import UTC, datetime
from pathlib import Path

import pandas as pd

from harness.errors import InputError

FORMAT = "gpis-harness ledger 2"
#: Format 1 lacked the analytic P_L: a format-1 ledger gains its columns (empty for the
#: rows it holds) when opened.
_MIGRATIONS = {"gpis-harness ledger 1": ("ALTER TABLE analytic ADD COLUMN p_l REAL",
                                         "ALTER TABLE analytic ADD COLUMN p_l_ci_low REAL",
                                         "ALTER TABLE analytic ADD COLUMN p_l_ci_high REAL",
                                         "ALTER TABLE analytic ADD COLUMN pivots INTEGER",
                                         "ALTER TABLE analytic ADD COLUMN reasons TEXT")}
FILENAME = "ledger.sqlite"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    run INTEGER PRIMARY KEY AUTOINCREMENT, config_hash TEXT NOT NULL, name TEXT NOT NULL,
    config TEXT NOT NULL, environment TEXT NOT NULL, started TEXT NOT NULL, ended TEXT,
    status TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS plans (
    config_hash TEXT NOT NULL, scene TEXT NOT NULL, realisation INTEGER NOT NULL,
    planner TEXT NOT NULL, planner_name TEXT NOT NULL, params TEXT NOT NULL,
    status TEXT NOT NULL, executed INTEGER NOT NULL, message TEXT NOT NULL,
    g1x REAL, g1y REAL, g2x REAL, g2y REAL, estimate REAL, plan_time_s REAL NOT NULL,
    iterations INTEGER NOT NULL, evaluations INTEGER NOT NULL, trace TEXT NOT NULL,
    PRIMARY KEY (config_hash, scene, realisation, planner));
CREATE TABLE IF NOT EXISTS analytic (
    config_hash TEXT NOT NULL, scene TEXT NOT NULL, realisation INTEGER NOT NULL,
    planner TEXT NOT NULL, draws INTEGER NOT NULL, p_f REAL NOT NULL, ci_low REAL NOT NULL,
    ci_high REAL NOT NULL, ferrari_canny_mean REAL NOT NULL, failures TEXT NOT NULL,
    p_l REAL, p_l_ci_low REAL, p_l_ci_high REAL, pivots INTEGER, reasons TEXT,
    PRIMARY KEY (config_hash, scene, realisation, planner));
CREATE TABLE IF NOT EXISTS trials (
    config_hash TEXT NOT NULL, scene TEXT NOT NULL, realisation INTEGER NOT NULL,
    planner TEXT NOT NULL, shapes TEXT NOT NULL, trial INTEGER NOT NULL, outcome TEXT NOT NULL,
    steps INTEGER NOT NULL, grip_width REAL, closing_turn REAL, rise REAL, pivot REAL,
    PRIMARY KEY (config_hash, scene, realisation, planner, shapes, trial));
"""

_COLUMNS = {
    "plans": ("scene", "realisation", "planner", "planner_name", "params", "status", "executed", "message",
              "g1x", "g1y", "g2x", "g2y", "estimate", "plan_time_s", "iterations", "evaluations", "trace"),
    "analytic": ("scene", "realisation", "planner", "draws", "p_f", "ci_low", "ci_high", "ferrari_canny_mean",
                 "failures", "p_l", "p_l_ci_low", "p_l_ci_high", "pivots", "reasons"),
    "trials": ("scene", "realisation", "planner", "shapes", "trial", "outcome", "steps", "grip_width",
               "closing_turn", "rise", "pivot"),
}


#: What each column must hold, checked when a ledger is opened (a hand-edited or damaged
#: row is bad input, not a traceback later): "int", "real" (an integer passes), "text",
#: "json" (text that parses); a trailing "?" allows NULL.
_KINDS = {
    "runs": {"run": "int", "config_hash": "text", "name": "text", "config": "json", "environment": "json",
             "started": "text", "ended": "text?", "status": "text"},
    "plans": {"config_hash": "text", "scene": "text", "realisation": "int", "planner": "text",
              "planner_name": "text", "params": "json", "status": "text", "executed": "int", "message": "text",
              "g1x": "real?", "g1y": "real?", "g2x": "real?", "g2y": "real?", "estimate": "real?",
              "plan_time_s": "real", "iterations": "int", "evaluations": "int", "trace": "json"},
    "analytic": {"config_hash": "text", "scene": "text", "realisation": "int", "planner": "text", "draws": "int",
                 "p_f": "real", "ci_low": "real", "ci_high": "real", "ferrari_canny_mean": "real",
                 "failures": "json", "p_l": "real?", "p_l_ci_low": "real?", "p_l_ci_high": "real?",
                 "pivots": "int?", "reasons": "text?"},
    "trials": {"config_hash": "text", "scene": "text", "realisation": "int", "planner": "text", "shapes": "text",
               "trial": "int", "outcome": "text", "steps": "int", "grip_width": "real?", "closing_turn": "real?",
               "rise": "real?", "pivot": "real?"},
}
#: SQLite's storage classes each kind accepts.
_STORAGE = {"int": ("integer",), "real": ("integer", "real"), "text": ("text",), "json": ("text",)}
_EXPECTED = {"int": "an integer", "real": "a number", "text": "text", "json": "JSON text"}
#: The columns that name a row in an error message.
_ROW_KEYS = {"runs": ("run",), "plans": ("scene", "realisation", "planner"),
             "analytic": ("scene", "realisation", "planner"),
             "trials": ("scene", "realisation", "planner", "shapes", "trial")}


def now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


class Ledger:
    """The ledger of one experiment directory. Opening a file that is not a ledger (or is
    damaged) is bad input: one line naming the file."""

    def __init__(self, path: Path, create: bool = True):
        self.path = Path(path)
        if not create and not self.path.is_file():
            raise InputError(str(self.path), None, "no ledger here (run eval first)")
        if self.path.is_symlink():  # the folder's own file, never a link planted to write elsewhere
            raise InputError(str(self.path), None, "is a symbolic link; a results folder's ledger must be its own file")
        try:
            self.db = sqlite3.connect(self.path, timeout=30.0, isolation_level=None)
            self._check_or_create(create)
        except sqlite3.DatabaseError as exc:
            raise InputError(str(self.path), None, f"not a usable ledger ({exc})") from None

    def _check_or_create(self, create: bool) -> None:
        tables = {r[0] for r in self.db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if tables:
            found = None
            if "meta" in tables:
                row = self.db.execute("SELECT value FROM meta WHERE key = 'format'").fetchone()
                found = row[0] if row else None
            if found in _MIGRATIONS:
                with self.transaction():
                    for statement in _MIGRATIONS[found]:
                        self.db.execute(statement)
                    self.db.execute("UPDATE meta SET value = ? WHERE key = 'format'", (FORMAT,))
                found = FORMAT
            if found != FORMAT:
                raise InputError(str(self.path), None, "not a gpis-harness ledger (a foreign SQLite database)")
            missing = sorted({"runs", *_COLUMNS} - tables)
            if missing:
                raise InputError(str(self.path), None, f"the ledger is damaged (its table '{missing[0]}' is missing)")
            check = self.db.execute("PRAGMA quick_check").fetchone()[0]
            if check != "ok":
                raise InputError(str(self.path), None, f"the ledger is damaged ({check})")
        elif not create:
            raise InputError(str(self.path), None, "not a gpis-harness ledger (empty database)")
        self.db.execute("PRAGMA journal_mode = WAL")
        self.db.execute("PRAGMA synchronous = NORMAL")
        if not tables:  # one script, one transaction: a half-created ledger never exists
            self.db.executescript(f"BEGIN; {_SCHEMA} INSERT INTO meta VALUES ('format', '{FORMAT}'); COMMIT;")
        else:
            self._check_rows()

    def _check_rows(self) -> None:
        """Every row's columns hold what their kind says (_KINDS); InputError naming the
        table, the row and the column of the first that does not."""
        for table, kinds in _KINDS.items():
            for column, kind in kinds.items():
                nullable = kind.endswith("?")
                kind = kind.rstrip("?")
                allowed = _STORAGE[kind] + (("null",) if nullable else ())
                marks = ", ".join("?" * len(allowed))
                bad = self.db.execute(f"SELECT rowid, {column} FROM {table} WHERE typeof({column}) NOT IN ({marks}) "
                                      "ORDER BY rowid LIMIT 1", allowed).fetchone()
                if bad is not None:
                    self._bad_row(table, bad[0], column, f"expected {_EXPECTED[kind]}, got {bad[1]!r}")
                if kind != "json":
                    continue
                for rowid, text in self.db.execute(f"SELECT rowid, {column} FROM {table} WHERE {column} IS NOT NULL"):
                    try:
                        json.loads(text)
                    except ValueError as exc:
                        self._bad_row(table, rowid, column, f"is not valid JSON ({exc})")

    def _bad_row(self, table: str, rowid: int, column: str, problem: str):
        keys = _ROW_KEYS[table]
        values = self.db.execute(f"SELECT {', '.join(keys)} FROM {table} WHERE rowid = ?", (rowid,)).fetchone()
        which = ", ".join(f"{k} {v!r}" for k, v in zip(keys, values, strict=True))
        raise InputError(str(self.path), f"table {table}, row {rowid} ({which}), column {column}",
                         f"{problem}; the ledger was changed by hand or is damaged")

    def close(self) -> None:
        self.db.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def transaction(self):
        return _Transaction(self.db)

    # -- runs ---------------------------------------------------------------
    def start_run(self, config_hash: str, name: str, config: dict, environment: dict) -> int:
        with self.transaction():
            cur = self.db.execute(
                "INSERT INTO runs (config_hash, name, config, environment, started, status) "
                "VALUES (?, ?, ?, ?, ?, 'running')",
                (config_hash, name, json.dumps(config, sort_keys=True), json.dumps(environment, sort_keys=True),
                 now()))
        return int(cur.lastrowid)

    def end_run(self, run: int, status: str) -> None:
        with self.transaction():
            self.db.execute("UPDATE runs SET ended = ?, status = ? WHERE run = ?", (now(), status, run))

    def forget(self, config_hash: str) -> None:
        """Delete everything recorded under a config hash (``eval --fresh``)."""
        with self.transaction():
            for table in ("runs", "plans", "analytic", "trials"):
                self.db.execute(f"DELETE FROM {table} WHERE config_hash = ?", (config_hash,))

    def planner_entries(self, config_hash: str) -> dict[str, set[tuple[str, str]]]:
        """Per planner label recorded under a config hash: the (registry name, parameters
        as JSON) of its plans."""
        out: dict[str, set[tuple[str, str]]] = {}
        for label, name, params in self.db.execute("SELECT DISTINCT planner, planner_name, params FROM plans "
                                                   "WHERE config_hash = ?", (config_hash,)):
            out.setdefault(label, set()).add((name, params))
        return out

    def runs(self) -> pd.DataFrame:
        return pd.read_sql_query("SELECT * FROM runs ORDER BY run", self.db)

    def latest_hash(self) -> str:
        row = self.db.execute("SELECT config_hash FROM runs ORDER BY run DESC LIMIT 1").fetchone()
        if row is None:
            raise InputError(str(self.path), None, "the ledger holds no experiment yet")
        return row[0]

    # -- results ------------------------------------------------------------
    def add(self, config_hash: str, tables: dict[str, list[dict]]) -> None:
        """Insert rows (dicts with each table's columns) of several tables in one
        transaction; rows already present are left as they are."""
        with self.transaction():
            for table, rows in tables.items():
                columns = _COLUMNS[table]
                sql = (f"INSERT OR IGNORE INTO {table} (config_hash, {', '.join(columns)}) "
                       f"VALUES (?, {', '.join('?' * len(columns))})")
                self.db.executemany(sql, [(config_hash, *(row[c] for c in columns)) for row in rows])

    def table(self, config_hash: str, table: str) -> pd.DataFrame:
        """A table's rows under a config hash, in the order of its key (the report's
        bootstrap and retest pick trials by position: their order must not be the order in
        which the workers finished)."""
        columns = ", ".join(_COLUMNS[table])
        return pd.read_sql_query(f"SELECT {columns} FROM {table} WHERE config_hash = ? "
                                 f"ORDER BY {', '.join(_ROW_KEYS[table])}", self.db, params=(config_hash,))

    def rows(self, config_hash: str, table: str) -> list[dict]:
        """A table's rows under a config hash as stored (Python values, NULL as None),
        ready for :meth:`add`."""
        columns = _COLUMNS[table]
        cur = self.db.execute(f"SELECT {', '.join(columns)} FROM {table} WHERE config_hash = ? "
                              f"ORDER BY {', '.join(_ROW_KEYS[table])}", (config_hash,))
        return [dict(zip(columns, row)) for row in cur]

    def done_trials(self, config_hash: str, scene: str, realisation: int) -> set[tuple[str, str, int]]:
        rows = self.db.execute("SELECT planner, shapes, trial FROM trials WHERE config_hash = ? AND scene = ? "
                               "AND realisation = ?", (config_hash, scene, realisation))
        return {tuple(r) for r in rows}

    def plan_rows(self, config_hash: str, scene: str, realisation: int) -> dict[str, dict]:
        cur = self.db.execute(f"SELECT {', '.join(_COLUMNS['plans'])} FROM plans WHERE config_hash = ? AND "
                              "scene = ? AND realisation = ?", (config_hash, scene, realisation))
        return {row[2]: dict(zip(_COLUMNS["plans"], row)) for row in cur}


class _Transaction:
    """BEGIN IMMEDIATE ... COMMIT, or ROLLBACK on an exception (autocommit connection)."""

    def __init__(self, db: sqlite3.Connection):
        self.db = db

    def __enter__(self):
        self.db.execute("BEGIN IMMEDIATE")
        return self.db

    def __exit__(self, kind, value, tb) -> None:
        self.db.execute("COMMIT" if kind is None else "ROLLBACK")
