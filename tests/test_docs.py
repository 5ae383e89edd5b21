"""The documentation cites no file that is not in the repository.

Checked: every relative link and every backticked repository path (``benchmarks/x.py``,
``docs/y.md``, ``rehabbot/...py``) in README.md and docs/**/*.md (the pages written at build
time, docs/_generated, and the build output, docs/_build, excluded), the README's size and
its headline-results markers, and the help text of the ``rehabbot`` command and of each of
its subcommands. The Sphinx build itself (``make docs``, strict) checks the cross-references
between pages.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
EXCLUDED = ("_build", "_generated")

# The folders and files at the repository's root that a path in backticks may start with.
TOP_DIRS = ("rehabbot", "benchmarks", "docs", "examples", "sweeps", "tests", ".ci")
TOP_FILES = ("README.md", "CHANGELOG.md", "CITATION.cff", "pyproject.toml", "Makefile",
             "LICENSE")

# The research notes are records of measurements: they name files of the commit they were
# measured with (each page says which) that the repository does not hold. Only these may be
# missing, and only on those pages.
HISTORICAL = {
    "rehabbot/rl/features_jax.py": "the JAX TrackingErrorFeatures (commit 51d9d71)",
    "rehabbot/rl/features.py": "TrackingErrorFeatures (commit 51d9d71)",
    "tests/test_normalized_actions.py": "the normalised-action policy's test (commit 51d9d71)",
}
HISTORICAL_PATTERNS = (
    re.compile(r"sweeps/[\w*.-]*-v1\.yaml"),  # the -v1 sweep files (commit 51d9d71)
)

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
BACKTICKED = re.compile(r"(?<!`)`([^`\s]+)`(?!`)")
FENCE = re.compile(r"^(```|~~~)")


def doc_files() -> list[Path]:
    files = [ROOT / "README.md"]
    for path in sorted(DOCS.rglob("*.md")):
        if not any(part in EXCLUDED for part in path.relative_to(DOCS).parts):
            files.append(path)
    return files


def prose(text: str) -> str:
    """The text outside fenced code blocks (commands there name run folders, not files)."""
    lines, fenced = [], False
    for line in text.splitlines():
        if FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if not fenced:
            lines.append(line)
    return "\n".join(lines)


ENV_ID = re.compile(r"rehabbot/rehab-[\w{},*-]*")  # a Gymnasium id, not a path


BUILD_OUTPUTS = ("docs/_build", "docs/_generated")


def is_repository_path(token: str) -> bool:
    token = token.rstrip(".,;:")
    if ENV_ID.fullmatch(token):
        return False
    if token in TOP_FILES:
        return True
    if token.startswith(BUILD_OUTPUTS):  # written by `make docs`, not part of the repository
        return False
    head = token.split("/", 1)[0]
    return "/" in token and head in TOP_DIRS


def path_exists(token: str) -> bool:
    token = token.rstrip(".,;:")
    if any(ch in token for ch in "<>{}"):  # a placeholder (rehabbot/zoo/<env>/<algo>.npz)
        token = re.split(r"[<>{}]", token, maxsplit=1)[0].rsplit("/", 1)[0]
    if "*" in token:
        return any(ROOT.glob(token))
    return (ROOT / token).exists()


def historical(token: str, page: Path) -> bool:
    if "research-notes" not in page.parts:
        return False
    token = token.rstrip(".,;:")
    return token in HISTORICAL or any(p.fullmatch(token) for p in HISTORICAL_PATTERNS)


@pytest.mark.parametrize("page", doc_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_exist(page: Path) -> None:
    missing = []
    for target in LINK.findall(prose(page.read_text(encoding="utf-8"))):
        if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
            continue  # a URL (https:, mailto:) or an anchor on the same page
        path = target.split("#", 1)[0]
        resolved = (page.parent / path).resolve()
        generated = DOCS / "_generated"
        if resolved.is_relative_to(generated):
            continue  # written at build time (docs/_ext/); the strict build checks them
        if not resolved.exists():
            missing.append(target)
    assert not missing, f"{page.relative_to(ROOT)} links to missing files: {missing}"


@pytest.mark.parametrize("page", doc_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_backticked_repository_paths_exist(page: Path) -> None:
    missing = [token for token in BACKTICKED.findall(prose(page.read_text(encoding="utf-8")))
               if is_repository_path(token) and not path_exists(token)
               and not historical(token, page)]
    assert not missing, f"{page.relative_to(ROOT)} names files not in the repository: {missing}"


def test_historical_exceptions_are_really_gone() -> None:
    """An exception for a removed file lapses once the file exists again."""
    assert not [path for path in HISTORICAL if (ROOT / path).exists()]


def test_readme_is_short_and_has_the_headline_markers() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) < 200
    start = text.index("<!-- headline-results: start -->")
    end = text.index("<!-- headline-results: end -->")
    assert start < end and re.search(r"\| env +\| algo +\|", text[start:end])


def help_texts() -> dict[str, str]:
    """``rehabbot --help`` and every subcommand's (nested ones too), as printed."""
    from rehabbot.cli import build_parser

    texts: dict[str, str] = {}

    def walk(parser: argparse.ArgumentParser, name: str) -> None:
        texts[name] = parser.format_help()
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for command, subparser in action.choices.items():
                    walk(subparser, f"{name} {command}")

    walk(build_parser(), "rehabbot")
    return texts


def test_cli_help_cites_only_files_in_the_repository() -> None:
    texts = help_texts()
    assert {"rehabbot", "rehabbot train", "rehabbot zoo export"} <= set(texts)
    problems = []
    for name, text in texts.items():
        if "domain-facts" in text:
            problems.append(f"{name}: cites domain-facts, which is not in the repository")
        for token in re.findall(r"[\w.-]+(?:/[\w.<>*-]+)+", text):
            token = token.rstrip(".,;:)")
            if is_repository_path(token) and not path_exists(token):
                problems.append(f"{name}: {token}")
    assert not problems, problems


def sections(text: str) -> dict[str, str]:
    """A Markdown page's ``## `` sections by title, each up to the next ``## `` heading."""
    parts = re.split(r"^## (.+)$", text, flags=re.MULTILINE)
    return {title.strip(): body for title, body in zip(parts[1::2], parts[2::2], strict=True)}


def python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.MULTILINE | re.DOTALL)


def test_the_landing_page_leads_with_a_picture_install_and_quickstart() -> None:
    text = (DOCS / "index.md").read_text(encoding="utf-8")
    before_toctree = text[:text.index("```{toctree}")]
    titles = list(sections(before_toctree))
    assert titles[:2] == ["Install", "Quickstart"], titles
    intro = before_toctree[:before_toctree.index("## Install")]
    pictures = re.findall(r"!\[[^\]]+\]\((images/[\w.-]+\.png)\)", intro)
    assert pictures and all((DOCS / picture).is_file() for picture in pictures), pictures
    install = sections(before_toctree)["Install"]
    assert re.search(r"^pip install \.\s", install, flags=re.MULTILINE), install
    assert python_blocks(sections(before_toctree)["Quickstart"])
    # How the site is built is a page of its own, not the landing page's business.
    assert "How this site is built" not in text
    assert "building-the-docs" in text[text.index("```{toctree}"):]


def test_the_readme_and_the_landing_page_give_the_same_quickstart() -> None:
    readme = sections((ROOT / "README.md").read_text(encoding="utf-8"))
    landing = sections((DOCS / "index.md").read_text(encoding="utf-8"))
    assert python_blocks(readme["Quickstart"])[0] == python_blocks(landing["Quickstart"])[0]
    assert list(readme).index("Install") < list(readme).index("Quickstart")


def test_the_quickstart_runs_as_typed(capsys) -> None:
    """The landing page's first code, with nothing but a core install: a zoo agent finishes
    its knee episode."""
    code = python_blocks(sections((DOCS / "index.md").read_text(encoding="utf-8"))
                         ["Quickstart"])[0]
    exec(compile(code, "docs/index.md, Quickstart", "exec"), {"__name__": "quickstart"})
    success, force_n = capsys.readouterr().out.split()
    assert success == "True" and 0 < float(force_n) < 130, (success, force_n)
