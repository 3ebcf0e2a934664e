"""Markdown text for summary.md, compare.md and the baseline section: below the verdicts and the
report, which both write tables."""


def cell(text):
    """Any value as one Markdown table cell, shown as text: no line break or unescaped '|' that
    would end the row or the cell, no '<' that a Markdown viewer would read as HTML, no backtick
    (code span) or link; names and ordinary reasons read plainly on a terminal too."""
    text = " ".join(str(text).split())
    for c in "\\|<`":
        text = text.replace(c, "\\" + c)
    return text.replace("](", "]\\(")  # no [text](link)
