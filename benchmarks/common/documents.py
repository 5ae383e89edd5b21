"""Results documents: what a benchmark publishes, as JSON, and its Markdown page.

A benchmark that publishes a table builds a document with :func:`make_document` and writes it
with :func:`write_page` as a pair ``<stem>.json`` + ``<stem>.md`` (``docs/results/``). The
JSON holds every figure; the Markdown page is :func:`render_markdown` of the JSON and nothing
else, so ``tests/test_results_pages.py`` renders every page again and compares text. A
document is a mapping:

* ``schema``: :data:`SCHEMA`;
* ``title``: the page's ``# `` heading; ``intro``: Markdown under it ("" for none);
* ``command``: the exact command, run from the repository root, that wrote the pair;
* ``sweeps``: the sweep files (``sweeps/*.yaml``) whose trials the tables report, ``[]``
  where none (the page's tests check that each one's trials are the table's runs);
* ``generated_by``: the script (a path in the repository);
* ``rehabbot_version``, ``machine`` (a description, for timings; else ``None``), ``seeds``
  (the seeds the figures come from, free-form JSON), ``settings`` (the run's other options);
* ``tables``: each ``{"id", "caption", "columns", "rows", ...}`` with optional ``align``
  (per column: left, right, center), ``digits`` (decimals of float cells), ``section`` (a
  ``## `` heading that groups this and the following tables of the same section; the
  captions then become ``### `` headings) and ``note`` (Markdown under the table);
* ``notes``: Markdown paragraphs after the tables; ``provenance``: where the data came from,
  as text (paths outside the repository included), or ``None``;
* ``figures``: optional, each ``{"id", "caption", "file", "alt", "sha256"}`` with optional
  ``after`` (the id of the table the figure follows; without it the figure comes before the
  tables), ``section`` and ``note`` (as a table's). ``file`` is the image's path relative to
  the page's folder (``figures/<page>/<name>.png``, :mod:`benchmarks.common.figures`), and
  ``sha256`` the digest (:func:`payload_sha256`) of the data the figure was drawn from: the
  script that made the page computes that data again from the JSON, and the image carries
  the same digest in its metadata, so a figure that no longer shows its JSON is found
  without comparing pixels;
* ``data``: optional raw data the tables are derived from (not rendered).
"""

from __future__ import annotations

import hashlib
import json
import re
import shlex
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from rehabbot.common.text_tables import Align, Cell, markdown_table, text_table

SCHEMA = "rehabbot-results/1"
ROOT = Path(__file__).resolve().parents[2]
REQUIRED = ("schema", "title", "intro", "command", "sweeps", "generated_by", "rehabbot_version",
            "machine", "seeds", "settings", "tables", "notes", "provenance")
FIGURE_REQUIRED = ("id", "caption", "file", "alt", "sha256")
HEADLINE_START = "<!-- headline-results: start -->"
HEADLINE_END = "<!-- headline-results: end -->"

__all__ = ["HEADLINE_END", "HEADLINE_START", "ROOT", "SCHEMA", "block_between", "command_line",
           "load_document", "make_document", "make_figure", "make_table", "payload_sha256",
           "render_markdown", "replace_block", "repo_path", "table_markdown", "table_text",
           "write_page"]


def repo_path(path: str | Path) -> str:
    """``path`` relative to the repository root (POSIX separators) where it lies inside it,
    else as given."""
    resolved = Path(path).resolve()
    try:
        return resolved.relative_to(ROOT).as_posix()
    except ValueError:
        return str(path)


def command_line(script: str | Path, argv: Sequence[str]) -> str:
    """The command that ran ``script`` with ``argv``, as a reader types it from the repository
    root: ``python benchmarks/<kind>/<name>.py ARGS`` (arguments quoted for a shell)."""
    return shlex.join(["python", repo_path(script), *map(str, argv)])


def make_table(table_id: str, caption: str, columns: Sequence[str],
               rows: Sequence[Sequence[Cell]], *, align: Sequence[Align] | None = None,
               digits: int | None = None, section: str | None = None,
               note: str | None = None) -> dict[str, Any]:
    """One table of a document (see the module's docstring)."""
    table: dict[str, Any] = {"id": table_id, "caption": caption, "columns": list(columns),
                             "rows": [list(row) for row in rows]}
    for key, value in (("align", None if align is None else list(align)), ("digits", digits),
                       ("section", section), ("note", note)):
        if value is not None:
            table[key] = value
    return table


def payload_sha256(payload: Any) -> str:
    """SHA-256 (hex) of ``payload`` as canonical JSON (sorted keys, no spaces, ASCII): the
    same data gives the same digest on every machine."""
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"), ensure_ascii=True,
                      allow_nan=False)
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def make_figure(figure_id: str, caption: str, file: str, alt: str, payload: Any, *,
                after: str | None = None, section: str | None = None,
                note: str | None = None) -> dict[str, Any]:
    """One figure of a document (see the module's docstring), recording the digest of
    ``payload``, the data it is drawn from."""
    figure: dict[str, Any] = {"id": figure_id, "caption": caption, "file": file, "alt": alt,
                              "sha256": payload_sha256(payload)}
    for key, value in (("after", after), ("section", section), ("note", note)):
        if value is not None:
            figure[key] = value
    return figure


def make_document(*, title: str, command: str, generated_by: str | Path,
                  tables: Sequence[Mapping[str, Any]], intro: str = "",
                  sweeps: Sequence[str | Path] = (), machine: str | None = None,
                  seeds: Any = None, settings: Mapping[str, Any] | None = None,
                  notes: Sequence[str] = (), provenance: str | None = None,
                  data: Any = None,
                  figures: Sequence[Mapping[str, Any]] = ()) -> dict[str, Any]:
    """A results document (see the module's docstring); ``generated_by`` and ``sweeps`` are
    recorded relative to the repository root."""
    import rehabbot

    document: dict[str, Any] = {
        "schema": SCHEMA, "title": title, "intro": intro.strip(), "command": command,
        "sweeps": [repo_path(path) for path in sweeps], "generated_by": repo_path(generated_by),
        "rehabbot_version": rehabbot.__version__, "machine": machine, "seeds": seeds,
        "settings": dict(settings or {}), "tables": [dict(table) for table in tables],
        "notes": [note.strip() for note in notes], "provenance": provenance}
    if figures:
        document["figures"] = [dict(figure) for figure in figures]
    if data is not None:
        document["data"] = data
    check_document(document)
    return document


def check_document(document: Mapping[str, Any]) -> None:
    """Raise :class:`ValueError` naming what a document lacks or holds wrongly."""
    missing = [key for key in REQUIRED if key not in document]
    if missing:
        raise ValueError(f"results document lacks {', '.join(missing)}")
    if document["schema"] != SCHEMA:
        raise ValueError(f"results document schema {document['schema']!r} is not {SCHEMA!r}")
    if not isinstance(document["sweeps"], list):
        raise ValueError(f"sweeps must be a list of paths, not {document['sweeps']!r}")
    ids = [table["id"] for table in document["tables"]]
    if len(set(ids)) != len(ids):
        raise ValueError(f"table ids repeat: {ids}")
    for table in document["tables"]:
        table_markdown(table)
    check_figures(document.get("figures", []), ids)


def check_figures(figures: Sequence[Mapping[str, Any]], table_ids: Sequence[str]) -> None:
    """Raise :class:`ValueError` naming a figure that lacks a key, repeats an id, follows no
    table of the document, or names a file outside the page's folder."""
    if not isinstance(figures, list):
        raise ValueError(f"figures must be a list, not {figures!r}")
    seen: set[str] = set()
    for figure in figures:
        missing = [key for key in FIGURE_REQUIRED if key not in figure]
        if missing:
            raise ValueError(f"figure {figure.get('id')!r} lacks {', '.join(missing)}")
        if figure["id"] in seen:
            raise ValueError(f"figure id {figure['id']!r} repeats")
        seen.add(figure["id"])
        if figure.get("after") is not None and figure["after"] not in table_ids:
            raise ValueError(f"figure {figure['id']!r} follows table {figure['after']!r}, "
                             f"which the document lacks")
        if any(mark in str(figure["alt"]) for mark in "[]\n"):
            raise ValueError(f"figure {figure['id']!r}: alt text {figure['alt']!r} cannot "
                             f"hold brackets or a newline")
        file = str(figure["file"])
        if file.startswith("/") or "\\" in file or ".." in file.split("/"):
            raise ValueError(f"figure {figure['id']!r}: file {file!r} must be a relative "
                             f"POSIX path inside the page's folder")


def _blocks(document: Mapping[str, Any]) -> list[tuple[str, Mapping[str, Any]]]:
    """The tables and figures in page order: figures without ``after`` first, then each table
    followed by the figures that name it."""
    figures = document.get("figures", [])
    blocks = [("figure", f) for f in figures if f.get("after") is None]
    for table in document["tables"]:
        blocks.append(("table", table))
        blocks += [("figure", f) for f in figures if f.get("after") == table["id"]]
    return blocks


def table_markdown(table: Mapping[str, Any]) -> str:
    """One table of a document as Markdown (:func:`rehabbot.common.text_tables.markdown_table`)."""
    return markdown_table(table["columns"], table["rows"], align=table.get("align"),
                          digits=table.get("digits"))


def table_text(table: Mapping[str, Any]) -> str:
    """One table of a document as aligned text for a terminal, under its caption."""
    return f"{table['caption']}\n" + text_table(table["columns"], table["rows"],
                                                align=table.get("align"),
                                                digits=table.get("digits"))


def _comment(text: str) -> str:
    """One comment line (Markdown ends a comment at the first ``-->`` only, so a command's
    ``--flags`` stay as they are)."""
    if "-->" in text or "\n" in text:
        raise ValueError(f"a page's comment line cannot hold '-->' or a newline: {text!r}")
    return f"<!-- {text} -->"


def render_markdown(document: Mapping[str, Any]) -> str:
    """The Markdown page of ``document`` (MyST-compatible): three comment lines naming the
    command, the sweep files and the JSON it is rendered from, the ``# `` title, the intro,
    every table and figure under its caption, the notes, and how the page was made."""
    check_document(document)
    sweeps = " ".join(document["sweeps"]) or "none"
    lines = [_comment(f"generated by: {document['command']}"),
             _comment(f"sweep files: {sweeps}"),
             _comment("rendered from the JSON file of the same name by "
                      "benchmarks/common/documents.py: do not edit by hand"),
             f"# {document['title']}", ""]
    if document["intro"]:
        lines += [document["intro"], ""]
    section = None
    for kind, block in _blocks(document):
        if block.get("section") != section:
            section = block.get("section")
            if section is not None:
                lines += [f"## {section}", ""]
        level = "###" if section is not None else "##"
        body = (table_markdown(block) if kind == "table"
                else f"![{block['alt']}]({block['file']})")
        lines += [f"{level} {block['caption']}", "", body, ""]
        if block.get("note"):
            lines += [block["note"], ""]
    for note in document["notes"]:
        lines += [note, ""]
    lines += ["## How this page was made", "",
              f"- Command (from the repository root): `{document['command']}`",
              f"- Script: `{document['generated_by']}`",
              "- Sweep files: " + (", ".join(f"`{path}`" for path in document["sweeps"])
                                   or "none"),
              f"- rehabbot {document['rehabbot_version']}"]
    if document["machine"]:
        lines.append(f"- Machine: {document['machine']}")
    if document["seeds"] is not None:
        lines.append(f"- Seeds: `{json.dumps(document['seeds'], sort_keys=True)}`")
    if document["settings"]:
        lines.append(f"- Settings: `{json.dumps(document['settings'], sort_keys=True)}`")
    if document["provenance"]:
        lines.append(f"- Provenance: {document['provenance']}")
    return "\n".join(lines) + "\n"


def load_document(path: str | Path) -> dict[str, Any]:
    """A document from its JSON file, checked."""
    document = json.loads(Path(path).read_text(encoding="utf-8"))
    check_document(document)
    return document


# An array that holds no array and no object: its line breaks are layout only (a JSON string
# never holds a raw line break), so they can go without changing the document.
_FLAT_ARRAY = re.compile(r"\[[^\[\]{}]*\]")


def document_json(document: Mapping[str, Any]) -> str:
    """The document as JSON text: indented, with each array of plain values on one line (a
    page's data holds long lists of numbers)."""
    text = json.dumps(document, indent=1)
    return _FLAT_ARRAY.sub(lambda m: re.sub(r"\n *", "", m.group(0)), text)


def write_page(document: Mapping[str, Any], stem: str | Path) -> tuple[Path, Path]:
    """Write ``<stem>.json`` (the document) and ``<stem>.md`` (its page); return both paths."""
    stem = Path(stem)
    if stem.suffix in (".json", ".md"):
        stem = stem.with_suffix("")
    stem.parent.mkdir(parents=True, exist_ok=True)
    json_path, md_path = stem.with_suffix(".json"), stem.with_suffix(".md")
    json_path.write_text(document_json(document) + "\n", encoding="utf-8")
    md_path.write_text(render_markdown(document), encoding="utf-8")
    return json_path, md_path


def replace_block(text: str, block: str, start: str = HEADLINE_START,
                  end: str = HEADLINE_END) -> str:
    """``text`` with the lines between the marker lines ``start`` and ``end`` replaced by
    ``block``. Raises :class:`ValueError` when the markers are missing or out of order."""
    lines = text.split("\n")
    try:
        first = lines.index(start)
        last = lines.index(end, first + 1)
    except ValueError:
        raise ValueError(f"the text lacks the lines {start!r} ... {end!r}") from None
    return "\n".join([*lines[:first + 1], *block.rstrip("\n").split("\n"), *lines[last:]])


def block_between(text: str, start: str = HEADLINE_START,
                  end: str = HEADLINE_END) -> str | None:
    """The lines between the marker lines ``start`` and ``end`` (``None`` without them)."""
    lines = text.split("\n")
    if start not in lines:
        return None
    first = lines.index(start)
    if end not in lines[first + 1:]:
        return None
    return "\n".join(lines[first + 1:lines.index(end, first + 1)])
