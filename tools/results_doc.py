#!/usr/bin/env python3
"""Copy ``pneu paper``'s tables into docs/results.md, between its ``generated`` markers.

    .venv/bin/python tools/results_doc.py [out/paper/paper_table.md] [docs/results.md]

``paper_table.md`` is the nominal table, and after ``pneu paper --uncertainty N`` a blank
line and the band and ranking tables. The nominal block is always replaced; the
uncertainty block only when the file has one (``tools/paper.sh`` runs without it), else
it is kept and the script says so. Nothing outside the markers changes.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BLOCKS = ("nominal", "uncertainty")


def markers(block: str) -> tuple[str, str]:
    return (
        f"<!-- begin generated: paper_table.md, {block} -->",
        f"<!-- end generated: paper_table.md, {block} -->",
    )


def split_table(text: str) -> dict[str, str]:
    """paper_table.md -> {"nominal": ..., "uncertainty": ...} (the latter only if present).

    The band tables come under pneu paper's own heading ("## Over N plant samples
    (uncertainty/)"); the page has its section heading, so that line is not copied.
    """
    nominal, _, rest = text.strip("\n").partition("\n\n")
    parts = {"nominal": nominal.strip("\n")}
    rest = rest.strip("\n")
    if rest.startswith("## "):
        rest = rest.partition("\n")[2].strip("\n")
    if rest:
        parts["uncertainty"] = rest
    return parts


def block_text(doc: str, block: str) -> str:
    """The text between a block's markers in ``doc`` (ValueError if the markers are not there)."""
    begin, end = markers(block)
    i, j = doc.find(begin), doc.find(end)
    if i < 0 or j < i:
        raise ValueError(f"{begin!r} ... {end!r} not found (in this order)")
    return doc[i + len(begin) : j].strip("\n")


def replace_blocks(doc: str, parts: dict[str, str]) -> str:
    for block, text in parts.items():
        block_text(doc, block)  # both markers there, in order
        begin, end = markers(block)
        i, j = doc.index(begin) + len(begin), doc.index(end)
        doc = doc[:i] + "\n" + text + "\n" + doc[j:]
    return doc


def main(argv: list[str]) -> int:
    table = Path(argv[0]) if argv else ROOT / "out/paper/paper_table.md"
    target = Path(argv[1]) if len(argv) > 1 else ROOT / "docs/results.md"
    if not table.is_file():
        print(f"results_doc: {table}: no such file (run pneu paper first)", file=sys.stderr)
        return 2
    parts = split_table(table.read_text(encoding="utf-8"))
    doc = target.read_text(encoding="utf-8")
    try:
        new = replace_blocks(doc, parts)
    except ValueError as err:
        print(f"results_doc: {target}: {err}", file=sys.stderr)
        return 2
    target.write_text(new, encoding="utf-8")
    kept = [b for b in BLOCKS if b not in parts]
    print(
        f"results_doc: {target}: replaced {', '.join(parts)} from {table}"
        + (f"; kept {', '.join(kept)} (not in {table.name})" if kept else "")
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
