"""Pages generated from rimcl itself, so that the reference cannot drift from the code.

At the start of every build this writes, under ``docs/_generated/`` (not committed):

- ``scene-keys.md``: one table per scene section, from :data:`rimcl.scene.load.SCENE_KEYS`
  (the same table that ``rimcl study --print-default-scene`` prints), each key with the
  commands that use it (:func:`rimcl.scene.usage.users`);
- ``default-scene.toml``: that printed default scene, verbatim;
- ``public-api.md``: the names ``import rimcl`` offers (``rimcl.__all__``), each linked to
  the module that defines it.

The reference pages include these files. The functions are also used by
``tests/test_docs.py``.
"""

import re
from pathlib import Path

GENERATED = Path(__file__).resolve().parents[1] / "_generated"


def _cell(text):
    """Markdown table cell: pipes escaped, on one line."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _default(key):
    from rimcl.scene.load import _toml_value

    if key.default is None or key.default == {}:
        shown = "–" if key.default is None else "`{}`"
        return shown + (f" (e.g. `{_toml_value(key.example)}`)" if key.example is not None else "")
    return f"`{_toml_value(key.default)}`"


def scene_keys_markdown():
    """Markdown of every scene key, one table per section, in the printed scene's order.

    Returns
    -------
    str
    """
    from rimcl.scene.load import SCENE_KEYS, SECTIONS

    lines = []
    for section in SECTIONS:
        lines += [f"({_anchor(section)})=", f"## `[{section}]`", ""]
        lines += ["| key | default | meaning | used by |", "|---|---|---|---|"]
        for key in (k for k in SCENE_KEYS if k.section == section):
            meaning = key.doc
            if key.choices:
                meaning += " (one of: " + ", ".join(f"`{c}`" for c in key.choices) + ")"
            meaning += _limit(key)
            lines.append(
                f"| `{key.dotted}` | {_cell(_default(key))} | {_cell(meaning)} | {_used_by(key)} |"
            )
        lines.append("")
    return "\n".join(lines)


def _used_by(key):
    """The commands using a key (:func:`rimcl.scene.usage.users`), short, and the cameras."""
    from rimcl.scene.usage import CAMERA_KINDS, users

    short = {"study": "study", "render": "render", "piv": "piv", "trace": "trace", "lpt": "lpt"}
    tags = users(key)
    shown = "all" if len(tags) == len(short) else ", ".join(t for t in short if t in tags)
    kinds = CAMERA_KINDS.get(key.dotted)
    return shown + (f" ({', '.join(kinds)} camera)" if kinds else "")


def _limit(key):
    """The range the scene loader enforces on a number, where the meaning does not say it."""
    if ">=" in key.doc or "at least" in key.doc:
        return ""
    if key.minimum is not None:
        return f"; at least {key.minimum:g}"
    if key.positive:
        return "; positive"
    return ""


def _anchor(section):
    return f"scene-{section}"


def public_api_markdown():
    """Markdown table of ``rimcl.__all__``, each name linked to where it is defined.

    Returns
    -------
    str
    """
    import rimcl

    rows = []
    for name in rimcl.__all__:
        if name.startswith("__"):
            continue
        obj = getattr(rimcl, name)
        module = getattr(obj, "__module__", None)
        target = f"{module}.{name}" if module and module.startswith("rimcl") else None
        summary = ""
        doc = getattr(obj, "__doc__", None) if callable(obj) else None
        if doc:
            # the first line of a reST docstring, in MyST: roles and literals converted
            summary = re.sub(r":(\w+):`", r"{py:\1}`", doc.strip().splitlines()[0])
            summary = re.sub(r"``(.+?)``", r"`\1`", summary)
        link = f"{{py:obj}}`rimcl.{name} <{target}>`" if target else f"`rimcl.{name}`"
        rows.append(f"| {link} | {_cell(summary)} |")
    return "\n".join(["| name | what |", "|---|---|", *rows, ""])


def _write_if_changed(path, text):
    """Rewrite only on change, so that an unchanged build stays incremental."""
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


def write_generated(app=None):
    """Write the generated pages under ``docs/_generated``."""
    from rimcl.scene.load import default_scene_text

    GENERATED.mkdir(exist_ok=True)
    _write_if_changed(GENERATED / "scene-keys.md", scene_keys_markdown())
    _write_if_changed(GENERATED / "default-scene.toml", default_scene_text())
    _write_if_changed(GENERATED / "public-api.md", public_api_markdown())


# ``literal`` spans, which reST leaves alone, and everything between them
_LITERAL = re.compile(r"(``.+?``)")
# a word ending in "_" before a bar or punctuation: reST would read ``ε_`` as a link
_TRAILING_UNDERSCORE = re.compile(r"(?<=\w)_(?=\||[\s,.;:)]|$)")


def _plain(text):
    return _TRAILING_UNDERSCORE.sub(r"\\_", text).replace("|", "\\|")


def escape_bars(app, what, name, obj, options, lines):
    """Escape ``|`` (and a word's trailing ``_`` before it) in docstrings outside literals.

    Docstrings write magnitudes as ``|x|`` and ``ε_|u|`` in plain text (they are read in
    ``help()`` too); reST would take ``|x|`` for a substitution and ``ε_`` for a link, and
    fail. No docstring uses reST tables, line blocks or ``name_`` links, the other meanings.
    """
    for i, line in enumerate(lines):
        if "|" in line:
            parts = _LITERAL.split(line)
            parts[::2] = [_plain(part) for part in parts[::2]]
            lines[i] = "".join(parts)


def skip_foreign_members(app, what, name, obj, skip, options):
    """Leave out a module's members that another package defines.

    Sphinx 9's autodoc takes some compiled classes imported into a module (scipy's
    ``cKDTree`` in :mod:`rimcl.lpt.matching`) for the module's own members and then fails
    on their signatures; rimcl's pages document rimcl's objects only.
    """
    module = getattr(obj, "__module__", None)
    if what == "module" and isinstance(module, str) and module.split(".")[0] != "rimcl":
        return True
    return None


def setup(app):
    app.connect("autodoc-skip-member", skip_foreign_members)
    app.connect("builder-inited", write_generated)
    app.connect("autodoc-process-docstring", escape_bars, priority=400)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
