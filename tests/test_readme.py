"""The README is a landing page that works as written: at most 250 lines, the set-up commands
that CI runs, a quick start that runs, and links into the documentation."""

import re

import pytest
from doc_pages import README, ROOT, code_blocks, run_page


def _ci_lines():
    """The commands of .ci/run, without comments and shell settings."""
    lines = (ROOT / ".ci/run").read_text(encoding="utf-8").splitlines()
    return [line for line in lines if line and not line.startswith(("#", "set ", "cd ", "export "))]


def test_the_readme_is_a_landing_page():
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 250


def test_the_readme_test_command_is_the_one_ci_runs():
    blocks = [b.text for b in code_blocks(README) if b.lang == "bash"]
    test_command = next(line for line in _ci_lines() if line.endswith("&& pytest"))
    assert test_command in blocks
    # the main job: the same set-up with the runtime extra, then the default study
    main_job = test_command.replace('".[pocl,test]"', '".[pocl]"').replace(
        "&& pytest", "&& rimcl study --out study-out"
    )
    assert main_job in blocks


def test_the_docs_build_command_is_the_one_ci_runs():
    build = next(line for line in _ci_lines() if "sphinx-build" in line)
    assert build == (
        'pip install -e ".[docs]" && sphinx-build -W --keep-going -b html docs docs/_build/html'
    )
    for page in (README, ROOT / "docs/install.md", ROOT / "docs/README.md"):
        assert build in page.read_text(encoding="utf-8"), page


def test_the_readme_links_every_tutorial_and_how_to():
    text = README.read_text(encoding="utf-8")
    linked = set(re.findall(r"\]\((docs/[^)]+\.md)\)", text))
    for folder in ("tutorials", "howto"):
        for page in (ROOT / "docs" / folder).glob("*.md"):
            assert str(page.relative_to(ROOT)) in linked


@pytest.mark.slow
def test_the_quick_start_runs(tmp_path):
    assert run_page(README, tmp_path) >= 2
