"""The Summary value: one report shape rendered as text and HTML (unit tier, no solve)."""

from __future__ import annotations

import dataclasses
import html.parser
import math

import numpy as np
import pytest

from rocketid.summary import Row, Section, Summary, Table, Text


def _example() -> Summary:
    inner = Summary("statistic criterion", (Section("", (("eta", "0.1"),)),), rule=False)
    return Summary(
        "rocketid example",
        (Section("Fit", (("objective J", "3.25"), ("chi2 / dof", "1.01"), "a free line")),
         Section("Parameters", (Table(("name", "estimate", "n"), (("CD0", 0.50123456, 3), ("CL", math.nan, 12)),
                                      (None, ".4g", ".4g")),)),
         Section("", (inner,))),
        notes=("CD0 is at its upper bound", "chi2/dof = 37 <well above 1> & more"))


def test_text_has_title_rule_sections_rows_tables_and_numbered_notes():
    text = _example().text()
    lines = text.splitlines()
    assert lines[0] == "rocketid example" and lines[1] == "=" * 60
    assert "\nFit\n  objective J   : 3.25\n  chi2 / dof    : 1.01\n  a free line\n" in text
    # the table: header, left-aligned first column, numbers with their format, NaN as '-',
    # integers as integers whatever the column's format
    i = lines.index("Parameters")
    assert lines[i + 1].split() == ["name", "estimate", "n"]
    assert lines[i + 2].split() == ["CD0", "0.5012", "3"]
    assert lines[i + 3].split() == ["CL", "-", "12"]
    assert lines[i + 1].index("estimate") + len("estimate") == lines[i + 2].index("0.5012") + len("0.5012")
    # nested summary: its own title, no rule
    assert "\nstatistic criterion\n  eta" in text
    assert text.endswith("Notes\n  [1] CD0 is at its upper bound\n  [2] chi2/dof = 37 <well above 1> & more")
    assert str(_example()) == text


def test_keys_align_on_the_longest_key():
    s = Summary("t", (Section("a", (("k", "1"), ("a rather long key", "2"))),))
    rows = s.text().splitlines()[3:5]
    assert rows[0].index(":") == rows[1].index(":") == 2 + len("a rather long key") + 1


class _Collect(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.stack, self.text, self.tags = [], [], []

    def handle_starttag(self, tag, attrs):
        self.stack.append(tag)
        self.tags.append(tag)

    def handle_endtag(self, tag):
        assert self.stack and self.stack[-1] == tag, f"</{tag}> closes <{self.stack[-1] if self.stack else None}>"
        self.stack.pop()

    def handle_data(self, data):
        if data.strip():
            self.text.append((self.stack[-1] if self.stack else None, data))


def test_html_is_well_formed_escaped_and_holds_the_same_content():
    page = _example().html()
    p = _Collect()
    p.feed(page)
    p.close()
    assert p.stack == []  # every tag closed, in order
    texts = dict((d, t) for t, d in p.text)
    assert texts["rocketid example"] == "h3" and texts["Fit"] == "h4"
    assert texts["objective J"] == "th" and texts["3.25"] == "td" and texts["0.5012"] == "td"
    assert texts["chi2/dof = 37 <well above 1> & more"] == "li"  # escaped in the source, intact as text
    assert "<well" not in page and "&lt;well above 1&gt; &amp; more" in page
    assert p.tags.count("li") == 2 and "ol" in p.tags
    assert _example()._repr_html_() == page


def test_to_dict_and_accessors():
    s = _example()
    d = s.to_dict()
    assert d["notes"] == list(s.notes) and d["title"] == "rocketid example"
    assert d["sections"][1]["items"][0]["rows"][0] == ["CD0", "0.5012", "3"]
    assert s.rows() == {"objective J": "3.25", "chi2 / dof": "1.01"}
    assert s.section("Fit").items[0] == Row("objective J", "3.25")
    with pytest.raises(KeyError, match="no section 'Nope'.*'Fit'"):
        s.section("Nope")
    assert s.with_notes(["third"]).notes[-1] == "third" and len(s.notes) == 2


def test_summary_is_a_frozen_value():
    s = _example()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.title = "x"
    assert s == _example()
    assert isinstance(s.sections, tuple) and isinstance(s.sections[0].items, tuple)


def test_bad_parts_are_refused_with_a_message():
    with pytest.raises(ValueError, match="row 0 of the table has 1 cells for 2 columns"):
        Table(("a", "b"), (("x",),))
    with pytest.raises(TypeError, match="holds Row, Table, Text"):
        Section("s", (3.0,))
    with pytest.raises(TypeError, match="must be Section values"):
        Summary("t", ("not a section",))


def test_numpy_numbers_render_like_python_ones():
    t = Table(("a", "b"), ((np.float64(1.23456), np.int64(7)),), (".3g", ".3g"))
    assert t.cells() == [["1.23", "7"]]
    assert Text("x\n\ny", indent=4) in Section("", (Text("x\n\ny", indent=4),)).items


def test_summary_text_is_the_text_and_keeps_the_value():
    """The diagnostics' results return a SummaryText: a str (joined, searched and printed as
    before) that renders as its Summary does and nests as that value."""
    from rocketid.summary import SummaryText

    s = _example()
    t = SummaryText(s)
    assert isinstance(t, str) and t == s.text() and t.text() == s.text() and type(t.text()) is str
    assert t.value is s and t.notes == s.notes and t.html() == s.html() and t.to_dict() == s.to_dict()
    assert "\n".join(["before", t]).endswith(s.text()) and "CD0 is at its upper bound" in t
    assert Section("", (t,)).items == (s,)
    with pytest.raises(TypeError, match="wraps a Summary"):
        SummaryText("text")
