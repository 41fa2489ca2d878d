"""The docs keep up with the code: every scenario, failure reason and command-line option is
documented in README.md or docs/*.md, the README's scenario table states each scenario's
expected outcome, and no file of the project names a path outside the repository."""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterable, Iterator
from pathlib import Path

import pytest

from pickplace.cli import build_parser
from pickplace.sim.checks import FAILURE_REASONS
from pickplace.sim.parameters import PARAMETERS
from pickplace.sim.scenarios import SCENARIOS, Scenario

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"
# What the project consists of (its own files, not the environment it was made in).
SCANNED_DIRS = ("pickplace", "tests", "scripts", "docs", "robots", "scenes", ".ci")
SCANNED_FILES = ("README.md", "pyproject.toml", ".gitignore")
# Written in two parts so that this file does not contain them itself.
OUTSIDE_PATHS = ("../" + "shared", "/" + "work/")


def doc_texts() -> dict[str, str]:
    """README.md and every docs/*.md, by path relative to the repository."""
    paths = [REPO / "README.md", *sorted(DOCS.glob("*.md"))]
    return {str(p.relative_to(REPO)): p.read_text() for p in paths}


def code_spans(text: str) -> list[str]:
    """The Markdown code in ``text``: fenced blocks, then inline spans outside them."""
    fences = re.findall(r"^```[^\n]*\n(.*?)^```", text, flags=re.MULTILINE | re.DOTALL)
    prose = re.sub(r"^```[^\n]*\n.*?^```", "", text, flags=re.MULTILINE | re.DOTALL)
    return fences + re.findall(r"`([^`]+)`", prose)


def mentions(name: str, texts: Iterable[str]) -> bool:
    """Whether ``name`` appears as a whole word (not inside a longer name such as
    ``pick-place-random`` for ``pick-place``) in the Markdown code of any of ``texts``."""
    word = re.compile(rf"(?<![\w-]){re.escape(name)}(?![\w-])")
    return any(word.search(span) for text in texts for span in code_spans(text))


def undocumented(names: Iterable[str], texts: Iterable[str]) -> list[str]:
    """The names no text mentions (see :func:`mentions`)."""
    texts = list(texts)
    return [n for n in names if not mentions(n, texts)]


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The parser's subcommands by name ("" for the top-level parser itself)."""
    found = {"": parser}
    for action in parser._actions:  # argparse has no public way to list them
        if isinstance(action, argparse._SubParsersAction):
            found.update(action.choices)
    return found


def long_options(parser: argparse.ArgumentParser) -> list[str]:
    """Every ``--option`` of one parser (not of its subcommands)."""
    return [s for a in parser._actions for s in a.option_strings if s.startswith("--")]


def cli_options(parser: argparse.ArgumentParser) -> dict[str, list[str]]:
    """Subcommand ("" for the top level) → its ``--options``, argparse's ``--help`` included."""
    return {name: long_options(p) for name, p in subcommands(parser).items()}


def synopsis(text: str) -> dict[str, str]:
    """The first code block of ``text`` as a synopsis: subcommand → the text of its entry (a
    line starting ``pickplace NAME`` and its indented continuation lines; "" for ``pickplace
    --option`` lines)."""
    block = code_spans(text)[0]
    entries: dict[str, str] = {}
    current: str | None = None
    for line in block.splitlines():
        if m := re.match(r"pickplace (\S+)", line):
            current = "" if m.group(1).startswith("-") else m.group(1)
            entries[current] = entries.get(current, "") + line + "\n"
        elif current is not None and line.startswith(" "):
            entries[current] += line + "\n"
    return entries


def missing_from_synopsis(
    options: dict[str, list[str]], entries: dict[str, str]
) -> dict[str, list[str]]:
    """Per subcommand, the options its synopsis entry does not show (``--help`` aside, which
    every command has)."""
    missing = {}
    for command, opts in options.items():
        entry = entries.get(command, "")
        absent = [o for o in opts if o != "--help" and not mentions(o, [f"`{entry}`"])]
        if command and command not in entries:
            absent.insert(0, "(no entry)")
        if absent:
            missing[command] = absent
    return missing


def table_rows(text: str, first_cells: Iterable[str]) -> dict[str, str]:
    """Rows of Markdown tables whose first cell is `` `name` `` for one of ``first_cells``."""
    wanted = set(first_cells)
    rows = {}
    for line in text.splitlines():
        m = re.match(r"\| `([^`]+)` \|(.*)\|\s*$", line)
        if m and m.group(1) in wanted:
            rows[m.group(1)] = m.group(2)
    return rows


def outcome_problems(scenarios: Iterable[Scenario], rows: dict[str, str]) -> list[str]:
    """What a scenario table gets wrong: a missing row, or a row whose last cell does not name
    each outcome (and each controller other than the default ``qp`` with its outcome)."""
    problems = []
    for s in scenarios:
        if s.name not in rows:
            problems.append(f"{s.name}: no row")
            continue
        last = rows[s.name].split("|")[-1]
        for controller, outcome in s.outcomes().items():
            if outcome not in last or (controller != "qp" and f"`{controller}`" not in last):
                problems.append(f"{s.name}: {outcome} with {controller} not in '{last.strip()}'")
    return problems


def project_files(root: Path) -> Iterator[Path]:
    """The project's text files under ``root``: :data:`SCANNED_DIRS` and
    :data:`SCANNED_FILES`, without caches and binary files (those with a NUL byte)."""
    paths = [root / f for f in SCANNED_FILES if (root / f).is_file()]
    for d in SCANNED_DIRS:
        if (root / d).is_dir():
            paths += sorted(p for p in (root / d).rglob("*") if p.is_file())
    for p in paths:
        if "__pycache__" in p.parts or b"\0" in p.read_bytes()[:8192]:
            continue
        yield p


def outside_path_mentions(root: Path) -> list[str]:
    """``path:line: text`` of every line of a project file that names a path outside the
    repository (:data:`OUTSIDE_PATHS`)."""
    found = []
    for p in project_files(root):
        for i, line in enumerate(p.read_text(errors="replace").splitlines(), 1):
            if any(s in line for s in OUTSIDE_PATHS):
                found.append(f"{p.relative_to(root)}:{i}: {line.strip()}")
    return found


# --------------------------------------------------------------------------- the project


def test_every_scenario_is_documented() -> None:
    assert undocumented(SCENARIOS, doc_texts().values()) == []


def test_the_readme_and_the_scenarios_page_state_each_scenarios_outcome() -> None:
    for doc in ("README.md", "docs/scenarios.md"):
        text = (REPO / doc).read_text()
        assert outcome_problems(SCENARIOS.values(), table_rows(text, SCENARIOS)) == [], doc


def test_every_varied_parameter_has_its_row_with_unit_and_range() -> None:
    """docs/sweeps.md's table of varied parameters has a row per ``--vary`` name, with its
    unit and its range (or grid) as the parameter states them."""
    rows = {
        m.group(1): m.group(0)
        for m in re.finditer(
            r"^\| `([a-z_]+)` \| ([^|]+) \| ([^|]+) \|.*$", (DOCS / "sweeps.md").read_text(), re.M
        )
    }
    for name, p in PARAMETERS.items():
        assert name in rows, f"docs/sweeps.md has no row for --vary {name}"
        cells = [c.strip() for c in rows[name].split("|")[1:-1]]
        assert cells[1] == p.unit, name
        assert f"{p.low:g}" in cells[2] and f"{p.high:g}" in cells[2], name
        assert ("grid" in cells[2]) == p.grid_only, name


def test_every_failure_reason_is_documented() -> None:
    assert undocumented(FAILURE_REASONS, doc_texts().values()) == []


def test_every_command_and_option_is_documented() -> None:
    options = cli_options(build_parser())
    assert {"run", "plan", "sweep", "scenarios", "robots"} <= set(options)
    texts = doc_texts().values()
    assert undocumented([f"pickplace {c}" for c in options if c], texts) == []
    assert undocumented(sorted({o for opts in options.values() for o in opts}), texts) == []


def test_the_cli_synopsis_shows_every_option_of_every_command() -> None:
    options = cli_options(build_parser())
    entries = synopsis((DOCS / "cli.md").read_text())
    assert missing_from_synopsis(options, entries) == {}


def test_no_project_file_names_a_path_outside_the_repository() -> None:
    assert len(list(project_files(REPO))) > 50
    assert outside_path_mentions(REPO) == []


# --------------------------------------------------------------------------- the checks fail


def test_mentions_are_whole_names_in_code() -> None:
    text = "Run `pickplace run --scenario pick-place-random`; fault-knock in prose.\n"
    assert mentions("pick-place-random", [text])
    assert mentions("--scenario", [text])
    assert not mentions("pick-place", [text])  # only inside a longer name
    assert not mentions("fault-knock", [text])  # not in code
    assert mentions("fault-knock", ["```\npickplace run --scenario fault-knock\n```\n"])
    assert undocumented(["pick-place-random", "no-such-scenario"], [text]) == ["no-such-scenario"]


def test_an_undocumented_option_or_command_is_found() -> None:
    parser = argparse.ArgumentParser(prog="pickplace")
    parser.add_argument("--version", action="version", version="0")
    sub = parser.add_subparsers(dest="command")
    sub.add_parser("run").add_argument("--made-up-option")
    sub.add_parser("made-up-command").add_argument("--json", action="store_true")
    options = cli_options(parser)
    assert options == {
        "": ["--help", "--version"],
        "run": ["--help", "--made-up-option"],
        "made-up-command": ["--help", "--json"],
    }
    doc = "```\npickplace run [--json]\npickplace --version\n```\n"
    assert missing_from_synopsis(options, synopsis(doc)) == {
        "run": ["--made-up-option"],
        "made-up-command": ["(no entry)", "--json"],
    }
    assert undocumented(["--made-up-option", "--version"], [doc]) == ["--made-up-option"]


def test_a_wrong_or_missing_outcome_is_found() -> None:
    reach = SCENARIOS["singular-reach"]
    good = (
        "| `singular-reach` | past full stretch "
        "| success with `qp`; `limit-violated` with `pinv` and `dls` |"
    )
    assert outcome_problems([reach], table_rows(good, ["singular-reach"])) == []
    bad = "| `singular-reach` | past full stretch | success |"
    assert len(outcome_problems([reach], table_rows(bad, ["singular-reach"]))) == 2
    assert outcome_problems([reach], {}) == ["singular-reach: no row"]


def test_a_path_outside_the_repository_is_found_and_binary_files_are_skipped(
    tmp_path: Path,
) -> None:
    (tmp_path / "pickplace").mkdir()
    (tmp_path / "pickplace" / "a.py").write_text('"""See ../' + 'shared/notes/x.md."""\n')
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "b.md").write_text("Run it from /" + "work/main.\n")
    (tmp_path / "docs" / "c.png").write_bytes(b"\x89PNG\0/" + b"work/")
    (tmp_path / "README.md").write_text("Clean.\n")
    found = outside_path_mentions(tmp_path)
    assert [f.split(":")[0] for f in found] == ["pickplace/a.py", "docs/b.md"]


@pytest.mark.parametrize("name", ["README.md", "docs/cli.md"])
def test_the_docs_it_reads_exist(name: str) -> None:
    assert (REPO / name).is_file()
