"""The figures of a results page: small PNG files beside the page, each carrying the digest of
the data it was drawn from.

A page ``<folder>/<page>.md`` keeps its figures in ``<folder>/figures/<page>/<name>.png``
(the document's ``figures`` entries name them relative to ``<folder>``, see
:mod:`benchmarks.common.documents`). :func:`write_figures` draws them when the script writes
the page, and removes that folder's PNG files the page no longer names. Each PNG holds, in a
``tEXt`` chunk named :data:`DIGEST_KEY`, the SHA-256 of the figure's data
(:func:`benchmarks.common.documents.payload_sha256`), the digest its document records:
``tests/test_results_pages.py`` computes the data again from the JSON and compares digests,
never pixels (which differ between machines and matplotlib versions).

The PNGs are drawn at :data:`DPI` and reduced to a 256-colour palette (flat plots lose
nothing visible), so that a figure stays under :data:`MAX_FIGURE_BYTES`.
"""

from __future__ import annotations

import io
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rehabbot.common.files import atomic_write

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FIGURES_DIR = "figures"
DIGEST_KEY = "rehabbot-data-sha256"
DPI = 100
MAX_FIGURE_BYTES = 100_000
MAX_PAGE_FIGURES_BYTES = 1_000_000

__all__ = ["DIGEST_KEY", "DPI", "FIGURES_DIR", "MAX_FIGURE_BYTES", "MAX_PAGE_FIGURES_BYTES",
           "figure_file", "page_name", "png_digest", "save_png", "slug", "write_figures"]


def page_name(stem: str | Path) -> str:
    """The page's name from its stem (``docs/results/learning-v2[.json|.md]`` ->
    ``learning-v2``)."""
    stem = Path(stem)
    return stem.stem if stem.suffix in (".json", ".md") else stem.name


def slug(text: str) -> str:
    """``text`` as a file name: lower case, runs of other characters than letters and digits
    as one ``-`` (``rehab-hip-v2 (fr3)`` -> ``rehab-hip-v2-fr3``)."""
    cleaned = re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")
    if not cleaned:
        raise ValueError(f"{text!r} holds no letter or digit to name a file by")
    return cleaned


def figure_file(page: str, name: str) -> str:
    """A figure's path relative to its page's folder: ``figures/<page>/<name>.png``."""
    return f"{FIGURES_DIR}/{page}/{slug(name)}.png"


def save_png(figure: Figure, path: Path, sha256: str) -> int:
    """Write ``figure`` to ``path`` as a palette PNG at :data:`DPI` carrying ``sha256`` under
    :data:`DIGEST_KEY` (nothing else: no software or date); return its size in bytes."""
    from PIL import Image, PngImagePlugin

    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=DPI, metadata={"Software": None})
    with Image.open(io.BytesIO(buffer.getvalue())) as image:
        palette = image.convert("RGB").quantize(colors=256, dither=Image.Dither.NONE)
    info = PngImagePlugin.PngInfo()
    info.add_text(DIGEST_KEY, sha256)
    out = io.BytesIO()
    palette.save(out, format="png", pnginfo=info, optimize=True)
    data = out.getvalue()
    atomic_write(Path(path), lambda stream: stream.write(data))
    return len(data)


def png_digest(path: Path) -> str | None:
    """The digest a PNG written by :func:`save_png` carries (None: none)."""
    from PIL import Image

    with Image.open(path) as image:
        return getattr(image, "text", {}).get(DIGEST_KEY)


def write_figures(document: Mapping[str, Any], stem: str | Path,
                  drawings: Mapping[str, Callable[[], Figure]]) -> list[Path]:
    """Draw every figure ``document`` names (``drawings[id]()`` builds it) beside the page
    ``stem``, remove the PNG files of the page's figure folder it no longer names, and return
    the written paths."""
    folder = Path(stem).parent
    written = []
    for figure in document.get("figures", []):
        if figure["id"] not in drawings:
            raise ValueError(f"no drawing for figure {figure['id']!r}")
        path = folder / figure["file"]
        path.parent.mkdir(parents=True, exist_ok=True)
        save_png(drawings[figure["id"]](), path, figure["sha256"])
        written.append(path)
    own = folder / FIGURES_DIR / page_name(stem)
    for png in sorted(own.glob("*.png")) if own.is_dir() else []:
        if png not in written:
            png.unlink()
    return written
