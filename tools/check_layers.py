"""Checks that rimcl's stage subpackages import only downward, that no two modules import
each other (directly or around a loop), and that no module is too long.

The stages, lowest first, are listed in :data:`STAGES`; a module may import from its own
stage or a lower one, never a higher one (function-level imports included). Run from the
repository root: ``python tools/check_layers.py``; exits 1 and names each offence.
"""

import ast
import sys
from pathlib import Path

#: Stage subpackages of ``rimcl``, lowest first: the pipeline a newcomer reads.
STAGES = ("core", "fields", "optics", "imaging", "scene", "ptv", "stats", "piv", "lpt", "study")
#: Longest module, in lines, that is still short enough to read.
MAX_LINES = 800


def stage_of(module):
    """Stage index of a dotted ``rimcl`` module name, or None for the package root."""
    parts = module.split(".")
    if len(parts) < 2 or parts[0] != "rimcl" or parts[1] not in STAGES:
        return None
    return STAGES.index(parts[1])


def imported_modules(path):
    """Dotted names of the rimcl modules that ``path`` imports, anywhere in the file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.module


def import_cycles(root):
    """Loops of rimcl modules that import each other (function-level imports included)."""
    package = root / "rimcl"
    graph = {}
    for path in sorted(package.rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        graph[module] = set()
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                graph[module] |= {node.module, *(f"{node.module}.{a.name}" for a in node.names)}
            elif isinstance(node, ast.Import):
                graph[module] |= {alias.name for alias in node.names}
    graph = {m: sorted(t for t in targets if t in graph and t != m) for m, targets in graph.items()}
    state, loops = {}, []

    def visit(module, stack):
        state[module] = "open"
        stack.append(module)
        for target in graph[module]:
            if state.get(target) == "open":
                loops.append([*stack[stack.index(target) :], target])
            elif target not in state:
                visit(target, stack)
        stack.pop()
        state[module] = "done"

    for module in graph:
        if module not in state:
            visit(module, [])
    return loops


def offences(root):
    """Lines describing each upward import and each over-long module under ``root/rimcl``."""
    package = root / "rimcl"
    for path in sorted(package.rglob("*.py")):
        module = ".".join(path.relative_to(root).with_suffix("").parts)
        own = stage_of(module)
        lines = len(path.read_text().splitlines())
        if lines > MAX_LINES:
            yield f"{path.relative_to(root)}: {lines} lines (more than {MAX_LINES})"
        if own is None:
            continue
        for target in imported_modules(path):
            other = stage_of(target)
            if other is not None and other > own:
                yield (
                    f"{path.relative_to(root)}: imports {target} "
                    f"(stage {STAGES[other]} is above {STAGES[own]})"
                )


def main():
    root = Path(__file__).resolve().parents[1]
    found = list(offences(root))
    found += ["import cycle: " + " -> ".join(loop) for loop in import_cycles(root)]
    for line in found:
        print(line)
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
