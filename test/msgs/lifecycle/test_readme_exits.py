"""The README's exit-code table is :data:`pneu_msgs_py.lifecycle.exits.EXIT_CODES`, row for row."""

from __future__ import annotations

import re
from pathlib import Path

from pneu_msgs_py.lifecycle.exits import EXIT_CODES

README = Path(__file__).resolve().parents[3] / "README.md"


def test_readme_lists_every_exit_code_as_the_code_does():
    text = README.read_text(encoding="utf-8")
    section = text[text.index("### Exit codes") :]
    rows = re.findall(r"^\| (\d+) \| (.+) \|$", section, flags=re.M)
    assert [(int(c), t) for c, t in rows[: len(EXIT_CODES)]] == list(EXIT_CODES)
