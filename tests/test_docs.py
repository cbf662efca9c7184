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
