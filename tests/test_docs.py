"""The documentation cannot drift from the code: its tutorials run, every command, option,
scene key and figure it names exists, and its reference is generated from the code."""

import importlib
import re
import sys
from pathlib import Path

import click
import pytest
from doc_pages import (
    DOCS,
    PAGES,
    ROOT,
    TUTORIALS,
    code_blocks,
    documented_invocations,
    prepared_shell,
    run_page,
)

from rimcl.cli.main import COMMANDS, cli
from rimcl.scene.load import SCENE_KEYS, SECTIONS

sys.path.insert(0, str(DOCS / "_ext"))
import rimcl_docs

# what `rimcl` accepts before its command
ROOT_OPTIONS = {"-v", "--verbose", "--version", "-h", "--help"}


def _command(name):
    module, attribute, _ = COMMANDS[name]
    return getattr(importlib.import_module(module), attribute)


def _placeholder(word):
    return word.isupper() or "..." in word or "…" in word


@pytest.mark.slow
@pytest.mark.parametrize("page", TUTORIALS, ids=lambda p: p.stem)
def test_every_block_of_the_tutorial_runs(page, tmp_path):
    assert run_page(page, tmp_path) >= 1


def test_the_tutorials_are_the_four_of_the_site():
    assert [p.stem for p in TUTORIALS] == [
        "gpu-and-cluster",
        "piv-pairs",
        "water-tank",
        "your-dns",
    ]


def test_every_documented_command_and_option_exists():
    problems = []
    for where, words in documented_invocations():
        words = [w for w in words if w not in ROOT_OPTIONS]
        if not words or _placeholder(words[0]):
            continue
        if words[0] not in COMMANDS:
            problems.append(f"{where}: rimcl {words[0]} is not a command")
            continue
        command, name = _command(words[0]), words[0]
        rest = words[1:]
        if isinstance(command, click.Group):
            if not rest or _placeholder(rest[0]) or rest[0].startswith("-"):
                continue
            if rest[0] not in command.commands:
                problems.append(f"{where}: rimcl {name} {rest[0]} is not a command")
                continue
            name, command, rest = f"{name} {rest[0]}", command.commands[rest[0]], rest[1:]
        options = {opt for p in command.params for opt in [*p.opts, *p.secondary_opts]}
        options |= {"-h", "--help"}
        for word in rest:
            if not word.startswith("-"):
                continue
            for option in word.split("=", 1)[0].split("/"):  # "--window/--overlap"
                if len(option) > 1 and option not in options:
                    problems.append(f"{where}: rimcl {name} has no option {option}")
    assert problems == []


def test_every_scene_key_named_in_the_docs_exists():
    keys = {key.dotted for key in SCENE_KEYS}
    named = re.compile(rf"`({'|'.join(SECTIONS)})\.([a-z0-9_]+)")
    problems = []
    for page in PAGES:
        for section, name in named.findall(page.read_text(encoding="utf-8")):
            if f"{section}.{name}" not in keys:
                problems.append(f"{page.relative_to(ROOT)}: {section}.{name}")
    assert problems == []


def test_the_scene_reference_lists_every_key_once():
    text = rimcl_docs.scene_keys_markdown()
    listed = re.findall(r"^\| `([a-z_]+\.[a-z0-9_]+)` \|", text, flags=re.MULTILINE)
    assert sorted(listed) == sorted(key.dotted for key in SCENE_KEYS)
    assert len(listed) == len(set(listed))
    assert "{include} ../_generated/scene-keys.md" in (DOCS / "reference/scene.md").read_text()


def test_the_api_reference_lists_every_public_name():
    import rimcl

    text = rimcl_docs.public_api_markdown()
    listed = re.findall(r"^\| (?:\{py:obj\})?`rimcl\.(\w+)[ `]", text, flags=re.MULTILINE)
    assert sorted(listed) == sorted(n for n in rimcl.__all__ if not n.startswith("__"))
    api = (DOCS / "reference/api.md").read_text()
    # the module reference is discovered by walking the package, never a list of modules
    assert ":recursive:" in api and re.search(r"^   rimcl$", api, flags=re.MULTILINE)


def test_the_cli_reference_is_generated_from_every_command():
    page = (DOCS / "reference/cli.md").read_text()
    assert "```{click} rimcl.cli.main:cli\n:prog: rimcl\n:nested: full\n```" in page
    # sphinx-click walks the group as click does: every command must be reachable
    ctx = click.Context(cli)
    assert cli.list_commands(ctx) == list(COMMANDS)
    for name in COMMANDS:
        assert cli.get_command(ctx, name) is _command(name)


def test_the_figures_table_names_every_figure_a_study_writes():
    from rimcl.piv.figures import FIGURE_NAMES as PIV_FIGURES
    from rimcl.stats.figures import FIGURE_NAMES

    page = (DOCS / "reference/formats/study.md").read_text()
    table = page[page.index("## Figures") :]
    named = set(re.findall(r"^\| `([a-z_]+)` \|", table, flags=re.MULTILINE))
    assert named == {*FIGURE_NAMES, "dt_sweep", "numerics"}
    assert all(f"`{name}`" in table for name in PIV_FIGURES)


def test_no_page_cites_a_file_outside_the_repository():
    problems = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        # the design notes and the paper live beside the repository, not in it
        for cited in re.findall(r"DESIGN|/work/|(?<![/\w])shared/", text):
            problems.append(f"{page.relative_to(ROOT)}: {cited}")
        # relative links and images lead to files of the repository
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
            if "://" in target:
                continue
            if not (page.parent / target).resolve().is_file():
                problems.append(f"{page.relative_to(ROOT)}: link to {target}")
    assert problems == []


def test_append_directives_apply_to_their_command_only():
    block = code_blocks(DOCS / "tutorials/water-tank.md")[0]
    assert block.directives == ["append study --tracers 8 --no-figures"]
    assert prepared_shell(block) == (
        "rimcl study data_samples/scenes/water_tank.toml --out tank --tracers 30"
        " --tracers 8 --no-figures"
    )


def test_the_api_pages_cite_nothing_outside_the_repository():
    """Every docstring, as the API pages show it, is free of citations of the design notes."""
    import inspect
    import pkgutil

    import rimcl

    left = []
    for info in pkgutil.walk_packages(rimcl.__path__, "rimcl."):
        if info.name.endswith("__main__"):  # runs the command line
            continue
        module = importlib.import_module(info.name)
        objects = [module, *vars(module).values()]
        objects += [m for o in objects if inspect.isclass(o) for m in vars(o).values()]
        for obj in objects:
            if getattr(obj, "__module__", module.__name__) != module.__name__:
                continue
            lines = (inspect.getdoc(obj) or "").splitlines() if obj is not None else []
            left += [f"{info.name}: {line}" for line in lines if "DESIGN" in line]
    assert left == []


def test_the_code_cites_nothing_outside_the_repository():
    """Comments and kernels name the docs pages, never design notes outside the repository."""
    root = Path(__file__).resolve().parents[1]
    files = [
        *root.glob("rimcl/**/*.py"),
        *root.glob("cli/*.py"),
        *root.glob("cl/*"),
        *root.glob("benchmarks/*"),
        *root.glob("tools/*"),
    ]
    cited = [
        f"{path.relative_to(root)}:{number}"
        for path in files
        if path.is_file()
        for number, line in enumerate(path.read_text().splitlines(), 1)
        if "DESIGN §" in line
    ]
    assert files and cited == []


def _documented_columns(page, group):
    """Names in backticks in the datasets cell of ``group``'s row of a page's table."""
    row = re.search(rf"^\| `{group}`[^\n]*\| ([^\n]*) \|$", page, flags=re.MULTILINE)
    assert row, f"no table row for {group}"
    return set(re.findall(r"`([A-Za-z][A-Za-z0-9_]*)[` ]", row.group(1)))


def test_the_render_file_page_names_every_table_column_and_attribute(device, tmp_path):
    """A render file holds exactly the groups, columns and root attributes its page lists."""
    import h5py

    from rimcl.ptv.measure import run_render
    from rimcl.ptv.render_file import write_render
    from rimcl.scene.config import (
        CameraConfig,
        MeasureConfig,
        RunConfig,
        TimeConfig,
        TracerConfig,
    )

    config = MeasureConfig(
        camera=CameraConfig(kind="plane", fan=2),
        tracers=TracerConfig(count=2, seed=0),
        time=TimeConfig(frames=5),
        run=RunConfig(device=device, engine="numpy"),
    )
    path = write_render(tmp_path / "r.h5", run_render(None, case="C1", config=config))
    page = (DOCS / "reference/formats/render.md").read_text(encoding="utf-8")
    with h5py.File(path) as f:
        groups = set(f)
        for group in groups:
            columns = set(f[group])
            like = {"velocity_fit": "velocity", "acceleration_fit": "acceleration"}
            documented = _documented_columns(page, like.get(group, group))
            attrs = set(f[group].attrs)
            assert columns <= documented, f"{group}: undocumented {columns - documented}"
            # what the page lists for a group is there (or is one of its attributes)
            listed = documented - columns - attrs - groups
            if group in like.values():
                assert listed == set(), f"{group}: documented, not written: {listed}"
        root = set(f.attrs)
    documented_root = set(
        re.findall(r"`([A-Za-z][A-Za-z0-9_]*)[` ]", page[: page.index("| group |")])
    )
    assert root <= documented_root, f"undocumented root attributes {root - documented_root}"
    assert groups == {
        "tracers",
        "velocity",
        "acceleration",
        "velocity_fit",
        "acceleration_fit",
        "rays",
    }
