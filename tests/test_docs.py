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


def _study_files_with_records(study: str) -> list[Path]:
    """A study that a README row quotes: the row names `records/STUDY`, its per-run files in
    `experiments/results/STUDY/arms` are committed (not git-ignored), and every run replayed
    in gymnasium there has its committed record. Returns those files."""
    rows = [cells for cells in _readme_results() if f"records/{study}" in cells[-1]]
    assert rows
    scored = sorted((ROOT / "experiments/results" / study / "arms").glob("*.json"))
    assert scored  # the study's per-run files are committed, not ignored
    if (ROOT / ".git").exists() and shutil.which("git"):
        ignored = subprocess.run(
            ["git", "check-ignore", "-q", str(scored[0])], cwd=ROOT, check=False
        ).returncode
        assert ignored == 1, f"{scored[0]} is git-ignored"
    for file in scored:
        if "gymnasium" in file.read_text():
            record = ROOT / "experiments/results/records" / study / file.stem
            assert (record / "summary.json").is_file(), file.name
    return scored


def test_the_readme_headline_rows_have_a_record_per_arm():
    from experiments.paper import headline

    scored = _study_files_with_records("headline")
    assert set(headline.ARMS) >= {p.stem.split("-s10")[0].split("-", 1)[1] for p in scored}


def test_the_readme_sac_rows_have_a_record_per_scored_run():
    _study_files_with_records("sac")


def test_the_readme_a2c_rows_have_a_record_per_scored_run():
    _study_files_with_records("a2c")


def _words(text: str) -> set[str]:
    return set(re.findall(r"[\w-]+", text))


def test_every_choice_is_named_in_its_flags_help_and_the_field_table(site):
    """A value added to a choice field (a stop rule, an estimator, a world, ...) must be
    described where users look: its flag's help and the docs' field table."""
    from ldn_jax.config import CHOICES
    from ldn_jax.host import flags

    parser = flags.parser()
    by_dest = {action.dest: action for action in parser._actions}
    for flag, field in flags.CONFIG_FLAGS.items():
        if field in CHOICES:
            help_text = by_dest[flag].help
            missing = [c for c in CHOICES[field] if c not in _words(help_text)]
            assert not missing, (flag, missing)
            if by_dest[flag].choices is not None:
                assert tuple(by_dest[flag].choices) == CHOICES[field], flag
    html = (site / "configuration" / "index.html").read_text()
    for field, values in CHOICES.items():
        row = html.split(f"<td><code>{field}</code></td>", 1)[1].split("</tr>", 1)[0]
        missing = [v for v in values if f"<code>{v}</code>" not in row]
        assert not missing, (field, missing)


def test_the_choice_table_is_what_validate_accepts():
    from ldn_jax.config import CHOICES, Config, from_preset, validate

    for field in CHOICES:
        section, _, name = field.rpartition(".")
        bad = {name: "no-such-value"}
        overrides = {section: bad} if section else bad
        with pytest.raises(ValueError):
            validate(from_preset("paper", **{"env": "cartpole-v1", **overrides}))
    assert Config().stop.rule is None  # the algorithm's own rule: not one of the names


def test_the_user_guide_holds_no_dated_log():
    """Dated measurement logs live under docs/logs/, in the navigation's section of their own;
    the user guide's pages have no dated section."""
    import yaml

    nav = yaml.safe_load((ROOT / "mkdocs.yml").read_text())["nav"]
    guide = [page for item in nav for page in item.values() if isinstance(page, str)]
    logs = [page for item in nav for v in item.values() if isinstance(v, list) for page in v]
    assert guide and logs
    assert all(page.startswith("logs/") for entry in logs for page in entry.values())
    assert not any(page.startswith("logs/") for page in guide)
    for page in guide:
        dated = re.findall(r"^#+ .*\b20\d\d-\d\d-\d\d", (ROOT / "docs" / page).read_text(), re.M)
        assert not dated, (page, dated)
    on_disk = {f"logs/{p.name}" for p in (ROOT / "docs" / "logs").glob("*.md")}
    assert on_disk == {page for entry in logs for page in entry.values()}
