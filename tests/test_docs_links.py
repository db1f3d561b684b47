"""The README and docs/ (issue 33): every relative link and #anchor in them resolves, and the README
stays a newcomer's five minutes: at most 250 lines, opening with the two set-up commands (their
text is tests/test_install.py's business)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("*.md"))]
MAX_README_LINES = 250

FENCE = re.compile(r"^(```|~~~).*?^\1[ \t]*$", re.S | re.M)
CODE_SPAN = re.compile(r"(`+).+?\1", re.S)
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HEADING = re.compile(r"^ {0,3}(#{1,6})[ \t]+(.*?)[ \t#]*$", re.M)
EXTERNAL = re.compile(r"^[a-z][a-z0-9+.-]*:", re.I)     # https:, mailto:, ...


def prose(text: str) -> str:
    """*text* without its fenced code blocks and code spans (a link there is only an example)."""
    return CODE_SPAN.sub("", FENCE.sub("", text))


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: its text without markup, lower case, punctuation dropped
    (letters, digits, `_` and `-` stay), each space a `-`."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)     # a link: its text
    text = re.sub(r"<[^>]+>", "", text).replace("`", "")           # html tags, code markers
    text = re.sub(r"(\*\*|__|\*)", "", text)                        # emphasis
    return re.sub(r"[^\w\- ]", "", text.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """Every anchor GitHub gives *page*'s headings (a repeated one gets -1, -2, ...), and explicit
    `<a id=...>` or `name=` targets."""
    seen: dict[str, int] = {}
    out = set()
    text = FENCE.sub("", page.read_text(encoding="utf-8"))
    for m in HEADING.finditer(text):
        base = slug(m.group(2))
        n = seen.get(base, 0)
        out.add(base if n == 0 else f"{base}-{n}")
        seen[base] = n + 1
    out.update(re.findall(r"<a\s+(?:id|name)=\"([^\"]+)\"", text))
    return out


def links(page: Path) -> list[str]:
    return LINK.findall(prose(page.read_text(encoding="utf-8")))


def test_the_slugs_follow_githubs_rules():
    assert slug("Seen from outside: security.ssh_auth and security.outsider") == \
        "seen-from-outside-securityssh_auth-and-securityoutsider"
    assert slug("ROS 2: only the fleet gets in (mutual TLS)") == \
        "ros-2-only-the-fleet-gets-in-mutual-tls"
    assert slug("The modem (UPnP IGD, PCP, NAT-PMP)") == "the-modem-upnp-igd-pcp-nat-pmp"
    assert slug("`linux.hosts` says *missing*") == "linuxhosts-says-missing"
    assert slug("ROS 1's firewall") == "ros-1s-firewall"


def test_the_link_finder_sees_links_and_pictures_but_not_code():
    text = "[a](x.md#b) ![p](pic.svg) `[c](no.md)` [d](https://example.org)\n```\n[e](no.md)\n```\n"
    assert LINK.findall(prose(text)) == ["x.md#b", "pic.svg", "https://example.org"]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_and_anchor_resolves(page):
    bad = []
    for target in links(page):
        if EXTERNAL.match(target):
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif not str(dest).startswith(str(ROOT)):
            bad.append(f"{target}: outside the repository")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading with that anchor in {dest.relative_to(ROOT)}")
    assert not bad, f"{page.relative_to(ROOT)}: links that do not resolve:\n" + "\n".join(bad)


def test_the_readme_is_short_and_opens_with_the_set_up_commands():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_README_LINES, \
        f"README.md has {len(lines)} lines (at most {MAX_README_LINES}): move the rest to docs/"
    assert lines[0].startswith("# ") and lines[1] == "" and lines[2].startswith("```"), \
        "the README opens with the user's set-up command right under its title"
    before_first_section = "\n".join(lines[:next(n for n, ln in enumerate(lines)
                                                 if ln.startswith("## "))])
    assert len(FENCE.findall(before_first_section)) == 2, \
        "both set-up commands come before the README's first section"


def test_the_readme_points_into_docs():
    """Every page of docs/ is reachable from the README."""
    targets = {(ROOT / t.partition("#")[0]).resolve() for t in links(README)
               if not EXTERNAL.match(t)}
    missing = [p.name for p in PAGES[1:] if p.resolve() not in targets]
    assert not missing, f"README.md links to no {missing}"
