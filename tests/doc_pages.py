"""Reading the README and the documentation pages for the tests that keep them true.

A page's fenced code blocks are run in page order in a scratch directory. An HTML comment on
the line before a block adjusts it (``docs/README.md`` describes the rules):

- ``<!-- test: skip REASON -->``: not run;
- ``<!-- test: append CMD OPTIONS -->``: OPTIONS appended to every line of the block that
  starts with ``rimcl CMD`` (smaller sizes than a reader would use).
"""

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = ROOT / "README.md"
TUTORIALS = sorted((DOCS / "tutorials").glob("*.md"))
# every Markdown page a reader sees: the README and the site's sources (not build output)
PAGES = [README, *sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts)]

_FENCE = re.compile(r"^(`{3,})\s*([^\s`]*)")
_DIRECTIVE = re.compile(r"^<!--\s*test:\s*(.*?)\s*-->\s*$")


@dataclass
class Block:
    """One fenced code block of a page."""

    path: Path
    line: int  # 1-based line of the opening fence
    lang: str
    text: str
    directives: list = field(default_factory=list)

    @property
    def skipped(self):
        return any(d.startswith("skip") for d in self.directives)

    def where(self):
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def code_blocks(path):
    """Every fenced block of a Markdown page, with the test directives just before it."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    blocks, i = [], 0
    while i < len(lines):
        match = _FENCE.match(lines[i])
        if not match:
            i += 1
            continue
        fence, lang = match.groups()
        directives, j = [], i - 1
        while j >= 0 and _DIRECTIVE.match(lines[j]):
            directives.insert(0, _DIRECTIVE.match(lines[j]).group(1))
            j -= 1
        end = i + 1
        while end < len(lines) and lines[end].strip() != fence:
            end += 1
        blocks.append(Block(Path(path), i + 1, lang, "\n".join(lines[i + 1 : end]), directives))
        i = end + 1
    return blocks


def logical_lines(text):
    """Shell lines with backslash continuations joined."""
    return text.replace("\\\n", " ").splitlines()


def prepared_shell(block):
    """The block's shell text with its ``append`` directives applied."""
    lines = logical_lines(block.text)
    for directive in block.directives:
        if not directive.startswith("append "):
            continue
        words = directive.split()[1:]
        # the command is the leading words that are not options: "study", "piv render"
        n_cmd = next(k for k, w in enumerate(words) if w.startswith("-"))
        command, options = " ".join(words[:n_cmd]), " ".join(words[n_cmd:])
        for k, line in enumerate(lines):
            if re.match(rf"\s*rimcl {re.escape(command)}\b", line):
                code, hash_, comment = line.partition(" #")
                lines[k] = f"{code.rstrip()} {options}" + (f"  #{comment}" if hash_ else "")
    return "\n".join(lines)


def run_page(path, workdir, timeout=900):
    """Run every bash and python block of a page in order, in ``workdir``."""
    workdir = Path(workdir)
    (workdir / "data_samples").symlink_to(ROOT / "data_samples")
    env = dict(os.environ)
    # the rimcl command of this interpreter's environment, as after `. .venv/bin/activate`
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env["MPLBACKEND"] = "Agg"
    ran = 0
    for block in code_blocks(path):
        if block.lang not in ("bash", "python") or block.skipped:
            continue
        if block.lang == "bash":
            argv = ["bash", "-euo", "pipefail", "-c", prepared_shell(block)]
        else:
            script = workdir / f".block-{block.line}.py"
            script.write_text(block.text, encoding="utf-8")
            argv = [sys.executable, str(script)]
        done = subprocess.run(
            argv, cwd=workdir, env=env, capture_output=True, text=True, timeout=timeout
        )
        assert done.returncode == 0, (
            f"{block.where()} failed ({done.returncode}):\n{done.stdout[-3000:]}\n"
            f"{done.stderr[-3000:]}"
        )
        ran += 1
    return ran


_RIMCL = re.compile(r"(?:^|[\s;&|(=$])rimcl\s+(.*)$")


def documented_invocations():
    """``(where, words)`` of every ``rimcl ...`` written in a page: code blocks and inline code.

    ``words`` are the shell words after ``rimcl`` up to the end of the command (a pipe,
    ``&&``, ``;``, a redirection or a comment).
    """
    found = []

    def collect(where, line):
        match = _RIMCL.search(line)
        if not match:
            return
        try:
            words = shlex.split(match.group(1), comments=True)
        except ValueError:  # an unbalanced quote in prose: take the plain words
            words = match.group(1).split()
        command = []
        for word in words:
            if word in ("|", "||", "&&", ";", "&") or word.startswith((">", "<", "2>")):
                break
            command.append(word)
        found.append((where, command))

    for page in PAGES:
        for block in code_blocks(page):
            if block.lang in ("bash", "sh", "console", "text", ""):
                for line in logical_lines(block.text):
                    collect(block.where(), line.removeprefix("$ "))
        text = page.read_text(encoding="utf-8")
        prose = re.sub(r"^(`{3,}).*?^\1\s*$", "", text, flags=re.MULTILINE | re.DOTALL)
        for span in re.findall(r"`(rimcl [^`]+)`", prose):
            collect(str(page.relative_to(ROOT)), span)
    return found
