"""The README and docs/ against the tree and the code.

- the README stays the front door: at most 200 lines;
- every "DESIGN §n" cited anywhere in the tree (src, test, tools, config, docs, README,
  ARCHITECTURE) names a heading of docs/design.md, and every other section sign names
  the document it cites;
- every relative link of README.md, ARCHITECTURE.md and docs/*.md reaches a file of
  the repository, and its anchor a heading of that file; every repository path quoted
  in backticks exists;
- the tables that restate the code are the code's: the README's command table
  (subcommands and their options, from the parser itself), the first run (run ->
  analyze, executed), docs/results.md's generated blocks (the columns and rows
  ``pneu paper`` writes; ``tools/results_doc.py`` round trip), docs/design.md's
  experiments and gains (the catalogue, config/controllers.yaml), docs/ros2.md's node
  table (each package's console scripts), docs/choices.md's fault list, docs/calibration.md's
  parameters, tolerances and plants (the identification study's).
(The topic table and the exit codes have their own tests beside their modules.)
"""

from __future__ import annotations

import importlib.util
import math
import os
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
DESIGN = DOCS / "design.md"
MARKDOWN = [README, ROOT / "ARCHITECTURE.md", *sorted(DOCS.glob("*.md"))]
SCANNED_DIRS = ("src", "test", "tools", "config", "docs")
SKIP_DIRS = {"__pycache__", "build", "install", "log", ".venv", ".git"}
TEXT_SUFFIXES = {".py", ".md", ".yaml", ".yml", ".xml", ".cfg", ".toml", ".sh", ".txt", ".json"}

SECTION = re.compile(r"§\s*(\d+(?:\.\d+)*)")
# a section sign that does not cite the design names its document just before it
OTHER_DOCUMENTS = ("paper", "Digital Control,", "System Identification")
SECTION_8 = "## \N{SECTION SIGN}8 What the paper reports"  # escaped: not a citation
LINK = re.compile(r"(?<!!)\[([^\]]*)\]\(([^)\s]+)\)")


# --------------------------------------------------------------------------- helpers


def _prose(path: Path) -> list[tuple[int, str]]:
    """(line number, line) of a Markdown file outside fenced code blocks."""
    out, fence = [], False
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if line.lstrip().startswith("```"):
            fence = not fence
            continue
        if not fence:
            out.append((n, line))
    return out


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    anchors = set()
    for _, line in _prose(path):
        m = re.match(r"^#{1,6} (.+)$", line)
        if not m:
            continue
        base = _slug(m.group(1))
        k = seen.get(base, 0)
        seen[base] = k + 1
        anchors.add(base if k == 0 else f"{base}-{k}")
    return anchors


def _section(path: Path, heading: str) -> str:
    """The text under ``heading`` (a whole heading line) up to the next heading of its level."""
    text = path.read_text(encoding="utf-8")
    level = heading.split(" ")[0]
    start = text.index(heading + "\n") + len(heading) + 1
    nxt = re.search(rf"^{level} ", text[start:], flags=re.M)
    return text[start : start + nxt.start()] if nxt else text[start:]


def _cells(row: str) -> list[str]:
    return [c.strip() for c in re.split(r"(?<!\\)\|", row.strip())[1:-1]]


def _table_rows(text: str) -> list[list[str]]:
    """Body rows of the Markdown tables in ``text`` (header and separator left out)."""
    rows, header_next = [], True
    for line in text.splitlines():
        if not line.startswith("|"):
            header_next = True
            continue
        if header_next:  # the header line
            header_next = False
            continue
        if re.fullmatch(r"\|(\s*:?-+:?\s*\|)+", line.strip()):
            continue
        rows.append(_cells(line))
    return rows


def _tree_files() -> list[Path]:
    files = [README, ROOT / "ARCHITECTURE.md"]
    for top in SCANNED_DIRS:
        for dirpath, dirnames, filenames in os.walk(ROOT / top):  # links not followed
            dirnames[:] = [
                d for d in dirnames if d not in SKIP_DIRS and not d.endswith(".egg-info")
            ]
            files += [
                Path(dirpath) / f
                for f in filenames
                if Path(f).suffix in TEXT_SUFFIXES and not (Path(dirpath) / f).is_symlink()
            ]
    return sorted(files)


def _design_sections() -> set[str]:
    sections = set()
    for _, line in _prose(DESIGN):
        m = re.match(r"^#{2,6} §(\d+(?:\.\d+)*) \S", line)
        if m:
            sections.add(m.group(1))
    return sections


# --------------------------------------------------------------------------- the README


def test_readme_is_the_front_door_at_most_200_lines():
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= 200, f"README.md has {n} lines; move detail to docs/ (at most 200)"


# --------------------------------------------------------------------------- DESIGN §n


def test_design_has_one_heading_per_section_in_order():
    numbers = [
        int(m.group(1)) for _, line in _prose(DESIGN) if (m := re.match(r"^## §(\d+) ", line))
    ]
    assert numbers == list(range(1, len(numbers) + 1)), numbers


def test_every_design_section_cited_in_the_tree_is_a_heading_of_docs_design():
    sections = _design_sections()
    cited, unresolved, unnamed = set(), [], []
    for path in _tree_files():
        text = path.read_text(encoding="utf-8", errors="replace")
        rel = path.relative_to(ROOT)
        heading_lines = (
            {n for n, line in _prose(path) if re.match(r"^#{1,6} ", line)}
            if path == DESIGN
            else set()
        )
        for m in SECTION.finditer(text):
            line_no = text.count("\n", 0, m.start()) + 1
            if line_no in heading_lines:
                continue  # a heading of the design itself
            before = " ".join(text[max(0, m.start() - 80) : m.start()].split()).replace("*", "")
            design = path == DESIGN or re.search(r"(DESIGN|design\.md)\s*$", before)
            if not design:
                if not before.endswith(OTHER_DOCUMENTS):
                    unnamed.append(f"{rel}:{line_no}: ...{before[-40:]} §{m.group(1)}")
                continue
            cited.add(m.group(1))
            if m.group(1) not in sections:
                unresolved.append(f"{rel}:{line_no}: §{m.group(1)}")
    assert not unresolved, f"cited, but no such heading in docs/design.md: {unresolved}"
    assert not unnamed, f"a section sign that names no document (write DESIGN §n): {unnamed}"
    assert {"2", "3", "7"} <= cited  # the scan does see the tree's citations


# --------------------------------------------------------------------------- links and paths


def _links() -> list[tuple[Path, int, str]]:
    return [
        (path, n, m.group(2))
        for path in MARKDOWN
        for n, line in _prose(path)
        for m in LINK.finditer(line)
    ]


def test_every_relative_link_reaches_a_file_and_its_anchor():
    links = _links()
    assert len(links) > 20
    broken = []
    for path, n, target in links:
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        where = f"{path.relative_to(ROOT)}:{n}: {target}"
        if ROOT not in dest.parents and dest != ROOT:
            broken.append(f"{where} (outside the repository)")
        elif not dest.exists():
            broken.append(f"{where} (no such file)")
        elif anchor and (dest.suffix != ".md" or anchor not in _anchors(dest)):
            broken.append(f"{where} (no such heading)")
    assert not broken, broken


def test_every_repository_path_quoted_in_the_docs_exists():
    quoted = re.compile(r"`((?:config|tools|src|test|docs|pneu_\w+)/[^`\s]*)`")
    missing, n_paths = [], 0
    for path in MARKDOWN:
        for n, line in _prose(path):
            for m in quoted.finditer(line):
                p = m.group(1).split("::")[0].split(":")[0]
                if re.search(r"[<>*|]|\.\.\.", p):
                    continue  # a pattern, not a path
                n_paths += 1
                if p.startswith("pneu_"):  # inside a package: src/<pkg>/<pkg>/...
                    p = f"src/{p.split('/')[0]}/{p}"
                if not (ROOT / p).exists():
                    missing.append(f"{path.relative_to(ROOT)}:{n}: {p}")
    assert n_paths > 20
    assert not missing, missing


def test_the_slug_is_githubs():
    assert _slug("\N{SECTION SIGN}3 The control cycle") == "3-the-control-cycle"
    assert _slug("The `pneu` command") == "the-pneu-command"
    assert _slug("Topics (the message contract)") == "topics-the-message-contract"
    assert _slug("A first run: run → analyze → view") == "a-first-run-run--analyze--view"


# --------------------------------------------------------------------------- the command table


def _subparsers():
    import argparse

    from pneu_control.cli.main import build_parser

    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return sub.choices


def test_readme_command_table_is_the_parsers():
    choices = _subparsers()
    rows = _table_rows(_section(README, "## The `pneu` command"))
    assert rows
    listed, wrong = set(), []
    for cells in rows:
        m = re.fullmatch(r"`([^`]+)`", cells[0])
        assert m, cells[0]
        words = m.group(1).replace("\\|", "|").split()
        assert words[0] == "pneu", words
        cmd = words[1]
        if cmd not in choices:
            wrong.append(f"pneu {cmd}: no such subcommand")
            continue
        listed.add(cmd)
        options = {o for a in choices[cmd]._actions for o in a.option_strings}
        for w in words[2:]:
            opt = re.match(r"^\[?(--[a-z][a-z0-9-]*)", w)
            if opt and opt.group(1) not in options:
                wrong.append(f"pneu {cmd}: no option {opt.group(1)}")
    assert not wrong, wrong
    assert listed == set(choices), f"not in the README's table: {set(choices) - listed}"


def test_the_readme_first_run_prints_what_the_readme_says(tmp_path, capsys):
    from pneu_control.cli.main import main

    section = _section(README, "## A first run: run → analyze → view")
    blocks = re.findall(r"^```(\w*)\n(.*?)^```", section, flags=re.M | re.S)
    (commands,) = [b for lang, b in blocks if lang == "bash"]
    commands = commands.replace("\\\n", " ")
    (shown,) = [b for lang, b in blocks if lang == ""]
    out = {}
    for line in commands.strip().splitlines():
        argv = shlex.split(line.replace("out/first", str(tmp_path / "first")))
        assert argv[0] == ".venv/bin/pneu", argv
        capsys.readouterr()
        assert main(argv[1:]) == 0, line
        out[argv[1]] = capsys.readouterr().out
    assert out["analyze"] == shown, f"the README's first run now prints:\n{out['analyze']}"
    assert (tmp_path / "first" / "run.png").stat().st_size > 0


# --------------------------------------------------------------------------- docs/results.md


def _results_doc():
    spec = importlib.util.spec_from_file_location("results_doc", ROOT / "tools" / "results_doc.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_results_nominal_block_is_what_pneu_paper_writes():
    from pneu_control.experiment.catalog import PAPER_EXPERIMENTS
    from pneu_control.experiment.paper import render_markdown, runs_for

    block = _results_doc().block_text((DOCS / "results.md").read_text(encoding="utf-8"), "nominal")
    header = render_markdown([])
    assert block.startswith(header), "the nominal table's columns are not render_markdown's"
    n_cols = len(_cells(header.splitlines()[0]))
    rows = [_cells(line) for line in block.splitlines()[2:]]
    assert all(len(r) == n_cols for r in rows)
    expected = [(e.id, c, g) for e in PAPER_EXPERIMENTS for c, g in runs_for(e)]
    assert [tuple(r[:3]) for r in rows] == expected, (
        "docs/results.md's rows are not pneu paper's: regenerate them with bash tools/paper.sh"
    )


def test_results_uncertainty_block_has_the_summary_columns():
    from pneu_control.sweep.summary import render_summary

    block = _results_doc().block_text(
        (DOCS / "results.md").read_text(encoding="utf-8"), "uncertainty"
    )
    n = int(re.match(r"Over (\d+) plant samples", block).group(1))
    assert block.startswith(render_summary([], [], n))
    assert "P(ESO-SMC < LADRC < PID)" in block


def test_results_doc_tool_replaces_only_inside_the_markers(tmp_path):
    tool = _results_doc()
    from pneu_control.experiment.paper import render_markdown

    doc = (DOCS / "results.md").read_text(encoding="utf-8")
    target = tmp_path / "results.md"
    target.write_text(doc, encoding="utf-8")
    nominal = render_markdown([]) + "| x | y | z |\n"
    (tmp_path / "nominal.md").write_text(nominal, encoding="utf-8")
    assert tool.main([str(tmp_path / "nominal.md"), str(target)]) == 0
    new = target.read_text(encoding="utf-8")
    assert tool.block_text(new, "nominal") == nominal.strip("\n")
    assert tool.block_text(new, "uncertainty") == tool.block_text(doc, "uncertainty")  # kept
    begin, end = tool.markers("nominal")
    assert new[: new.index(begin)] == doc[: doc.index(begin)]
    assert new[new.index(end) :] == doc[doc.index(end) :]
    # with the band table appended under its heading (as pneu paper --uncertainty does):
    # both replaced, the heading left out (the page has its own)
    (tmp_path / "both.md").write_text(
        nominal + "\n## Over 3 plant samples (uncertainty/)\n\nOver 3 plant samples\n\n| a |\n",
        encoding="utf-8",
    )
    assert tool.main([str(tmp_path / "both.md"), str(target)]) == 0
    assert tool.block_text(target.read_text(encoding="utf-8"), "uncertainty") == (
        "Over 3 plant samples\n\n| a |"
    )
    assert tool.main([str(tmp_path / "missing.md"), str(target)]) == 2


# --------------------------------------------------------------------------- docs/design.md


def _num(text: str) -> float:
    return float(text.replace(" ", ""))


def test_design_experiments_are_the_catalogues():
    from pneu_control.experiment.catalog import PAPER_EXPERIMENTS

    rows = _table_rows(_section(DESIGN, SECTION_8))
    experiments = [r for r in rows if len(r) == 4]
    assert [re.match(r"`(\w+)`", r[0]).group(1) for r in experiments] == [
        e.id for e in PAPER_EXPERIMENTS
    ]
    for exp, (_, controllers, e_max, rmse) in zip(PAPER_EXPERIMENTS, experiments, strict=True):
        assert tuple(c.strip() for c in controllers.split(",")) == exp.controllers
        unit = f" {exp.unit}"
        assert e_max.endswith(unit)
        assert [_num(v) for v in e_max[: -len(unit)].split(",")] == [
            exp.paper[c][0] for c in exp.controllers
        ]
        paper_rmse = [exp.paper[c][1] for c in exp.controllers]
        if rmse == "—":
            assert paper_rmse == [None] * len(paper_rmse)
        else:
            assert [_num(v) for v in rmse[: -len(unit)].split(",")] == paper_rmse


def test_design_gains_are_config_controllers_yaml():
    import yaml

    cfg = yaml.safe_load((ROOT / "config" / "controllers.yaml").read_text(encoding="utf-8"))
    rows = [r for r in _table_rows(_section(DESIGN, SECTION_8)) if len(r) == 3]
    assert len(rows) == 14
    for name, lin, rot in rows:
        group, key = name.strip("`").split(".")
        for axis, text in (("linear", lin), ("rotary", rot)):
            value = cfg[f"{axis}_controller"]["ros__parameters"][group][key]
            assert math.isclose(float(text), value), (axis, name, text, value)


# --------------------------------------------------------------------------- ros2.md, choices.md


def _console_scripts(pkg: str) -> set[str]:
    setup = (ROOT / "src" / pkg / "setup.py").read_text(encoding="utf-8")
    block = setup[setup.index('"console_scripts"') :]
    block = block[: block.index("]")]
    return set(re.findall(r'"\s*(\w+)\s*=\s*[\w.]+:\w+\s*"', block))


def test_ros2_node_table_names_installed_executables():
    rows = _table_rows(_section(DOCS / "ros2.md", "## Nodes"))
    assert len(rows) >= 8
    for cells in rows:
        m = re.fullmatch(r"`ros2 run (\w+) (\w+)`", cells[0])
        assert m, cells[0]
        assert m.group(2) in _console_scripts(m.group(1)), cells[0]


def test_choices_list_every_fault_the_twin_injects():
    from pneu_sim.faults.injection import FAULT_NAMES, parse_fault

    text = (DOCS / "choices.md").read_text(encoding="utf-8")
    bullet = text[text.index("- **Faults**") :].split("\n- ")[0]
    assert set(FAULT_NAMES) <= set(re.findall(r"`(\w+)`", bullet))
    for example in re.findall(r"`--fault ([^`]+)`", bullet):
        parse_fault(example)  # the example is accepted as written


@pytest.mark.parametrize("path", MARKDOWN, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_page_has_one_title(path):
    titles = [line for _, line in _prose(path) if line.startswith("# ")]
    assert len(titles) == 1, titles


def test_calibration_tables_are_the_studys_parameters_tolerances_and_plants():
    from pneu_control.sysid.study import CURVE_TOLERANCE, PERTURBATIONS, TOLERANCE

    text = _section(
        ROOT / "docs" / "calibration.md",
        "# Calibrating the twin on a rig: excite → identify → validate → tune",
    )
    rows = [r for r in _table_rows(text) if re.fullmatch(r"[\w. σΔ]+ \(±[\d.]+( %)?\)", r[0])]
    curves = [r for r in rows if ".curve " in r[0]]  # a valve's own curve, where fitted and beyond
    errors = [r for r in rows if r not in curves]
    assert len(errors) == len(TOLERANCE) + 2  # noise σ of p_c1, p_c2 and p_m1 share noise.p
    for cells in curves:
        assert re.fullmatch(r"valve_(linear|rotary)\.curve worst Δf (where fitted|beyond the data) \(±[\d.]+\)", cells[0]), cells[0]  # fmt: skip
        assert math.isclose(float(cells[0].split("(±")[1][:-1]), CURVE_TOLERANCE), cells[0]
        assert len(cells) == 1 + len(PERTURBATIONS), cells[0]
    for cells in errors:
        name, tol = re.fullmatch(r"(.+) \(±([\d.]+(?: %)?)\)", cells[0]).groups()
        key = {"noise σ x": "noise.x"}.get(
            name, "noise.p" if name.startswith("noise σ p") else name
        )
        kind, value = TOLERANCE[key]
        stated = ("rel", float(tol[:-2]) / 100) if tol.endswith(" %") else ("abs", float(tol))
        assert kind == stated[0] and math.isclose(value, stated[1]), (cells[0], TOLERANCE[key])
        assert len(cells) == 1 + len(PERTURBATIONS), cells[0]
    held_out = [r for r in _table_rows(text) if len(r) == 5 and r[0] in PERTURBATIONS]
    assert [r[0] for r in held_out] == list(PERTURBATIONS)
