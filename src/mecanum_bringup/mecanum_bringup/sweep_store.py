"""
The results store of a sweep: one SQLite row per finished variant (pure, no ROS).

A sweep writes each variant's row the moment it finishes, in its own transaction, so a
sweep that is killed keeps every finished run and, started again, runs only the others.
The store also keeps what fixes the variants (the sweep's fingerprint) and the digests
of the files they read (the sweep, scenario, world and map files:
mecanum_bringup.sweep.input_digests): a store made by another sweep file, by this one
after its axes changed, or before one of those files was edited, is refused rather than
mixed, naming what changed.

Tables::

    sweep(key TEXT PRIMARY KEY, value TEXT)      -- name, fingerprint, inputs, created_at
    variants(idx INTEGER PRIMARY KEY, name TEXT, values_json TEXT, status TEXT,
             verdict TEXT, expected TEXT, criteria_json TEXT, first_failure TEXT,
             sim_time_s REAL, wall_time_s REAL, run_dir TEXT, error TEXT, worker TEXT,
             finished_at REAL, min_zone_clearance_m REAL, margins_json TEXT)

``status`` is the scenario runner's: 'OK' (verdict as expected), 'UNEXPECTED' or
'ERROR' (no verdict: the run could not be judged). ``criteria_json`` maps each criterion
name ('step 1', 'no_collision', ...) to whether it passed. ``min_zone_clearance_m`` is
the run's least footprint clearance to the authorised zone's border (m, < 0: the
footprint left the zone; NULL: not measured; see scenario_judge). ``margins_json`` maps
each criterion that has a margin to it (positive: passed by that much; <= 0: failed; m
or s, see scenario_judge); :attr:`VariantRow.least_margin` is the least of them. A store
made before a column existed reads with NULL there (no margins), and gets the column
when a sweep resumes it.
"""

from dataclasses import dataclass, field
import json
from pathlib import Path
import sqlite3
import time
from typing import Any, Dict, Iterable, List, Optional, Union

PathLike = Union[str, Path]
SCHEMA_VERSION = '1'


class StoreError(RuntimeError):
    """The store cannot be used for this sweep (another sweep's, or not a sweep store)."""


@dataclass
class VariantRow:
    """One finished variant, as stored."""

    index: int
    name: str
    values: Dict[str, Any]
    status: str                     # OK | UNEXPECTED | ERROR
    verdict: Optional[str]          # pass | fail | None (not judged)
    expected: str                   # pass | fail
    criteria: Dict[str, bool] = field(default_factory=dict)
    first_failure: str = ''
    sim_time_s: Optional[float] = None
    wall_time_s: Optional[float] = None
    run_dir: str = ''
    error: str = ''
    worker: str = ''
    finished_at: float = 0.0
    min_zone_clearance_m: Optional[float] = None   # m; None: not measured
    #: criterion name -> margin (m or s; positive: passed by that much), where it has one.
    margins: Dict[str, float] = field(default_factory=dict)

    @property
    def least_margin(self) -> Optional[float]:
        """Return the least margin of any criterion (None: no criterion has one)."""
        return min(self.margins.values()) if self.margins else None

    @property
    def failed(self) -> bool:
        """Return True when the run's verdict is not the expected one (or no verdict)."""
        return self.status != 'OK'


_COLUMNS = ('idx', 'name', 'values_json', 'status', 'verdict', 'expected', 'criteria_json',
            'first_failure', 'sim_time_s', 'wall_time_s', 'run_dir', 'error', 'worker',
            'finished_at', 'min_zone_clearance_m', 'margins_json')
#: Columns added after the first stores, with their types (added to an old store on open).
_ADDED_COLUMNS = {'min_zone_clearance_m': 'REAL', 'margins_json': 'TEXT'}


def _change(name: str, before: Dict[str, str], now: Dict[str, str]) -> str:
    """Return how an input file changed: 'new', 'no longer read' or 'edited'."""
    if name not in before:
        return 'new'
    return 'no longer read' if name not in now else 'edited'


class ResultsStore:
    """A sweep's SQLite store; rows are written one transaction each (WAL journal)."""

    def __init__(self, path: PathLike, sweep_name: str, fingerprint: str,
                 inputs: Optional[Dict[str, str]] = None):
        """
        Open (or create) the store; raise StoreError if it belongs to another sweep.

        inputs: {file: digest} of the files the variants read; a store whose recorded
        inputs differ is refused, naming the files (a store without them is accepted).
        """
        stored_inputs: Optional[Dict[str, str]] = None
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._db = sqlite3.connect(str(self.path), timeout=30.0)
            self._db.execute('PRAGMA journal_mode=WAL')
            self._db.execute('PRAGMA synchronous=NORMAL')
            with self._db:
                self._db.execute('CREATE TABLE IF NOT EXISTS sweep '
                                 '(key TEXT PRIMARY KEY, value TEXT)')
                self._db.execute(
                    'CREATE TABLE IF NOT EXISTS variants (idx INTEGER PRIMARY KEY, name TEXT, '
                    'values_json TEXT, status TEXT, verdict TEXT, expected TEXT, '
                    'criteria_json TEXT, first_failure TEXT, sim_time_s REAL, '
                    'wall_time_s REAL, run_dir TEXT, error TEXT, worker TEXT, '
                    'finished_at REAL, min_zone_clearance_m REAL, margins_json TEXT)')
                meta = dict(self._db.execute('SELECT key, value FROM sweep'))
                if not meta:
                    self._db.executemany('INSERT INTO sweep VALUES (?, ?)', [
                        ('schema', SCHEMA_VERSION), ('name', sweep_name),
                        ('fingerprint', fingerprint), ('created_at', repr(time.time()))]
                        + ([('inputs', json.dumps(inputs, sort_keys=True))]
                           if inputs is not None else []))
                    meta = {'name': sweep_name, 'fingerprint': fingerprint}
                elif 'inputs' in meta:
                    stored_inputs = json.loads(meta['inputs'])
        except sqlite3.DatabaseError as error:
            raise StoreError(f'{self.path}: not a sweep results store ({error})') from None
        if meta.get('name') != sweep_name or meta.get('fingerprint') != fingerprint:
            self._db.close()
            raise StoreError(
                f'{self.path} holds the results of another sweep ({meta.get("name")!r}, or '
                'the same sweep with other axes, samples or seed): give this sweep another '
                '--out folder, or delete the store to start again')
        if inputs is not None and stored_inputs is not None and stored_inputs != inputs:
            self._db.close()
            changed = sorted(name for name in set(stored_inputs) | set(inputs)
                             if stored_inputs.get(name) != inputs.get(name))
            words = [f'{name} ({_change(name, stored_inputs, inputs)})' for name in changed]
            raise StoreError(
                f'{self.path}: the files this sweep reads changed since its results were '
                f'stored: {", ".join(words)}; its stored verdicts may no longer hold: give '
                'this sweep another --out folder, or delete the store to run them again')
        try:   # a store from before a column was added gets it (NULL in the old rows)
            with self._db:
                present = _column_names(self._db)
                for column, kind in _ADDED_COLUMNS.items():
                    if column not in present:
                        self._db.execute(f'ALTER TABLE variants ADD COLUMN {column} {kind}')
        except sqlite3.DatabaseError as error:
            self._db.close()
            raise StoreError(f'{self.path}: cannot add the new columns ({error})') from None

    def close(self) -> None:
        """Close the database."""
        self._db.close()

    def __enter__(self) -> 'ResultsStore':
        """Return the open store."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the store."""
        self.close()

    def add(self, row: VariantRow) -> None:
        """Write one finished variant (replacing an earlier row of the same index)."""
        with self._db:
            self._db.execute(
                f'INSERT OR REPLACE INTO variants ({", ".join(_COLUMNS)}) VALUES '
                f'({", ".join("?" * len(_COLUMNS))})',
                (row.index, row.name, json.dumps(row.values, sort_keys=True), row.status,
                 row.verdict, row.expected, json.dumps(row.criteria), row.first_failure,
                 row.sim_time_s, row.wall_time_s, row.run_dir, row.error, row.worker,
                 row.finished_at or time.time(), row.min_zone_clearance_m,
                 json.dumps(row.margins, sort_keys=True)))

    def done_indices(self) -> set:
        """Return the indices of the variants that have a row."""
        return {index for (index,) in self._db.execute('SELECT idx FROM variants')}

    def rows(self) -> List[VariantRow]:
        """Return every row, by index."""
        cursor = self._db.execute(_select(self._db))
        return [_row(record) for record in cursor]


def read_rows(path: PathLike) -> List[VariantRow]:
    """Return the rows of a store file (read only; for reports and compare)."""
    path = Path(path)
    if not path.is_file():
        raise StoreError(f'{path}: no such results store')
    try:
        db = sqlite3.connect(f'file:{path}?mode=ro', uri=True)
        try:
            cursor = db.execute(_select(db))
            return [_row(record) for record in cursor]
        finally:
            db.close()
    except sqlite3.DatabaseError as error:
        raise StoreError(f'{path}: not a sweep results store ({error})') from None


def read_meta(path: PathLike) -> Dict[str, str]:
    """Return the store's sweep table (name, fingerprint, created_at)."""
    db = sqlite3.connect(f'file:{Path(path)}?mode=ro', uri=True)
    try:
        return dict(db.execute('SELECT key, value FROM sweep'))
    except sqlite3.DatabaseError as error:
        raise StoreError(f'{path}: not a sweep results store ({error})') from None
    finally:
        db.close()


def _column_names(db: sqlite3.Connection) -> set:
    return {record[1] for record in db.execute('PRAGMA table_info(variants)')}


def _select(db: sqlite3.Connection) -> str:
    """Return the SELECT of every row; NULL for a column an old (read-only) store lacks."""
    present = _column_names(db)
    columns = [c if c in present or c not in _ADDED_COLUMNS else f'NULL AS {c}'
               for c in _COLUMNS]
    return f'SELECT {", ".join(columns)} FROM variants ORDER BY idx'


def _row(record: Iterable[Any]) -> VariantRow:
    (index, name, values, status, verdict, expected, criteria, first_failure, sim_time_s,
     wall_time_s, run_dir, error, worker, finished_at, min_zone_clearance_m,
     margins) = record
    return VariantRow(index, name, json.loads(values), status, verdict, expected,
                      json.loads(criteria or '{}'), first_failure or '', sim_time_s,
                      wall_time_s, run_dir or '', error or '', worker or '', finished_at,
                      min_zone_clearance_m, json.loads(margins or '{}'))
