"""The documentation site builds in strict mode, and its generated tables follow the code."""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from ldn_jax.config import fields

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    if shutil.which("mkdocs", path=str(Path(sys.executable).parent)) is None:
        pytest.fail("mkdocs is not installed: it is in the dev extra (`make test` installs it)")
    out = tmp_path_factory.mktemp("site")
    mkdocs = str(Path(sys.executable).parent / "mkdocs")
    done = subprocess.run(
        [mkdocs, "build", "--strict", "--site-dir", str(out)],
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr[-4000:]
    return out


def test_the_site_builds_strict_with_every_page(site):
    # strict: a broken link, a missing page or a docstring mkdocstrings cannot read fails it
    for page in ("index", "flags", "configuration", "api", "design", "paper", "benchmarks"):
        path = site / "index.html" if page == "index" else site / page / "index.html"
        assert path.exists(), page


def test_the_flag_table_has_every_flag_of_the_command(site):
    from ldn_jax.host import cli

    html = (site / "flags" / "index.html").read_text()
    for command, parser in cli.parsers().items():
        assert command in html
        for action in parser._actions:
            for option in action.option_strings:
                if option not in ("-h", "--help"):
                    assert f"<code>{option}</code>" in html, (command, option)


def test_the_field_table_has_every_config_field(site):
    html = (site / "configuration" / "index.html").read_text()
    shown = set(re.findall(r"<td><code>([\w.]+)</code></td>", html))
    assert set(fields()) <= shown, set(fields()) - shown


def test_no_page_points_outside_the_repository():
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        assert "../shared" not in path.read_text(), path


def _readme_results() -> list[list[str]]:
    """The cells of each row of README.md's results table (header and rule left out)."""
    text = (ROOT / "README.md").read_text()
    section = text.split("## Results", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| ")]
    return [[cell.strip() for cell in row.strip("|").split(" | ")] for row in rows[1:]]


def _is_commit(name: str) -> bool:
    done = subprocess.run(
        ["git", "cat-file", "-e", f"{name}^{{commit}}"], cwd=ROOT, capture_output=True, check=False
    )
    return done.returncode == 0


def test_every_readme_result_names_its_record_and_commit():
    """Each results row names committed files that exist and the commit(s) that wrote them; a
    range of commits (runs trained across code versions) or no record says "exploratory"."""
    rows = _readme_results()
    assert len(rows) >= 5
    in_git = (ROOT / ".git").exists() and shutil.which("git")
    for cells in rows:
        assert len(cells) == 4, cells
        record = cells[-1]
        if record == "exploratory, no record":
            continue
        paths = re.findall(r"`([^`]+)`", record)
        assert paths, cells
        for path in paths:
            assert (ROOT / path).exists(), path
        commits = re.search(r"\(([0-9a-f]{7,40})(?:\.\.([0-9a-f]{7,40}))?[;)]", record)
        assert commits, cells
        if commits.group(2):
            assert "exploratory" in record, cells
        if in_git:
            assert all(_is_commit(c) for c in commits.groups() if c), record


def test_the_readme_headline_rows_have_a_record_per_arm():
    """A README row that quotes the headline study names its records folder, and every arm the
    study has scored there has its committed record."""
    from experiments.paper import headline

    rows = [cells for cells in _readme_results() if "records/headline" in cells[-1]]
    assert rows
    scored = sorted((ROOT / "experiments/results/headline/runs").glob("*.json"))
    for file in scored:
        if "gymnasium" in file.read_text():
            record = ROOT / "experiments/results/records/headline" / file.stem
            assert (record / "summary.json").is_file(), file.name
    assert set(headline.ARMS) >= {p.stem.split("-s10")[0].split("-", 1)[1] for p in scored}
