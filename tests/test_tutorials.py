"""The tutorials in docs/tutorials/ are MyST-NB text notebooks that the docs build executes in
full; this fast check catches a missing front matter, a page without code or a syntax slip in
a code cell before that."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

TUTORIALS_DIR = Path(__file__).resolve().parents[1] / "docs" / "tutorials"
TUTORIALS = sorted(p for p in TUTORIALS_DIR.glob("*.md") if p.name != "index.md")
FRONT_MATTER_RE = re.compile(r"\A---\n(?P<body>.*?)\n---\n", re.DOTALL)
# A code cell: a fence of three or more backticks opening with {code-cell}, up to the same
# fence; MyST options (":tags: [...]" lines, or a "---" block) may open the cell.
CODE_CELL_RE = re.compile(r"^(?P<fence>`{3,})\{code-cell\}[^\n]*\n(?P<body>.*?)^(?P=fence)[ \t]*$",
                          re.DOTALL | re.MULTILINE)


def code_cells(text: str) -> list[str]:
    """The code of each ``{code-cell}`` of a MyST-NB page, cell options removed."""
    cells = []
    for match in CODE_CELL_RE.finditer(text):
        body = match["body"]
        if body.startswith("---\n"):  # a YAML block of cell options
            body = body.split("\n---\n", 1)[1] if "\n---\n" in body else ""
        lines = body.splitlines()
        while lines and re.match(r"^:[\w-]+:", lines[0]):  # short-form cell options
            lines.pop(0)
        cells.append("\n".join(lines) + "\n")
    return cells


def ipython_to_python(code: str) -> str:
    """IPython-only lines (``!cmd``, ``%magic``, ``%%cell magic``) as ``pass`` so that the
    rest compiles as Python; indentation kept."""
    return "\n".join(re.sub(r"^(\s*)[!%].*$", r"\1pass", line) for line in code.splitlines())


def test_there_are_tutorials():
    names = {p.name for p in TUTORIALS}
    assert {"train-and-evaluate.md", "your-own-exercise.md"} <= names, names


@pytest.mark.parametrize("path", TUTORIALS, ids=[p.name for p in TUTORIALS])
def test_tutorial_is_a_mystnb_notebook_whose_cells_compile(path: Path):
    text = path.read_text(encoding="utf-8")
    front = FRONT_MATTER_RE.match(text)
    assert front, f"{path.name}: no front matter (--- ... ---) at the top"
    body = front["body"]
    assert re.search(r"^file_format:\s*mystnb\s*$", body, re.MULTILINE), \
        f"{path.name}: front matter lacks 'file_format: mystnb' (MyST-NB would not run it)"
    assert re.search(r"^kernelspec:\s*$", body, re.MULTILINE) and \
        re.search(r"^\s+name:\s*python3\s*$", body, re.MULTILINE), \
        f"{path.name}: front matter lacks a kernelspec with name: python3"
    rest = text[front.end():]
    assert rest.lstrip("\n").startswith("# "), f"{path.name}: the page must start with a # Title"
    cells = code_cells(text)
    assert cells, f"{path.name}: no ```{{code-cell}} ipython3 cell"
    assert text.count("{code-cell}") == len(cells), \
        f"{path.name}: a {{code-cell}} fence is not closed"
    for k, cell in enumerate(cells):
        try:
            compile(ipython_to_python(cell), f"{path.name}, code cell {k + 1}", "exec",
                    flags=ast.PyCF_ALLOW_TOP_LEVEL_AWAIT)
        except SyntaxError as error:
            pytest.fail(f"{path.name}, code cell {k + 1}: {error}")


def test_the_cell_reader_finds_cells_and_reports_syntax_errors():
    page = ("---\nfile_format: mystnb\n---\n# T\n\n```{code-cell} ipython3\n:tags: [hide-input]\n"
            "x = 1\n!ls\n```\n\n````{code-cell} ipython3\nprint('```')\n````\n\n"
            "```{code-cell} ipython3\ndef f(:\n```\n")
    cells = code_cells(page)
    assert cells == ["x = 1\n!ls\n", "print('```')\n", "def f(:\n"]
    compile(ipython_to_python(cells[0]), "cell", "exec")
    with pytest.raises(SyntaxError):
        compile(ipython_to_python(cells[2]), "cell", "exec")


# The widest code line that the site's content column shows without scrolling (Furo, a
# laptop's 1366 px window: 89 characters of its code font); longer lines hide their end.
CODE_LINE_MAX_CHARS = 88


@pytest.mark.parametrize("path", TUTORIALS, ids=[p.name for p in TUTORIALS])
def test_tutorial_code_lines_fit_the_page(path: Path):
    long_lines = [f"code cell {k + 1}: {len(line)} characters: {line.strip()[:60]}"
                  for k, cell in enumerate(code_cells(path.read_text(encoding="utf-8")))
                  for line in cell.splitlines() if len(line) > CODE_LINE_MAX_CHARS]
    assert not long_lines, f"{path.name}: lines wider than the page's column: {long_lines}"


# `rehabbot evaluate mymodule:GentleExpert`: a policy given as module:attribute in a command.
COMMAND_POLICY_RE = re.compile(r"(?<![\w/.:-])([a-z_][a-z0-9_]*):([A-Z]\w*)")
SHELL_BLOCK_RE = re.compile(r"^```(?:console|bash|shell|sh)\n(?P<body>.*?)^```",
                            re.DOTALL | re.MULTILINE)


@pytest.mark.parametrize("path", TUTORIALS, ids=[p.name for p in TUTORIALS])
def test_a_module_a_command_imports_is_one_the_page_says_to_write(path: Path):
    """A command that loads ``mymodule:GentleExpert`` works only if the reader saved the class
    in ``mymodule.py``: the page must say so (outside the command)."""
    text = path.read_text(encoding="utf-8")
    prose = SHELL_BLOCK_RE.sub("", text)
    for block in SHELL_BLOCK_RE.finditer(text):
        for module, attribute in COMMAND_POLICY_RE.findall(block["body"]):
            assert f"`{module}.py`" in prose, (
                f"{path.name}: a command uses {module}:{attribute}, but the page never says to "
                f"save {attribute} as `{module}.py`")
            assert re.search(rf"\bclass {attribute}\b", text), \
                f"{path.name}: {module}:{attribute} is not defined on the page"


def test_the_command_policy_reader_finds_module_attributes():
    block = ("```console\nrehabbot evaluate expert mymodule:GentleExpert zoo:rehab-knee-v2/sac "
             "--env-kwargs '{\"a\": 1}' runs/x:Y\n```\n")
    found = [COMMAND_POLICY_RE.findall(m["body"]) for m in SHELL_BLOCK_RE.finditer(block)]
    assert found == [[("mymodule", "GentleExpert")]]
