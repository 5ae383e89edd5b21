"""The browser check of the built docs (docs/_ext/site_check.py, ``make docs-check``) finds what
a reader would see broken, and only that: each test opens small pages in headless Chromium,
one with a defect, one without.

It needs Debian's chromium and chromium-driver and the selenium package (``.ci/run`` installs
them; the ``docs`` extra has selenium). Without them the tests skip, except in CI (``CI`` set),
where a missing browser fails them: the check must never be skipped silently there.
"""

from __future__ import annotations

import base64
import os
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))

import site_check  # noqa: E402  (docs/_ext)

# A 1 x 1 PNG, so that a page can show an image that loads.
PIXEL_PNG = base64.b64decode(
    "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8BQDwAEhQGAhKmMIQAAAABJRU5Erk"
    "Jggg==")


@pytest.fixture(scope="module")
def browser() -> Iterator[site_check.Browser]:
    missing = site_check.browser_missing()
    if missing:
        if os.environ.get("CI"):
            pytest.fail(f"the docs' browser check cannot run in CI: {missing}")
        pytest.skip(f"no browser for the docs' check: {missing}")
    with site_check.Browser() as opened:
        yield opened


def findings(browser: site_check.Browser, tmp_path: Path, body: str) -> list[tuple[str, str]]:
    """(kind, detail) of each finding on a page with Furo's content column (736 px) around
    ``body``."""
    (tmp_path / "pixel.png").write_bytes(PIXEL_PNG)
    page = tmp_path / "page.html"
    page.write_text(
        "<!doctype html><html><head><meta charset='utf-8'><style>"
        "body{margin:0;font:16px sans-serif} article{width:736px;margin-left:300px}"
        "pre{overflow:auto}</style></head><body><article role='main'><h1>A page</h1>"
        f"{body}</article></body></html>", encoding="utf-8")
    return [(f.kind, f.detail) for f in browser.check(page, "page.html")]


WIDE_TABLE = ("<table><tr>" + "".join(f"<td>column_{k}_with_a_long_name</td>" for k in range(12))
              + "</tr></table>")
LONG_LINE = "x = " + "1 + " * 150 + "1"


def test_a_markdown_table_shown_as_a_paragraph_is_found(browser, tmp_path):
    # As MyST-NB's CommonMark output showed the clinical table: the dashes made em dashes.
    text = ("<p>| metric | expert | gentle | | \u2014\u2014\u2014 | \u2014\u2014 | \u2014\u2014 | "
            "| return | 180 \u00b1 4 | 168 \u00b1 3 |</p>")
    assert [kind for kind, _ in findings(browser, tmp_path, text)] == ["table as text"]
    plain = "<p>| metric | --- | --- |</p>"
    assert [kind for kind, _ in findings(browser, tmp_path, plain)] == ["table as text"]


def test_a_real_table_and_a_norm_are_not_tables_as_text(browser, tmp_path):
    body = ("<table><tr><th>metric</th><th>expert</th></tr><tr><td>return</td><td>\u2014</td>"
            "</tr></table><p>Eq. (5) pays -||theta - theta*||, ||a|| and |b| are norms.</p>"
            "<pre>| a | b |\n|---|---|</pre>")
    assert findings(browser, tmp_path, body) == []


def test_a_figure_shown_as_its_repr_is_found(browser, tmp_path):
    body = ("<div class='cell_output'><div class='output text_plain'><pre>"
            "&lt;Figure size 800x780 with 3 Axes&gt;</pre></div></div>"
            "<div class='cell_output'><pre>&lt;rehabbot.Thing object at 0x7f3a2b&gt;</pre></div>")
    assert findings(browser, tmp_path, body) == [
        ("repr shown", "<Figure size 800x780 with 3 Axes>"),
        ("repr shown", "<rehabbot.Thing object at 0x7f3a2b>")]


def test_a_repr_quoted_in_the_prose_is_not_a_lost_figure(browser, tmp_path):
    body = ("<p>A figure prints as <code>&lt;Figure size 8x6 with 1 Axes&gt;</code>.</p>"
            "<table><tr><td><code>&lt;Figure size 8x6 with 1 Axes&gt;</code></td></tr></table>")
    assert findings(browser, tmp_path, body) == []


def test_a_table_wider_than_the_column_is_found_unless_it_scrolls_in_its_box(browser, tmp_path):
    found = findings(browser, tmp_path, WIDE_TABLE)
    assert [kind for kind, _ in found] == ["overflow"]
    assert "wider than the content column" in found[0][1]
    scrolling = f"<div style='overflow-x:auto'>{WIDE_TABLE}</div>"
    assert findings(browser, tmp_path, scrolling) == []


def test_a_scrolling_box_that_itself_sticks_out_of_the_column_is_found(browser, tmp_path):
    # Furo's table wrapper before docs/_static/rehabbot.css: width 100 % plus its padding.
    body = f"<div style='overflow-x:auto;width:100%;padding:0 .2rem'>{WIDE_TABLE}</div>"
    found = findings(browser, tmp_path, body)
    assert [kind for kind, _ in found] == ["overflow"]
    assert "scrolling box ends" in found[0][1]


def test_code_clipped_with_no_scroll_bar_is_found(browser, tmp_path):
    body = f"<pre style='overflow:hidden'>{LONG_LINE}</pre>"
    found = findings(browser, tmp_path, body)
    assert [kind for kind, _ in found] == ["cut off"]
    clipped_by_parent = (f"<div style='overflow:hidden'><pre style='overflow:visible'>"
                         f"{LONG_LINE}</pre></div>")
    assert [kind for kind, _ in findings(browser, tmp_path, clipped_by_parent)] == ["cut off"]
    spilling = f"<pre style='overflow:visible'>{LONG_LINE}</pre>"
    assert [kind for kind, _ in findings(browser, tmp_path, spilling)] == ["overflow"]


def test_code_that_scrolls_or_wraps_is_not_cut_off(browser, tmp_path):
    body = (f"<pre style='overflow:auto'>{LONG_LINE}</pre>"
            f"<div class='cell_output'><pre style='white-space:pre-wrap;overflow-wrap:anywhere'>"
            f"{LONG_LINE}</pre></div>")
    assert findings(browser, tmp_path, body) == []


def test_a_cell_output_that_must_be_scrolled_sideways_is_found(browser, tmp_path):
    body = f"<div class='cell_output'><pre style='overflow:auto'>{LONG_LINE}</pre></div>"
    assert [kind for kind, _ in findings(browser, tmp_path, body)] == ["output scrolls"]


def test_an_image_that_does_not_load_is_found(browser, tmp_path):
    body = "<img src='pixel.png' alt='loads'><img src='missing.png' alt='missing'>"
    assert findings(browser, tmp_path, body) == [("image not loaded", "missing.png")]


def test_the_pages_of_a_site_are_its_html_files_but_assets_and_sphinx_indexes(tmp_path):
    for name in ("index.html", "_generated/envs/ids.html", "tutorials/a.html", "search.html",
                 "genindex.html", "_static/x.html", "_sources/index.html"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("<html></html>")
    assert [p.relative_to(tmp_path).as_posix() for p in site_check.pages_of(tmp_path)] == [
        "_generated/envs/ids.html", "index.html", "tutorials/a.html"]


def test_the_command_refuses_a_folder_without_a_built_site(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        site_check.main([str(tmp_path)])
    assert stop.value.code == 2
    assert "no index.html" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        site_check.main([str(tmp_path), "--width", "100"])
    assert stop.value.code == 2
