"""One way to report: the :class:`Summary` value every result's ``summary()`` returns.

A summary is data, not text: a title, fixed sections and numbered notes. Each section holds
items of three kinds, in order:

============  ================================================================
item          rendered as
============  ================================================================
``Row``       ``key : value`` (keys aligned across the whole summary)
``Table``     a table with a header row (text: aligned columns; HTML: ``<table>``)
``Text``      a free line or paragraph
``Summary``   another summary nested in this one (a report made of reports)
============  ================================================================

The same value renders as plain text (:meth:`Summary.text`, also ``str(summary)`` and
``print(summary)``) and as HTML (:meth:`Summary.html`, also shown by Jupyter). Notes are
the things a user must act on, numbered ``[1]``, ``[2]``, ... in both renderings.

Examples
--------
>>> from rocketid.summary import Summary, Section, Table
>>> s = Summary("rocketid example", (
...     Section("Fit", (("objective J", "3.25"), ("chi2 / dof", "1.01"))),
...     Section("Parameters", (Table(("name", "estimate"), (("CD0", 0.5012),), (None, ".4g")),)),
... ), notes=("CD0 is at its upper bound",))
>>> print(s)  # doctest: +NORMALIZE_WHITESPACE
rocketid example
============================================================
Fit
  objective J   : 3.25
  chi2 / dof    : 1.01
Parameters
  name  estimate
  CD0     0.5012
Notes
  [1] CD0 is at its upper bound
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Iterable, Union

__all__ = ["Row", "Table", "Text", "Section", "Summary", "SummaryText", "KEY_WIDTH"]

#: Keys of rows are padded to at least this many characters (``"scaling       : nominal"``).
KEY_WIDTH = 14
#: The rule under a summary's title is at least this long.
RULE_WIDTH = 60


@dataclass(frozen=True)
class Row:
    """One ``key : value`` line.

    Parameters
    ----------
    key : str
    value : str
    """

    key: str
    value: str

    def __post_init__(self):
        object.__setattr__(self, "key", str(self.key))
        object.__setattr__(self, "value", str(self.value))


@dataclass(frozen=True)
class Text:
    """A free line or paragraph (may span several lines).

    Parameters
    ----------
    text : str
    indent : int
        Spaces before every line of the plain-text rendering (default 2, the rows' indent).
    """

    text: str
    indent: int = 2

    def __post_init__(self):
        object.__setattr__(self, "text", str(self.text))


@dataclass(frozen=True)
class Table:
    """A table: column names and rows of cells.

    Parameters
    ----------
    columns : sequence of str
    rows : sequence of sequence
        Cells are text or numbers; every row has one cell per column.
    formats : sequence of str or None, optional
        A format spec per column applied to non-integer numeric cells (``".6g"``); ``None``
        or a missing entry means ``str``. Integers and text render with ``str``; a non-finite
        number renders as ``-``.

    In text, the first column and columns of text are left-aligned, columns with numbers
    right-aligned.
    """

    columns: tuple
    rows: tuple
    formats: tuple = ()

    def __post_init__(self):
        cols = tuple(str(c) for c in self.columns)
        rows = tuple(tuple(r) for r in self.rows)
        for i, r in enumerate(rows):
            if len(r) != len(cols):
                raise ValueError(f"row {i} of the table has {len(r)} cells for {len(cols)} columns {cols}")
        if len(self.formats) > len(cols):
            raise ValueError(f"{len(self.formats)} formats for {len(cols)} columns {cols}")
        object.__setattr__(self, "columns", cols)
        object.__setattr__(self, "rows", rows)
        object.__setattr__(self, "formats", tuple(self.formats))

    def cell(self, i: int, j: int) -> str:
        """The text of row ``i``, column ``j``."""
        v = self.rows[i][j]
        fmt = self.formats[j] if j < len(self.formats) else None
        if isinstance(v, Real) and not isinstance(v, (bool, Integral)):
            if not math.isfinite(float(v)):
                return "-"
            return format(v, fmt) if fmt else str(v)
        return str(v)

    def cells(self) -> list[list[str]]:
        """Every row's cells as text."""
        return [[self.cell(i, j) for j in range(len(self.columns))] for i in range(len(self.rows))]

    def numeric(self, j: int) -> bool:
        """Column ``j`` holds a number in some row (it is right-aligned)."""
        return any(isinstance(r[j], Real) and not isinstance(r[j], bool) for r in self.rows)

    def text_lines(self) -> list[str]:
        """The header and the rows as aligned text lines (numbers right, text left)."""
        body = self.cells()
        widths = [max([len(c)] + [len(r[j]) for r in body]) for j, c in enumerate(self.columns)]
        right = [j > 0 and self.numeric(j) for j in range(len(self.columns))]
        def line(cells):
            return "  ".join(c.rjust(w) if r else c.ljust(w) for c, w, r in zip(cells, widths, right))
        return [line(self.columns).rstrip()] + [line(r).rstrip() for r in body]


Item = Union[Row, Table, Text, "Summary"]


def _item(x) -> Item:
    if isinstance(x, SummaryText):
        return x.value
    if isinstance(x, (Row, Table, Text, Summary)):
        return x
    if isinstance(x, str):
        return Text(x)
    if isinstance(x, tuple) and len(x) == 2:
        return Row(*x)
    raise TypeError(f"a summary section holds Row, Table, Text, Summary, str or (key, value) items, got {x!r}")


@dataclass(frozen=True)
class Section:
    """A titled part of a summary.

    Parameters
    ----------
    title : str
        Shown on its own line; ``""`` for an untitled block.
    items : sequence
        :class:`Row`, :class:`Table`, :class:`Text` or :class:`Summary` items; a
        ``(key, value)`` pair is taken as a row and a ``str`` as text.
    """

    title: str
    items: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "items", tuple(_item(x) for x in self.items))


@dataclass(frozen=True)
class Summary:
    """A result's report: a title, fixed sections, numbered notes.

    Parameters
    ----------
    title : str
    sections : sequence of Section
    notes : sequence of str
        Numbered from 1 in the rendering.
    rule : bool
        Underline the title with ``=`` (top-level reports); ``False`` for a summary
        that is usually shown inside another one.

    Notes
    -----
    ``str(summary)`` is :meth:`text`; Jupyter shows :meth:`html`.
    """

    title: str
    sections: tuple = ()
    notes: tuple = ()
    rule: bool = True
    key_width: int = field(default=KEY_WIDTH, compare=False)

    def __post_init__(self):
        secs = tuple(self.sections)
        for s in secs:
            if not isinstance(s, Section):
                raise TypeError(f"Summary sections must be Section values, got {s!r}")
        object.__setattr__(self, "sections", secs)
        object.__setattr__(self, "notes", tuple(str(n) for n in self.notes))

    # ---- derived
    def rows(self) -> dict[str, str]:
        """Every row of the summary (nested summaries excluded) as ``{key: value}``."""
        return {it.key: it.value for s in self.sections for it in s.items if isinstance(it, Row)}

    def section(self, title: str) -> Section:
        """The section called ``title``."""
        for s in self.sections:
            if s.title == title:
                return s
        raise KeyError(f"no section {title!r} in this summary; it has {[s.title for s in self.sections]}")

    def with_notes(self, notes: Iterable[str]) -> "Summary":
        """A copy with ``notes`` appended."""
        return Summary(self.title, self.sections, self.notes + tuple(notes), self.rule, self.key_width)

    # ---- text
    def _width(self) -> int:
        keys = [len(it.key) for s in self.sections for it in s.items if isinstance(it, Row)]
        return max([self.key_width] + [k + 1 for k in keys])

    def text(self) -> str:
        """The plain-text rendering."""
        lines = []
        if self.title:
            lines.append(self.title)
            if self.rule:
                lines.append("=" * max(RULE_WIDTH, len(self.title)))
        w = self._width()
        for s in self.sections:
            if s.title:
                lines.append(s.title)
            for it in s.items:
                if isinstance(it, Row):
                    lines.append(f"  {it.key:<{w}}: {it.value}")
                elif isinstance(it, Table):
                    lines += ["  " + ln for ln in it.text_lines()]
                elif isinstance(it, Text):
                    lines += [" " * it.indent + ln if ln else "" for ln in it.text.split("\n")]
                else:
                    lines += ["", it.text()]
        if self.notes:
            lines.append("Notes")
            lines += [f"  [{i}] {n}" for i, n in enumerate(self.notes, 1)]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.text()

    # ---- HTML
    def html(self, level: int = 3) -> str:
        """The HTML rendering: headings, tables and an ordered list of notes.

        Parameters
        ----------
        level : int
            Heading level of the title (sections use the next one).
        """
        e = html.escape
        h, hs = f"h{min(level, 6)}", f"h{min(level + 1, 6)}"
        out = ['<div class="rocketid-summary">']
        if self.title:
            out.append(f"<{h}>{e(self.title)}</{h}>")
        for s in self.sections:
            if s.title:
                out.append(f"<{hs}>{e(s.title)}</{hs}>")
            rows: list[str] = []
            for it in s.items:
                if isinstance(it, Row):
                    rows.append(f"<tr><th>{e(it.key)}</th><td>{e(it.value)}</td></tr>")
                    continue
                if rows:
                    out.append('<table class="rows">' + "".join(rows) + "</table>")
                    rows = []
                if isinstance(it, Table):
                    head = "".join(f"<th>{e(c)}</th>" for c in it.columns)
                    body = "".join("<tr>" + "".join(f"<td>{e(c)}</td>" for c in r) + "</tr>" for r in it.cells())
                    out.append(f'<table class="table"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>')
                elif isinstance(it, Text):
                    out.append(f"<p>{e(it.text)}</p>".replace("\n", "<br>"))
                else:
                    out.append(it.html(level + 1))
            if rows:
                out.append('<table class="rows">' + "".join(rows) + "</table>")
        if self.notes:
            out.append(f"<{hs}>Notes</{hs}>")
            out.append('<ol class="notes">' + "".join(f"<li>{e(n)}</li>" for n in self.notes) + "</ol>")
        out.append("</div>")
        return "\n".join(out)

    def _repr_html_(self) -> str:
        return self.html()

    def to_dict(self) -> dict:
        """A JSON-ready dictionary: ``title``, ``sections`` (rows, tables, text), ``notes``."""
        def item(it):
            if isinstance(it, Row):
                return {"key": it.key, "value": it.value}
            if isinstance(it, Table):
                return {"columns": list(it.columns), "rows": it.cells()}
            if isinstance(it, Text):
                return {"text": it.text}
            return {"summary": it.to_dict()}
        return {"title": self.title,
                "sections": [{"title": s.title, "items": [item(it) for it in s.items]} for s in self.sections],
                "notes": list(self.notes)}



class SummaryText(str):
    """The text of a :class:`Summary` that keeps the value: what the diagnostics' results
    (``Comparison``, ``Location``, ``Plausibility``, ``CandidateRanking``, ``Confirmation``)
    return from ``summary()``.

    It is a ``str`` (the text, so ``print``, ``in``, ``splitlines`` and ``"\\n".join`` of the
    reports that still assemble their text from these are unchanged) and it answers as the
    value does: :meth:`text`, :meth:`html` (Jupyter shows it), :meth:`to_dict`, ``sections``,
    ``notes``; :attr:`value` is the :class:`Summary` itself. Nested in a :class:`Section` it is
    taken as that value.

    Parameters
    ----------
    summary : Summary
    """

    value: Summary

    def __new__(cls, summary: Summary) -> "SummaryText":
        if not isinstance(summary, Summary):
            raise TypeError(f"SummaryText wraps a Summary, got {type(summary).__name__}")
        out = super().__new__(cls, summary.text())
        out.value = summary
        return out

    @property
    def title(self) -> str:
        return self.value.title

    @property
    def sections(self) -> tuple:
        return self.value.sections

    @property
    def notes(self) -> tuple:
        return self.value.notes

    def text(self) -> str:
        """The plain-text rendering (this string, as a plain ``str``)."""
        return str.__str__(self)

    def html(self, level: int = 3) -> str:
        """The HTML rendering of the value (:meth:`Summary.html`)."""
        return self.value.html(level)

    def _repr_html_(self) -> str:
        return self.value.html()

    def to_dict(self) -> dict:
        """:meth:`Summary.to_dict` of the value."""
        return self.value.to_dict()
