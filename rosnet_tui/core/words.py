"""Small words for people: how an age reads ("40 s", "3 min", "5 h", "12 days"), a rate ("2.1
Mbit/s") and a message's size ("64 kB")."""

from __future__ import annotations


def age(seconds: float, *, day: str = "days") -> str:
    """An age in words, rounded to the unit that reads best; *day* names the day unit
    ("days" in sentences, "d" in tables)."""
    s = max(float(seconds), 0.0)
    if s < 90:
        return f"{s:.0f} s"
    if s < 90 * 60:
        return f"{s / 60:.0f} min"
    if s < 36 * 3600:
        return f"{s / 3600:.0f} h"
    return f"{s / 86400:.0f} {day}"


def mbit(bps: float | None) -> str:
    """Bits per second in words: Mbit/s, or kbit/s below 1 Mbit/s ("not measured" for None)."""
    if bps is None:
        return "not measured"
    return f"{bps / 1e6:.1f} Mbit/s" if bps >= 1e6 else f"{bps / 1e3:.0f} kbit/s"


def kb(n: int) -> str:
    """A message's size in words: kB, or MB from 1 MB (1 MB = 1024 kB, as the sizes tried)."""
    return f"{n / (1 << 20):g} MB" if n >= 1 << 20 else f"{n / 1024:g} kB"
