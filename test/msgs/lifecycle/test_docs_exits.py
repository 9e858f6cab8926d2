"""The exit-code table of docs/cli.md is :data:`pneu_msgs_py.lifecycle.exits.EXIT_CODES`, row for row."""

from __future__ import annotations

import re
from pathlib import Path

from pneu_msgs_py.lifecycle.exits import EXIT_CODES

CLI_DOC = Path(__file__).resolve().parents[3] / "docs" / "cli.md"


def test_cli_doc_lists_every_exit_code_as_the_code_does():
    text = CLI_DOC.read_text(encoding="utf-8")
    section = text[text.index("## Exit codes") :]
    section = section[: section.index("\n## ", 1)] if "\n## " in section[1:] else section
    rows = re.findall(r"^\| (\d+) \| (.+) \|$", section, flags=re.M)
    assert [(int(c), t) for c, t in rows] == list(EXIT_CODES)
