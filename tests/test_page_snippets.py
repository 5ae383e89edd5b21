"""The Python code blocks of the docs pages run as typed: each page's ```python blocks, in order,
as one script in a fresh interpreter (no ``rehabbot`` imported unless the page imports it) in an
empty folder, which they leave empty."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^```python\n(.*?)^```", flags=re.S | re.M)
# page -> the extra module it needs (None: a core install runs it)
PAGES = {"docs/musculoskeletal-patient.md": "myo_sim", "docs/envs.md": None,
         "docs/conditions.md": None, "docs/robots.md": None,
         "docs/deployment/export.md": "onnxruntime", "docs/deployment/randomisation.md": None}
FAST = ("docs/musculoskeletal-patient.md", "docs/envs.md")


def python_blocks(page: Path) -> list[str]:
    """The page's fenced ``python`` blocks, in order."""
    return FENCE.findall(page.read_text(encoding="utf-8"))


def test_blocks_are_found_as_fenced():
    text = "a\n```python\nx = 1\n```\n```bash\nls\n```\n```python\ny = x\n```\n"
    assert FENCE.findall(text) == ["x = 1\n", "y = x\n"]


@pytest.mark.parametrize("page", [pytest.param(p, marks=() if p in FAST else pytest.mark.slow)
                                  for p in PAGES])
def test_a_pages_python_blocks_run_as_typed(page, tmp_path):
    if PAGES[page] is not None:
        pytest.importorskip(PAGES[page], reason=f"{page} needs {PAGES[page]}")
    blocks = python_blocks(ROOT / page)
    assert blocks, f"{page} has no python block"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MUJOCO_GL": "egl"}
    result = subprocess.run([sys.executable, "-c", "\n".join(blocks)], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, f"{page}: {result.stderr[-3000:]}"
    assert sorted(p.name for p in tmp_path.iterdir()) == []
