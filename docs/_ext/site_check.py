"""Check the built documentation site in a real browser (headless Chromium, through Selenium).

``python docs/_ext/site_check.py docs/_build/html`` (``make docs-check``) opens every page of
the built site in a laptop's window and a phone's, and reports, page by page, what a reader
would see broken:

- ``table as text``: a paragraph (or list item, definition, table cell, output) outside code
  whose text holds a Markdown table's separator row (``| --- |``): a table not rendered;
- ``repr shown``: the text of an object's ``repr`` where a figure or value should be, such as
  ``<Figure size 800x780 with 3 Axes>`` or ``<... object at 0x7f...>``;
- ``overflow``: a table, code block or output wider than the content column and not inside a
  box that scrolls sideways, so that it runs over the page's edge;
- ``cut off``: a code block or output whose lines are clipped on the right with no scroll bar
  to reach them;
- ``output scrolls``: a line that an executed tutorial cell printed runs past the output's box
  (outputs wrap: docs/_static/rehabbot.css), hidden until the reader scrolls sideways;
- ``image not loaded``: an ``<img>`` whose file is missing or does not decode.

Each finding is one line, ``page @ width: what: element: detail``; the exit status is 1 when
there is any, 2 for bad usage (no built site, no browser), 0 for a clean site. The browser is
Debian's ``chromium`` with its ``chromium-driver`` (``.ci/run`` installs both); nothing is
downloaded: the driver's path is given, so Selenium Manager is never asked for one.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import sys
import tempfile
from collections.abc import Iterable
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
# A laptop's window (Furo shows its three columns: navigation, content, contents) and a phone's
# (one column).
WINDOW_WIDTHS_PX = (1366, 390)
WINDOW_HEIGHT_PX = 900
# Sphinx's own pages: the search page fills itself by script, the indexes are lists of links.
SKIPPED_PAGES = {"search.html", "genindex.html", "py-modindex.html"}
# Folders of a built site that hold assets and sources, not pages.
NOT_PAGES = {"_static", "_sources", "_images", "_downloads", "_modules"}
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage")

# Runs in the page; returns a list of [kind, element, detail]. Waits for every image to load
# or fail first (lazy images are made eager), at most IMAGE_WAIT_MS.
CHECK_PAGE_JS = r"""
const done = arguments[arguments.length - 1];
const IMAGE_WAIT_MS = 10000;
(async () => {
  const images = Array.from(document.images);
  await Promise.all(images.map((img) => {
    img.loading = "eager";
    if (img.complete) return null;
    return new Promise((resolve) => {
      img.addEventListener("load", resolve, {once: true});
      img.addEventListener("error", resolve, {once: true});
      setTimeout(resolve, IMAGE_WAIT_MS);
    });
  }));
  const findings = [];
  const column = document.querySelector("article[role=main]")
    || document.querySelector("div.body") || document.body;
  const columnBox = column.getBoundingClientRect();
  const SLACK = 1.5;  // px: sub-pixel rounding

  function describe(el) {
    const parts = [];
    for (let node = el; node && node !== column && parts.length < 3; node = node.parentElement) {
      let part = node.tagName.toLowerCase();
      if (node.id) part += "#" + node.id;
      const classes = Array.from(node.classList).slice(0, 2);
      if (classes.length) part += "." + classes.join(".");
      parts.unshift(part);
    }
    const heading = (() => {
      const all = Array.from(column.querySelectorAll("h1, h2, h3, h4"));
      let last = null;
      for (const h of all) {
        if (h.compareDocumentPosition(el) & Node.DOCUMENT_POSITION_FOLLOWING) last = h;
      }
      return last ? last.textContent.replace(/[#¶]/g, "").trim() : "";
    })();
    return parts.join(" > ") + (heading ? ` under "${heading}"` : "");
  }
  function snippet(text) {
    const flat = text.replace(/\s+/g, " ").trim();
    return flat.length > 80 ? flat.slice(0, 77) + "..." : flat;
  }
  function visible(el) {
    const box = el.getBoundingClientRect();
    return box.width > 0 && box.height > 0;
  }
  function inCode(el) {
    return el.closest("pre, code, .highlight, script, style, textarea") !== null;
  }

  // 1. A Markdown table rendered as text.
  // Its separator row: "| --- |", or "| — |" once the build's typography made the dashes
  // an en or em dash (a norm such as ||x|| has no dash between bars).
  const SEPARATOR = /\|\s*:?[-\u2010-\u2015]+:?\s*\|/;
  for (const el of column.querySelectorAll("p, li, dd, td, th, div.output")) {
    if (inCode(el) || !visible(el)) continue;
    const own = Array.from(el.childNodes)
      .filter((n) => n.nodeType === Node.TEXT_NODE || !["P", "UL", "OL", "DL", "TABLE", "PRE",
        "DIV"].includes(n.tagName))
      .map((n) => n.textContent).join("");
    if (SEPARATOR.test(own)) {
      findings.push(["table as text", describe(el), snippet(own)]);
    }
  }

  // 2. An object's repr where its picture or value should be.
  const FIGURE_REPR = /<(?:[\w.]+\.)?Figure size [\d.]+x[\d.]+ with \d+ Axes>/;
  const OBJECT_REPR = /<[\w.]+ object at 0x[0-9a-fA-F]+>/;
  const REPR = new RegExp(FIGURE_REPR.source + "|" + OBJECT_REPR.source);
  const walker = document.createTreeWalker(column, NodeFilter.SHOW_TEXT);
  for (let node = walker.nextNode(); node; node = walker.nextNode()) {
    const match = node.textContent.match(REPR);
    if (!match) continue;
    const el = node.parentElement;
    // A repr quoted in inline code (prose, a table) is text about the repr, not a lost figure.
    if (el.closest("code") && !el.closest("pre")) continue;
    if (!visible(el)) continue;
    findings.push(["repr shown", describe(el), match[0]]);
  }

  // 3 and 4. Content wider than its box: it must sit in a box that scrolls sideways, and that
  // box must fit the content column.
  function overflowProblem(el) {
    const box = el.getBoundingClientRect();
    const contentRight = Math.max(box.right, box.left + el.scrollWidth);
    if (contentRight <= box.right + SLACK && box.right <= columnBox.right + SLACK) return null;
    for (let node = el; node && node !== column.parentElement; node = node.parentElement) {
      const style = getComputedStyle(node);
      const nodeBox = node.getBoundingClientRect();
      if (["auto", "scroll"].includes(style.overflowX)) {
        if (node.scrollWidth > node.clientWidth + SLACK || node === el) {
          if (nodeBox.right > columnBox.right + SLACK) {
            const past = Math.round(nodeBox.right - columnBox.right);
            return ["overflow", `its scrolling box ends ${past} px right of the content column`];
          }
          return null;
        }
      }
      if (["hidden", "clip"].includes(style.overflowX) && contentRight > nodeBox.right + SLACK) {
        const clipped = Math.round(contentRight - nodeBox.right);
        return ["cut off", `${clipped} px clipped on the right, no scroll bar`];
      }
    }
    if (contentRight > columnBox.right + SLACK) {
      const past = Math.round(contentRight - columnBox.right);
      return ["overflow", `${past} px wider than the content column`];
    }
    return null;
  }
  for (const el of column.querySelectorAll("table, pre")) {
    if (!visible(el)) continue;
    if (el.tagName === "TABLE" && el.closest("pre, .highlight")) continue;
    const problem = overflowProblem(el);
    if (problem) findings.push([problem[0], describe(el), problem[1]]);
  }
  // What a tutorial's cell printed wraps (docs/_static/rehabbot.css): a line that runs past
  // the output's box is hidden until the reader scrolls sideways.
  for (const pre of column.querySelectorAll("div.cell_output pre")) {
    if (!visible(pre) || pre.scrollWidth <= pre.clientWidth + SLACK) continue;
    if (overflowProblem(pre)) continue;  // already reported as cut off or overflowing
    findings.push(["output scrolls", describe(pre),
                   `lines run ${pre.scrollWidth - pre.clientWidth} px past the output's box`]);
  }

  // 5. Images that do not load.
  for (const img of images) {
    if (!img.complete || img.naturalWidth === 0) {
      findings.push(["image not loaded", describe(img), img.getAttribute("src") || "(no src)"]);
    }
  }
  return findings;
})().then(done, (error) => done([["check failed", "", String(error)]]));
"""


@dataclasses.dataclass(frozen=True)
class Finding:
    """One thing a reader would see broken on one page."""

    page: str
    width_px: int
    kind: str
    element: str
    detail: str

    def __str__(self) -> str:
        return f"{self.page} @ {self.width_px} px: {self.kind}: {self.element}: {self.detail}"


def pages_of(site: Path) -> list[Path]:
    """Every HTML page of a built site, but Sphinx's search page and indexes."""
    return sorted(path for path in site.rglob("*.html")
                  if path.name not in SKIPPED_PAGES
                  and not set(path.relative_to(site).parts[:-1]) & NOT_PAGES)


def browser_missing() -> str | None:
    """Why the browser check cannot run here, or None when it can."""
    for path, package in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromium-driver")):
        if not Path(path).exists():
            return f"{path} is missing (Debian package {package})"
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "the selenium package is missing (pip install -e '.[docs]')"
    return None


class Browser:
    """One headless Chromium for a whole check; a fresh, throwaway profile."""

    def __init__(self, width_px: int = WINDOW_WIDTHS_PX[0], height_px: int = WINDOW_HEIGHT_PX):
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        os.environ.setdefault("SE_AVOID_STATS", "true")  # Selenium sends no usage statistics
        self._profile = tempfile.mkdtemp(prefix="rehabbot-site-check-")
        options = webdriver.ChromeOptions()
        options.binary_location = CHROMIUM
        for flag in CHROMIUM_FLAGS:
            options.add_argument(flag)
        options.add_argument(f"--user-data-dir={self._profile}")
        options.add_argument(f"--window-size={width_px},{height_px}")
        try:
            self._driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
        except Exception:
            shutil.rmtree(self._profile, ignore_errors=True)
            raise
        self._driver.set_script_timeout(60)
        self.width_px = width_px

    def resize(self, width_px: int) -> None:
        self._driver.set_window_size(width_px, WINDOW_HEIGHT_PX)
        self.width_px = width_px

    def check(self, page: Path, name: str) -> list[Finding]:
        self._driver.get(page.resolve().as_uri())
        rows = self._driver.execute_async_script(CHECK_PAGE_JS)
        return [Finding(name, self.width_px, kind, element, detail)
                for kind, element, detail in rows]

    def close(self) -> None:
        try:
            self._driver.quit()
        finally:
            shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def check_site(site: Path, widths_px: Iterable[int] = WINDOW_WIDTHS_PX) -> list[Finding]:
    """The findings of every page of a built site, at each window width, in one browser."""
    pages = [(page, page.relative_to(site).as_posix()) for page in pages_of(site)]
    findings: list[Finding] = []
    with Browser() as browser:
        for width_px in widths_px:
            browser.resize(width_px)
            for page, name in pages:
                findings += browser.check(page, name)
    return findings


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="site_check.py",
        description="Open every page of the built docs in headless Chromium and report tables "
                    "shown as text, reprs shown instead of figures, content wider than the "
                    "page, clipped code or output, and images that do not load.")
    parser.add_argument("site", type=Path, help="the built HTML (docs/_build/html)")
    parser.add_argument("--width", type=int, nargs="+", default=list(WINDOW_WIDTHS_PX),
                        metavar="PX", help="browser window widths in px, each checked (default "
                        f"{' '.join(map(str, WINDOW_WIDTHS_PX))}: a laptop and a phone)")
    args = parser.parse_args(argv)
    for width in args.width:
        if not 320 <= width <= 4000:
            parser.error(f"--width {width}: must be 320 to 4000 px")
    if not (args.site / "index.html").is_file():
        parser.error(f"{args.site}: no index.html there; build the site first (make docs)")
    missing = browser_missing()
    if missing:
        print(f"site_check.py: cannot run the browser check: {missing}", file=sys.stderr)
        return 2
    pages = pages_of(args.site)
    findings = check_site(args.site, args.width)
    for finding in findings:
        print(finding)
    widths = " and ".join(f"{width} px" for width in args.width)
    print(f"site_check.py: {len(pages)} pages at {widths}, {len(findings)} findings")
    return 1 if findings else 0


if __name__ == "__main__":
    sys.exit(main())
