"""The README documents what the code offers: every scene key (in the scene tables), every
figure, every command and every long option of every command."""

import importlib
import re
from pathlib import Path

import click

from rimcl.cli.main import COMMANDS
from rimcl.scene.keys import SCENE_KEYS
from rimcl.stats.figures import FIGURE_NAMES

README = Path(__file__).resolve().parents[1] / "README.md"


def _readme():
    return README.read_text(encoding="utf-8")


def _section(text, heading):
    """The text of a section, from its heading to the next heading of its level or above."""
    level = len(heading) - len(heading.lstrip("#"))
    start = text.index(f"\n{heading}\n")
    stop = re.search(rf"\n#{{1,{level}}} ", text[start + len(heading) + 2 :])
    return text[start : start + len(heading) + 2 + (stop.start() if stop else len(text))]


def _leaf_commands():
    """``(name, click command)`` of every command and sub-command of ``rimcl``."""
    found = []
    for name, (module, attribute, _) in COMMANDS.items():
        command = getattr(importlib.import_module(module), attribute)
        if isinstance(command, click.Group):
            found += [(f"{name} {sub}", command.commands[sub]) for sub in command.commands]
        else:
            found.append((name, command))
    return found


def test_the_scene_tables_list_every_scene_key_once():
    tables = _section(_readme(), "### Scene files")
    listed = re.findall(r"^\| `([a-z_]+\.[a-z0-9_]+)` \|", tables, flags=re.MULTILINE)
    expected = {key.dotted for key in SCENE_KEYS}
    assert sorted(set(listed) - expected) == [], "README lists keys the scene does not have"
    assert sorted(expected - set(listed)) == [], "scene keys missing from the README tables"
    assert len(listed) == len(set(listed)), "a scene key is listed twice"


def test_the_figures_table_names_every_figure():
    table = _section(_readme(), "### Figures")
    named = set(re.findall(r"^\| `([a-z_]+)` \|", table, flags=re.MULTILINE))
    assert named == {*FIGURE_NAMES, "dt_sweep"}


def test_every_command_and_long_option_is_documented():
    text = _readme()
    missing = []
    for name, command in _leaf_commands():
        if f"rimcl {name}" not in text:
            missing.append(f"rimcl {name}")
        for parameter in command.params:
            missing += [
                f"rimcl {name} {option}"
                for option in getattr(parameter, "opts", [])
                if option.startswith("--") and option not in text
            ]
    assert missing == []
