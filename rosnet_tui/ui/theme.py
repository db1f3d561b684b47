"""The wizard's look: the terminal's own 16 colours, readable without colour, frugal on the wire.

The theme uses the terminal's ANSI palette and its default background, so it reads the same in 16
colours (TERM=linux, tmux, xterm), costs few bytes per cell, and never turns an accent into red:
red is kept for failures. Focus and the selected row are shown by reverse video and double rules,
which survive NO_COLOR. On the Linux console (its font is code page 437) every glyph drawn is
one the font has: no rounded corners, block eighths or ellipsis character.
"""

from __future__ import annotations

import os

from textual.theme import Theme

THEME = Theme(
    name="rosnet",
    ansi=True,
    dark=True,
    primary="ansi_blue",
    secondary="ansi_cyan",
    accent="ansi_cyan",
    warning="ansi_yellow",
    error="ansi_red",
    success="ansi_green",
    foreground="ansi_default",
    background="ansi_default",
    surface="ansi_default",
    panel="ansi_default",
    boost="ansi_default",
    variables={
        "text-muted": "ansi_default",
        "ansi-background": "ansi_default",
        "ansi-foreground": "ansi_default",
        "border": "ansi_cyan",
        "border-blurred": "ansi_blue",
        "block-cursor-foreground": "ansi_default",
        "block-cursor-background": "ansi_default",
        "block-cursor-text-style": "reverse",
        "block-cursor-blurred-foreground": "ansi_default",
        "block-cursor-blurred-background": "ansi_default",
        "block-cursor-blurred-text-style": "underline",
        "block-hover-background": "ansi_default",
        "input-cursor-foreground": "ansi_default",
        "input-cursor-background": "ansi_default",
        "input-cursor-text-style": "reverse",
        "input-selection-foreground": "ansi_default",
        "input-selection-background": "ansi_default",
        "footer-foreground": "ansi_default",
        "footer-background": "ansi_default",
        "footer-key-foreground": "ansi_cyan",
        "footer-key-background": "ansi_default",
        "footer-description-foreground": "ansi_default",
        "footer-description-background": "ansi_default",
        "footer-item-background": "ansi_default",
        "scrollbar": "ansi_blue",
        "scrollbar-hover": "ansi_cyan",
        "scrollbar-active": "ansi_cyan",
        "scrollbar-background": "ansi_default",
        "scrollbar-background-hover": "ansi_default",
        "scrollbar-background-active": "ansi_default",
        "scrollbar-corner-color": "ansi_default",
        "button-foreground": "ansi_default",
        "button-focus-text-style": "reverse bold",
        "screen-selection-background": "ansi_blue",
        "screen-selection-foreground": "ansi_default",
        "link-color": "ansi_cyan",
        "link-background": "ansi_default",
        "markdown-h1-color": "ansi_cyan",
        "markdown-h1-background": "ansi_default",
        "markdown-h2-color": "ansi_cyan",
        "markdown-h2-background": "ansi_default",
        "markdown-h3-color": "ansi_default",
        "markdown-h3-background": "ansi_default",
    },
)


def linux_console(term: str | None = None) -> bool:
    """Whether the terminal is the Linux console (a code-page-437 font, 16 colours)."""
    term = os.environ.get("TERM", "") if term is None else term
    return term == "linux" or term.startswith("linux-")


def ellipsis() -> str:
    return "..." if linux_console() else "…"


def cut(text: str, width: int) -> str:
    """*text* on one line of at most *width* cells, ending in an ellipsis when cut."""
    text = " ".join(text.split())
    if len(text) <= width:
        return text
    mark = ellipsis()
    return text[:max(0, width - len(mark))].rstrip() + mark


def use_console_glyphs() -> None:
    """Scrollbars drawn without the block eighths the console font lacks (colour only)."""
    from textual.scrollbar import ScrollBar, ScrollBarRender

    class ConsoleScrollBarRender(ScrollBarRender):
        VERTICAL_BARS = [" "] * 8
        HORIZONTAL_BARS = [" "] * 8

    ScrollBar.renderer = ConsoleScrollBarRender
