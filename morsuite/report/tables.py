"""Tables: a DataFrame -> CSV (full precision) and Markdown (6 significant digits).

The Markdown file is the CSV rendered for reading; :func:`read_markdown` parses it
back so that tests (and users) can check that the two agree. pandas is imported
when a table is written, not before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from numbers import Integral, Real
from pathlib import Path

import numpy as np

from .files import write_text

__all__ = ["TableData", "to_markdown", "read_markdown", "write_table", "format_cell"]


@dataclass
class TableData:
    """A table as plain data: ``rows`` (dicts) in ``columns`` order (default: the
    first row's keys); ``int_columns`` become nullable integers (``Int64``), so a
    missing count prints as an empty cell, not as ``nan``. ``note`` goes into the
    Markdown file under the title; ``notes`` are messages for the run's log."""

    name: str
    title: str
    rows: list
    columns: list | None = None
    int_columns: tuple = ()
    note: str = ""
    notes: list = field(default_factory=list)

    def frame(self):
        """The table as a DataFrame (what its CSV file holds)."""
        import pandas as pd

        df = pd.DataFrame(self.rows, columns=self.columns) if self.columns is not None else pd.DataFrame(self.rows)
        for col in self.int_columns:
            df[col] = df[col].astype("Int64")
        return df

    @property
    def df(self):
        """The table as a DataFrame; the same as :meth:`frame`."""
        return self.frame()


def format_cell(value, floatfmt: str = ".6g") -> str:
    """One table cell as Markdown text.

    Missing values (None, ``pd.NA``, NaN) give an empty cell, bools ``True``/``False``,
    integers their digits, other reals ``format(value, floatfmt)`` (default ``".6g"``)
    and anything else its ``str`` with ``|`` escaped and newlines as spaces.
    """
    import pandas as pd

    if value is None or value is pd.NA or value is pd.NaT or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, Integral):
        return str(int(value))
    if isinstance(value, Real):
        return format(float(value), floatfmt)
    return str(value).replace("|", r"\|").replace("\n", " ")


def to_markdown(df: pd.DataFrame, floatfmt: str = ".6g") -> str:
    """GitHub-flavoured Markdown table of ``df`` (no index)."""
    import pandas as pd

    cols = list(df.columns)
    lines = ["| " + " | ".join(cols) + " |",
             "|" + "|".join("---:" if pd.api.types.is_numeric_dtype(df[c]) and not pd.api.types.is_bool_dtype(df[c])
                            else ":---" for c in cols) + "|"]
    for row in df.itertuples(index=False):
        lines.append("| " + " | ".join(format_cell(v, floatfmt) for v in row) + " |")
    return "\n".join(lines) + "\n"


def read_markdown(path_or_text) -> pd.DataFrame:
    """Parse a table written by :func:`to_markdown` (all cells as strings)."""
    import pandas as pd

    text = str(path_or_text)
    if "\n" not in text and Path(text).is_file():
        text = Path(text).read_text()
    rows = [ln.strip() for ln in text.splitlines() if ln.strip().startswith("|")]
    def cells(ln):
        body = ln.strip()[1:-1]
        out, cur, esc = [], "", False
        for ch in body:
            if esc:
                cur += ch
                esc = False
            elif ch == "\\":
                esc = True
            elif ch == "|":
                out.append(cur.strip())
                cur = ""
            else:
                cur += ch
        out.append(cur.strip())
        return out
    header = cells(rows[0])
    data = [cells(r) for r in rows[2:]]
    return pd.DataFrame(data, columns=header, dtype=str)


def write_table(df: pd.DataFrame, stem, *, title: str = "", note: str = "", md_columns=None) -> list[Path]:
    """Write ``stem``.csv and ``stem``.md atomically (each only if its bytes change); return both paths.

    The CSV has every column; the Markdown only ``md_columns`` (those present,
    in that order) when given.
    """
    csv, md = Path(f"{stem}.csv"), Path(f"{stem}.md")
    write_text(csv, df.to_csv(index=False))
    shown = df[[c for c in md_columns if c in df]] if md_columns is not None else df
    head = (f"## {title}\n\n" if title else "") + (f"{note}\n\n" if note else "")
    write_text(md, head + to_markdown(shown))
    return [csv, md]
