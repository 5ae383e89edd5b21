"""Sphinx configuration of RehabBot's documentation (``make docs``).

Sphinx + MyST-Parser (Markdown pages) + MyST-NB (tutorials executed during the build) + Furo.
The per-family env pages are written at build time from ``gymnasium.registry`` and the env
classes' docstrings by ``docs/_ext/env_pages.py`` into ``docs/_generated/`` (not committed).
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(DOCS / "_ext"))

import optional_imports  # noqa: E402  (docs/_ext, after the path is set)

import rehabbot  # noqa: E402

project = "RehabBot"
author = "RehabBot developers"
copyright = "RehabBot developers, MIT licence"
release = rehabbot.__version__
version = release

extensions = [
    "myst_nb",  # MyST-Parser's Markdown plus executed notebooks (docs/tutorials/)
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",  # the docstrings' Google-style "Raises:" sections
    "sphinx.ext.mathjax",
    "sphinx_copybutton",
    "env_pages",  # docs/_ext/env_pages.py: one page per env family, from the registry
    "api_pages",  # docs/_ext/api_pages.py: the API reference, one page per layer
]

source_suffix = {".md": "myst-nb", ".ipynb": "myst-nb"}
root_doc = "index"
exclude_patterns = [
    "_build",
    "**/*.json",
    "**/.ipynb_checkpoints",
]
# docs/results/*.json sit beside the generated results pages; they are data, not pages.

# -- MyST ------------------------------------------------------------------------------------
myst_enable_extensions = ["colon_fence", "deflist", "dollarmath", "attrs_inline"]
myst_heading_anchors = 4  # [text](page.md#a-heading) links resolve, as on GitHub

# -- MyST-NB: the tutorials are executed on every build, so they cannot rot ------------------
nb_execution_mode = "force"
nb_execution_raise_on_error = True
nb_execution_timeout = 600
nb_execution_excludepatterns: list[str] = []
nb_merge_streams = True
nb_execution_show_tb = True  # a failing tutorial prints its traceback in the build log
# A cell's Markdown output (IPython.display.Markdown: the clinical tables) is parsed as MyST,
# which has tables; MyST-NB's default, CommonMark, has none and shows a table as a paragraph.
nb_render_markdown_format = "myst"

# -- autodoc ---------------------------------------------------------------------------------
# The docs build needs `pip install ".[docs]"` alone (CI builds them in such a venv: make docs):
# the libraries of other extras that documented modules import ([gpu]: JAX, Flax, Warp, MJX,
# rsl_rl) are mocked where missing, with stand-ins for the two names that shape a documented
# class (docs/_ext/optional_imports.py).
autodoc_mock_imports = optional_imports.mocked_imports()
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_format = "short"
autodoc_default_options: dict[str, object] = {}  # docs/_ext/api_pages.py sets :members:
autodoc_inherit_docstrings = False  # no Gymnasium or SB3 docstrings in our reference
autosummary_generate = False
napoleon_google_docstring = True
napoleon_numpy_docstring = False

# -- strict mode (-W --keep-going -n): every cross-reference must resolve ------------------
nitpicky = True
# Only third-party types (and the standard library's), which this site does not document and
# for which no intersphinx inventory is fetched (the build needs no network).
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|np|npt|numpy\.typing)(\..*)?"),
    (r"py:.*", r"(gymnasium|gym)(\..*)?"),
    (r"py:.*", r"mujoco(\..*)?"),
    (r"py:.*", r"(torch|stable_baselines3|sbx|jax|flax|optax|ray|matplotlib|imageio)(\..*)?"),
    (r"py:.*", r"(ndarray|NDArray|ArrayLike|DTypeLike|MjModel|MjData|MjSpec|Env|Space|Box)"),
    (r"py:.*", r"(collections|typing|pathlib|argparse|os|io|json|types|dataclasses|enum|abc)\..*"),
    (r"py:class", r"subprocess\.Popen"),
    (r"py:class", r"(Figure|Axes)"),  # matplotlib's, in rehabbot.analysis.figures' annotations
    (r"py:.*", r"(Path|Callable|Iterable|Iterator|Sequence|Mapping|Any|Literal|Self)"),
]
# Our own docstrings resolve: nothing of rehabbot is ignored (third parties: above).
nitpick_ignore: list[tuple[str, str]] = []
# A glob toctree (tutorials/, results/) may match nothing until its pages land; Sphinx gives
# that warning no type, so suppress_warnings cannot select it: _EmptyGlob (below) drops it.

# -- HTML ------------------------------------------------------------------------------------
html_theme = "furo"
html_title = f"RehabBot {release}"
html_static_path = ["_static"]
html_css_files = ["rehabbot.css"]  # docs/_static/rehabbot.css: wide tables, cell outputs
html_show_sourcelink = False

# -- the env modules' docstrings are Markdown (Gymnasium-v5 tables): the env pages render them
MARKDOWN_DOCSTRING_MODULES = {
    "rehabbot.envs.rehab_env": "the [arm](../_generated/envs/arm.md), hip and knee pages",
    "rehabbot.envs.bilateral_env": "the [both arms](../_generated/envs/bilateral.md) page",
    "rehabbot.envs.population": "the [populations](../_generated/envs/populations.md) page",
}


def _markdown_module_docstring(app, what, name, obj, options, lines):
    """Replace a Markdown module docstring by a pointer to the page that renders it."""
    if what == "module" and name in MARKDOWN_DOCSTRING_MODULES:
        first = lines[0] if lines else ""
        lines[:] = [first, "", "Its full description (spaces, rewards, episode end, every "
                    "argument) is rendered from this module's docstring on the env family "
                    "pages (:doc:`/envs`)."]


def _patch_napoleon_inline_attributes():
    """Napoleon reads the first line of a property's docstring as ``type: description``. Ours
    are sentences ("The speed every joint can reach (rad/s): ..."): a first line whose part
    before the colon has a space outside brackets stays prose."""
    import re

    from sphinx.ext.napoleon.docstring import GoogleDocstring

    original = GoogleDocstring._consume_inline_attribute

    def consume(self):
        line = self._lines.get(0)
        if isinstance(line, str):
            head, colon, rest = self._partition_field_on_colon(line)
            if colon and rest and " " in re.sub(r"\[[^\]]*\]", "", head.strip()):
                self._lines.next()
                lines = [line, *self._dedent(self._consume_to_end())]
                return "", self.__class__(lines, self._config).lines()
        return original(self)

    GoogleDocstring._consume_inline_attribute = consume


_patch_napoleon_inline_attributes()


# Docstrings whose reStructuredText does not parse would be shown verbatim, as a literal
# block, so that nothing is lost; none is listed today (a new one fails the strict build).
VERBATIM_DOCSTRINGS: set[str] = set()


def _verbatim_docstring(app, what, name, obj, options, lines):
    if what == "module" and name in VERBATIM_DOCSTRINGS and lines:
        lines[:] = ["::", ""] + ["    " + line for line in lines]


def _python_targets(target, module_name, class_name):
    """Where a docstring's target can point, best first, as (kind, full dotted name): the object
    itself (a class, function or method, by its defining module and qualified name; a
    module), then what holds it (the class of a private member or of an instance attribute;
    the module of a constant)."""
    import importlib
    import inspect

    parts = target.split(".")
    candidates = []
    if target.startswith("rehabbot."):
        for cut in range(len(parts), 0, -1):
            candidates.append((".".join(parts[:cut]), parts[cut:]))
    elif module_name:
        candidates.append((module_name, parts))
        if class_name:
            candidates.append((module_name, [*class_name.split("."), *parts]))
    found = []
    for module_path, attrs in candidates:
        try:
            chain = [importlib.import_module(module_path)]
        except ImportError:
            continue
        missing = False
        for attr in attrs:
            try:
                chain.append(getattr(chain[-1], attr))
            except AttributeError:
                missing = True
                break
        if missing and not inspect.isclass(chain[-1]):
            continue  # a name the module does not have: not ours to guess
        for obj in reversed(chain):
            if inspect.ismodule(obj):
                if obj.__name__.startswith("rehabbot"):
                    found.append(("mod", obj.__name__))
                break
            if inspect.isclass(obj) or inspect.isroutine(obj):
                module = getattr(obj, "__module__", "") or ""
                if module.startswith("rehabbot"):
                    found.append(("obj", f"{module}.{obj.__qualname__}"))
    return found


def _resolve_rehabbot_target(app, env, node, contnode):
    """Resolve what a docstring names by its Python object rather than by its spelling: a
    short name the module imports (``:class:`PatientProfile```), a name re-exported by a
    package (``rehabbot.sim.Scene``), a module-level constant (linked to its module), a
    private member (linked to its class), or a name documented exactly once in the package
    (``:func:`train_run``` from a module that does not import it). Names of other libraries
    are not resolved here."""
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip("~.")
    domain = env.domains["py"]
    for kind, full in _python_targets(target, node.get("py:module"), node.get("py:class")):
        if full == target and kind != "mod":
            continue
        resolved = domain.resolve_xref(env, node.get("refdoc", ""), app.builder, kind, full,
                                       node, contnode)
        if resolved is not None:
            return resolved
    if "." not in target and target.isidentifier():
        matches = [name for name in domain.objects
                   if name.startswith("rehabbot.") and name.endswith("." + target)]
        if len(matches) == 1:
            return domain.resolve_xref(env, node.get("refdoc", ""), app.builder, "obj",
                                       matches[0], node, contnode)
    return None


class _EmptyGlob(logging.Filter):
    """Drop "toctree glob pattern '*' didn't match any documents" for the glob toctrees of
    tutorials/index.md and results/index.md, whose pages land later; every other toctree
    warning stays an error."""

    def filter(self, record):
        message = record.getMessage()
        location = str(getattr(record, "location", ""))
        return not ("didn't match any documents" in message
                    and ("tutorials/index" in location or "results/index" in location))


def setup(app):
    logging.getLogger("sphinx.sphinx.directives.other").addFilter(_EmptyGlob())
    app.connect("autodoc-process-docstring", _markdown_module_docstring)
    app.connect("autodoc-process-docstring", _verbatim_docstring)
    app.connect("missing-reference", _resolve_rehabbot_target)
