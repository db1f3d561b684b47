"""Reading an nft ruleset text as nft does (statements, blocks, strings, comments), so that root
loads a copy of our table from the user's undo journal only when it is our table and nothing
else: no other table, no ``flush ruleset`` (however indented, or after a ``;``), no ``include``
or ``define``, no chain but ours on the input hook with policy accept, no NAT nor queueing."""

from __future__ import annotations

from dataclasses import dataclass, field


class NftTextError(ValueError):
    """The text is not one nft may read the way we read it (an unclosed block or string)."""


@dataclass
class Stmt:
    """One statement: its words (the text outside its blocks) and its blocks, in order."""

    words: list[str] = field(default_factory=list)
    blocks: list[list[Stmt]] = field(default_factory=list)


def parse(text: str) -> list[Stmt]:
    """The top-level statements of *text* (empty ones dropped)."""
    stmts, i = _block(text, 0, top=True)
    if i != len(text):
        raise NftTextError("a '}' closes nothing")
    return stmts


def _block(text: str, i: int, top: bool) -> tuple[list[Stmt], int]:
    out: list[Stmt] = []
    cur, word = Stmt(), []

    def end_word() -> None:
        if word:
            cur.words.append("".join(word))
            word.clear()

    def end_stmt() -> None:
        nonlocal cur
        end_word()
        if cur.words or cur.blocks:
            out.append(cur)
        cur = Stmt()

    n = len(text)
    while i < n:
        ch = text[i]
        if ch == '"':
            j = text.find('"', i + 1)
            if j < 0:
                raise NftTextError("a string is not closed")
            word.append(text[i:j + 1])
            i = j + 1
        elif ch == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif ch == "\\" and text[i + 1:i + 2] == "\n":
            i += 2                                  # a continued line
        elif ch in ";\n":
            end_stmt()
            i += 1
        elif ch == "{":
            end_word()
            inner, i = _block(text, i + 1, top=False)
            cur.blocks.append(inner)
        elif ch == "}":
            if top:
                raise NftTextError("a '}' closes nothing")
            end_stmt()
            return out, i + 1
        elif ch.isspace():
            end_word()
            i += 1
        else:
            word.append(ch)
            i += 1
    if not top:
        raise NftTextError("a '{' is not closed")
    end_stmt()
    return out, i


# Words no statement of our table holds: other tables, the whole ruleset, other files, NAT,
# packets handed to user space, jumps out of our one chain.
_FORBIDDEN = {"table", "flush", "include", "define", "redefine", "undefine", "delete", "add",
              "create", "insert", "replace", "reset", "destroy", "rename", "list", "dnat",
              "snat", "redirect", "masquerade", "queue", "dup", "fwd", "tproxy", "jump", "goto",
              "notrack", "meta", "mark", "hook", "policy", "type", "priority"}
_SET_WORDS = {"type", "typeof", "flags", "elements", "size", "timeout", "gc-interval",
              "auto-merge", "policy", "comment", "counter"}


def _words(stmts: list[Stmt]) -> list[str]:
    out = []
    for s in stmts:
        out += s.words
        for b in s.blocks:
            out += _words(b)
    return out


def _verdict_words(words: list[str]) -> list[str]:
    """*words* without the ``reset`` of the verdict ``reject with tcp reset`` (a rule's own
    answer to strangers, not the ``reset`` command)."""
    out = list(words)
    for i in range(len(out) - 3):
        if out[i:i + 4] == ["reject", "with", "tcp", "reset"]:
            out[i + 3] = "tcp-reset"
    return out


def our_table_problem(text: str, table: str, chain: str, sets: set[str]) -> str | None:
    """Why *text* is not our table alone (None: it is): ``table <table> { ... }`` holding only
    the *sets* and the one *chain*, a filter chain on the input hook with policy accept."""
    try:
        top = parse(text)
    except NftTextError as exc:
        return str(exc)
    if len(top) != 1 or top[0].words != ["table", *table.split()] or len(top[0].blocks) != 1:
        return f"it holds more than the table {table} (or not that table)"
    for s in top[0].blocks[0]:
        if len(s.words) != 2 or len(s.blocks) != 1:
            return f"'{' '.join(s.words)[:60]}' is not a set or a chain of ours"
        kind, name = s.words
        if kind == "set" and name in sets:
            for inner in s.blocks[0]:
                if not inner.words or inner.words[0] not in _SET_WORDS or any(
                        w in _FORBIDDEN - {"type", "policy"} for w in _words([inner])):
                    return f"the set {name} holds '{' '.join(inner.words)[:60]}'"
            continue
        if kind != "chain" or name != chain:
            return f"'{kind} {name}' is not a set or the chain of ours"
        body = s.blocks[0]
        head = [x.words for x in body if x.words[:1] in (["type"], ["policy"])]
        if len(head) != 2 or head[0][:4] != ["type", "filter", "hook", "input"] \
                or head[1] != ["policy", "accept"]:
            return f"the chain {name} is not a filter on the input hook with policy accept"
        for rule in body:
            if rule.words[:1] in (["type"], ["policy"]):
                continue
            bad = sorted(set(_verdict_words(_words([rule]))) & _FORBIDDEN)
            if bad:
                return f"a rule of the chain {name} holds '{bad[0]}'"
    return None
