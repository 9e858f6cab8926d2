"""The README's topic table is the contract's table, verbatim."""

from pathlib import Path

from pneu_msgs_py.contract.topics import markdown_table


def test_readme_topic_table_matches_contract():
    readme = (Path(__file__).resolve().parents[3] / "README.md").read_text()
    assert markdown_table() in readme
