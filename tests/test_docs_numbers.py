"""The numbers the docs quote from runs equal docs/_static/numbers.json, made by the current
configuration (tools/docs_numbers.py; nothing is run here)."""

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def tool():
    spec = importlib.util.spec_from_file_location(
        "docs_numbers", ROOT / "tools" / "docs_numbers.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def numbers(tool):
    return tool.load_numbers()


def test_every_marked_number_and_block_is_the_runs(tool, numbers):
    problems = tool.differences(numbers)
    assert not problems, "run `python tools/docs_numbers.py apply`:\n" + "\n".join(problems)


def test_the_numbers_were_made_by_the_current_configuration(tool, numbers):
    """The default scene, the shipped scenes and sample, and the jobs hash as when the
    numbers were made; the file names the machine that made them (its timings' machine)."""
    assert numbers["schema"] == tool.SCHEMA
    assert numbers["config_hash"] == tool.config_hash(), (
        "the configuration changed since docs/_static/numbers.json was made: run "
        "`python tools/docs_numbers.py run` then `apply`"
    )
    assert numbers["machine"]["cpu"] and numbers["machine"]["cores"] >= 1
    assert numbers["versions"]["rimcl"]
    for job in numbers["jobs"].values():
        assert not job.get("reused") and job["wall_s"] >= 0 and "load_before" in job


def test_the_pages_quote_full_size_runs(numbers):
    """A smoke run (--small) never reaches the pages."""
    assert all(job["scale"] == "full" for job in numbers["jobs"].values())


@pytest.mark.parametrize(
    ("value", "kw", "text"),
    [
        (0.00013, {"scale": 100}, "0.013"),
        (0.0062, {"scale": 100}, "0.62"),
        (3.70, {"scale": 100}, "370"),
        (0.137, {"scale": 100, "digits": 3}, "13.7"),
        (3.8e-7, {}, "3.8e-7"),
        (9.96e-8, {}, "1.0e-7"),
        (248, {"decimals": 0}, "248"),
        (None, {}, "n/a"),
        (float("nan"), {}, "n/a"),
        (0.0, {}, "0"),
        (75.4, {}, "75"),
        (0.0026, {}, "0.0026"),
        (7.3e-6, {"scale": 100}, "0.00073"),
        (7.3e-5, {}, "7.3e-5"),
        (0.0026, {"sci": True}, "2.6e-3"),
    ],
)
def test_numbers_are_written_as_the_pages_write_them(tool, value, kw, text):
    assert tool.fmt(value, **kw) == text


def test_apply_rewrites_marked_numbers_and_blocks_only(tool):
    document = {
        "numbers": {"a.b": {"text": "0.62"}, "c": {"text": "n/a"}},
        "blocks": {"out": "new line\n"},
    }
    page = (
        "x 1.5<!--n:a.b--> %, y 7<!--n:c-->, z 3 unmarked\n"
        "<!--block:out-->\n```text\nold line\n```\n"
    )
    done = tool.render(page, document)
    assert done == (
        "x 0.62<!--n:a.b--> %, y n/a<!--n:c-->, z 3 unmarked\n"
        "<!--block:out-->\n```text\nnew line\n```\n"
    )
    assert tool.render(done, document) == done


def test_dig_reads_cases_by_name_and_tolerates_missing_keys(tool):
    cases = '[{"name": "C0", "v": {"ci95": [1, 2]}}, {"name": "C4"}, {"name": "dT=0.3", "v": 3}]'
    stats = json.loads(f'{{"cases": {cases}}}')
    assert tool.dig(stats, "cases[C0].v.ci95.1") == 2
    assert tool.dig(stats, "cases[dT=0.3].v") == 3
    assert tool.dig(stats, "cases[C4].v.ci95.1") is None
    assert tool.dig(stats, "cases[C9].v") is None
