"""Small words for people: how an age reads ("40 s", "3 min", "5 h", "12 days")."""

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
