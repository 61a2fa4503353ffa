"""``.. zoo-table::`` -- the table of the built-in models, read from the zoo's TOML files.

Each row is one file of ``src/pwsdyn/model/zoo``: its name, kind (flow or map), states, its
``description`` and its ``source`` (or ``reference``), so the page cannot fall behind the zoo.
"""

from __future__ import annotations

import tomllib
from importlib import resources

from docutils import nodes
from sphinx.util.docutils import SphinxDirective


def _text(text: str) -> str:
    # TOML line continuations leave single spaces; keep the text as written (no RST parsing:
    # descriptions hold ``*``, ``_`` and ``|`` as mathematics)
    return " ".join(str(text).split()) or "--"


def _row(cells) -> nodes.row:
    row = nodes.row()
    for cell in cells:
        entry = nodes.entry()
        entry += cell if isinstance(cell, nodes.Node) else nodes.paragraph(text=cell)
        row += entry
    return row


def _literals(names) -> nodes.paragraph:
    para = nodes.paragraph()
    for i, name in enumerate(names):
        if i:
            para += nodes.Text(", ")
        para += nodes.literal(text=name)
    return para


class ZooTable(SphinxDirective):
    has_content = False

    def run(self):
        zoo = resources.files("pwsdyn.model") / "zoo"
        widths = (14, 6, 12, 38, 30)
        table = nodes.table(classes=["zoo-table"])
        group = nodes.tgroup(cols=len(widths))
        table += group
        for w in widths:
            group += nodes.colspec(colwidth=w)
        head = nodes.thead()
        head += _row(["name", "kind", "states", "description", "source"])
        group += head
        body = nodes.tbody()
        for entry in sorted(zoo.iterdir(), key=lambda p: p.name):
            if not entry.name.endswith(".toml"):
                continue
            self.env.note_dependency(str(entry))
            data = tomllib.loads(entry.read_text(encoding="utf-8"))
            body += _row([_literals([data["name"]]),
                          "map" if data.get("kind") == "map" else "flow",
                          _literals(data.get("states", [])),
                          _text(data.get("description", "")),
                          _text(data.get("source", data.get("reference", "")))])
        group += body
        return [table]


def setup(app):
    app.add_directive("zoo-table", ZooTable)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
