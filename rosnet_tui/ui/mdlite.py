"""The configuration texts' Markdown, drawn as one rich renderable without a Markdown library.

The step texts (rosnet_tui/core/wizard/steps.py) use a small part of Markdown: paragraphs, "- " and
"1. " lists, fenced code blocks, headings, **bold**, *emphasis* and `code`. Drawing that here
keeps the first screen light (a full Markdown parser is the heaviest import of the start-up) and
its output plain: ASCII bullets, code indented and in the accent colour, so it reads without
colour and on the Linux console.
"""

from __future__ import annotations

import re

from rich.console import Group
from rich.padding import Padding
from rich.table import Table
from rich.text import Text

_INLINE = re.compile(r"\*\*(?P<b>.+?)\*\*|`(?P<c>[^`]+)`|(?<![\w*])\*(?P<i>[^*\s][^*]*?)\*(?!\w)"
                     r"|(?<!\w)_(?P<u>[^_\s][^_]*?)_(?!\w)|\[(?P<lt>[^\]]+)\]\((?P<lu>[^)]+)\)")
_ITEM = re.compile(r"^(\s*)([-*+]|\d+[.)])\s+(.*)$")
CODE_STYLE = "cyan"
CODE_INDENT = 2


def inline(text: str) -> Text:
    """One paragraph's text with its emphasis and code spans styled."""
    out = Text()
    pos = 0
    for m in _INLINE.finditer(text):
        out.append(text[pos:m.start()])
        if m.group("b") is not None:
            seg = inline(m.group("b"))
            seg.stylize("bold")
            out.append_text(seg)
        elif m.group("c") is not None:
            out.append(m.group("c"), style=CODE_STYLE)
        elif m.group("i") is not None or m.group("u") is not None:
            out.append(m.group("i") or m.group("u"), style="italic")
        else:
            out.append(f"{m.group('lt')} ({m.group('lu')})")
        pos = m.end()
    out.append(text[pos:])
    return _blank_ends_spans(out)


def _blank_ends_spans(text: Text) -> Text:
    """Move the blank after a styled span into it (some SVG viewers drop a span's leading
    blank, gluing words together in the screenshots)."""
    for span in text.spans:
        if text.plain[span.end:span.end + 1] == " ":
            text.spans[text.spans.index(span)] = span._replace(end=span.end + 1)
    return text


def render(markdown: str) -> Group:
    """*markdown* as a group of paragraphs, lists and code blocks, each separated by a line."""
    parts: list = []
    lines = markdown.splitlines()
    i = 0
    para: list[str] = []
    items: list[tuple[str, list[str]]] = []

    def flush() -> None:
        if para:
            parts.append(inline(" ".join(s.strip() for s in para)))
            para.clear()
        if items:
            grid = Table.grid(padding=(0, 1, 0, 0))
            grid.add_column(no_wrap=True)
            grid.add_column(ratio=1)
            for mark, text in items:
                grid.add_row(mark, inline(" ".join(text)))
            parts.append(grid)
            items.clear()

    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        if stripped.startswith("```"):
            flush()
            code: list[str] = []
            i += 1
            while i < len(lines) and not lines[i].strip().startswith("```"):
                code.append(lines[i])
                i += 1
            # Every line indented alike (Text.pad_left would indent only the first), a line too
            # long for the pane too, where it wraps.
            block = Text("\n".join(code).rstrip("\n"), style=CODE_STYLE, no_wrap=False)
            parts.append(Padding(block, (0, 0, 0, CODE_INDENT), expand=False))
            i += 1
            continue
        if not stripped:
            flush()
        elif stripped.startswith("#"):
            flush()
            heading = inline(stripped.lstrip("#").strip())
            heading.stylize("bold")
            parts.append(heading)
        elif (m := _ITEM.match(line)) is not None:
            if para:
                flush()
            mark = " -" if m.group(2) in "-*+" else " " + m.group(2)
            items.append((mark, [m.group(3)]))
        elif items and line.startswith((" ", "\t")):
            items[-1][1].append(stripped)
        else:
            if items:
                flush()
            para.append(line)
        i += 1
    flush()
    spaced: list = []
    for n, part in enumerate(parts):
        if n:
            spaced.append(Text(""))
        spaced.append(part)
    return Group(*spaced)
