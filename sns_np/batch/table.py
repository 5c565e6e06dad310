"""A small table of rows (one per shape) that writes and reads CSV and JSON without pandas."""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

from .._atomic import write_file

__all__ = ["Table"]


def _cell(value):
    """A value as a CSV cell: numbers round-trip exactly (repr), None is empty."""
    if value is None:
        return ""
    if isinstance(value, float):
        return "nan" if math.isnan(value) else repr(value)
    return str(value)


def _parse(text):
    """A CSV cell back to None, int, float or str."""
    if text == "":
        return None
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _json_value(value):
    """NaN and infinities are not JSON: they become null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


class Table:
    """Rows of named values, one row per shape, in a fixed column order.

    Parameters
    ----------
    rows : list of dict
        One dict per row; a missing key is an empty cell.
    columns : list of str, optional
        Column order (default: the keys in order of first appearance).
    meta : dict, optional
        JSON-serialisable facts about the whole table (options, cluster, times); written to
        the JSON file only.

    Examples
    --------
    >>> t = Table([{"name": "a", "status": "done", "steps": 10},
    ...            {"name": "b", "status": "error", "message": "bad mesh"}])
    >>> t.columns, len(t), t.column("status")
    (['name', 'status', 'steps', 'message'], 2, ['done', 'error'])
    >>> t[1]["steps"] is None
    True
    """

    def __init__(self, rows, columns=None, meta=None):
        self.rows = [dict(r) for r in rows]
        if columns is None:
            columns = []
            for r in self.rows:
                columns.extend(k for k in r if k not in columns)
        self.columns = list(columns)
        for r in self.rows:
            for c in self.columns:
                r.setdefault(c, None)
        self.meta = dict(meta or {})

    def __len__(self):
        return len(self.rows)

    def __iter__(self):
        return iter(self.rows)

    def __getitem__(self, i):
        return self.rows[i]

    def column(self, name) -> list:
        """The values of one column, in row order.

        Examples
        --------
        >>> Table([{"x": 1}, {"x": 2.5}]).column("x")
        [1, 2.5]
        """
        if name not in self.columns:
            raise KeyError(f"no column {name!r}; the columns are {', '.join(self.columns)}")
        return [r[name] for r in self.rows]

    def csv_text(self) -> str:
        """The table as CSV text (header line, then one line per row).

        Examples
        --------
        >>> print(Table([{"name": "a", "x": 0.5}]).csv_text(), end="")
        name,x
        a,0.5
        """
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(self.columns)
        for r in self.rows:
            w.writerow([_cell(r[c]) for c in self.columns])
        return buf.getvalue()

    def to_csv(self, path):
        """Write the table as CSV, atomically; returns the path.

        Examples
        --------
        >>> import os, tempfile
        >>> d = tempfile.mkdtemp()
        >>> path = Table([{"name": "a", "x": 0.1}]).to_csv(os.path.join(d, "t.csv"))
        >>> Table.read(path)[0]
        {'name': 'a', 'x': 0.1}
        """
        text = self.csv_text()

        def write(tmp):
            with open(tmp, "w", newline="", encoding="utf-8") as fh:
                fh.write(text)

        return write_file(path, write)

    def to_json(self, path):
        """Write ``{"meta": ..., "columns": ..., "rows": ...}`` as JSON, atomically.

        NaN values are written as null.

        Examples
        --------
        >>> import json, os, tempfile
        >>> d = tempfile.mkdtemp()
        >>> path = Table([{"name": "a", "x": float("nan")}], meta={"k": 3}).to_json(
        ...     os.path.join(d, "t.json"))
        >>> json.load(open(path))["rows"]
        [{'name': 'a', 'x': None}]
        """
        doc = {"meta": self.meta, "columns": self.columns,
               "rows": [{c: _json_value(r[c]) for c in self.columns} for r in self.rows]}
        text = json.dumps(doc, indent=1, default=str, allow_nan=False) + "\n"

        def write(tmp):
            with open(tmp, "w", encoding="utf-8") as fh:
                fh.write(text)

        return write_file(path, write)

    @classmethod
    def read(cls, path) -> Table:
        """Read a table written by :meth:`to_csv` (.csv) or :meth:`to_json` (.json).

        CSV cells come back as int, float, str, or None for an empty cell.

        Examples
        --------
        >>> import os, tempfile
        >>> d = tempfile.mkdtemp()
        >>> t = Table([{"name": "a", "steps": 3}], meta={"k": 1})
        >>> Table.read(t.to_json(os.path.join(d, "t.json"))).meta
        {'k': 1}
        >>> Table.read(t.to_csv(os.path.join(d, "t.csv"))).column("steps")
        [3]
        """
        path = Path(path)
        if path.suffix.lower() == ".json":
            with open(path, encoding="utf-8") as fh:
                doc = json.load(fh)
            if not isinstance(doc, dict) or "rows" not in doc:
                raise ValueError(f"{path}: not a table (expected a JSON object with 'rows')")
            return cls(doc["rows"], doc.get("columns"), doc.get("meta"))
        if path.suffix.lower() != ".csv":
            raise ValueError(f"table file {path.name!r} must end in .csv or .json")
        with open(path, newline="", encoding="utf-8") as fh:
            lines = list(csv.reader(fh))
        if not lines:
            raise ValueError(f"{path}: empty table (no header line)")
        head = lines[0]
        return cls([dict(zip(head, map(_parse, line))) for line in lines[1:]], head)

    def format(self, columns=None) -> str:
        """Fixed-width text of some columns (all by default), numbers to 4 digits.

        Examples
        --------
        >>> print(Table([{"name": "a", "x": 0.123456}, {"name": "bb", "x": 2}]).format())
        name  x
        a     0.1235
        bb    2
        """
        columns = list(columns or self.columns)

        def fmt(v):
            if v is None:
                return ""
            if isinstance(v, float):
                return f"{v:.4g}"
            return str(v)

        cells = [columns] + [[fmt(r.get(c)) for c in columns] for r in self.rows]
        widths = [max(len(row[i]) for row in cells) for i in range(len(columns))]
        return "\n".join("  ".join(v.ljust(w) for v, w in zip(row, widths)).rstrip()
                         for row in cells)

    def __str__(self):
        return self.format()

    def __repr__(self):
        return f"Table({len(self)} rows; columns {', '.join(self.columns)})"
