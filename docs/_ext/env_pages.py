"""Sphinx extension: one documentation page per env family, generated at build time.

Every ``rehabbot/`` id in ``gymnasium.registry`` is sorted into a family (arm, hip, knee, both
arms, condition variants, populations). Each family's page (``docs/_generated/envs/<family>.md``,
not committed) has a table of its ids with their registered kwargs, ``max_episode_steps`` and
the observation and action spaces of the env that ``gym.make`` builds (for a ``-myo`` id, its
base id's, which are the same: no ``[myo]`` extra needed), followed by the env
class's module docstring (Gymnasium-v5 style Markdown sections and tables), whose
reStructuredText roles (``:class:`x```) become MyST roles (``{class}`x```). The page
``docs/_generated/envs/ids.md`` lists every id, one table, so that no page types them by hand.
"""

from __future__ import annotations

import importlib
import re
import warnings
from pathlib import Path
from typing import Any

FAMILIES: tuple[tuple[str, str, str], ...] = (
    # (page name, title, one-line description)
    ("arm", "Arm: `rehab-reach` and `rehab-reach-l`",
     "One robot on the seated patient's hand: shoulder and elbow exercises, reaching "
     "(`rehab-reach`, right arm) or trajectory following (`rehab-reach-l`, left arm)."),
    ("hip", "Hip: `rehab-hip`",
     "One robot on the supine patient's distal shin: a straight-leg raise and hip flexion "
     "cycles, reaching six targets, the knee held extended."),
    ("knee", "Knee: `rehab-knee`",
     "One robot in front of the seated patient, on the distal shin: knee extension and knee "
     "flexion cycles along minimum-jerk trajectories."),
    ("bilateral", "Both arms: `rehab-bilateral`",
     "A robot on each hand of the seated patient, one policy for both: symmetric or "
     "alternating shoulder and elbow exercises (the paper's two-arm scene, its Figs. 2-3)."),
    ("conditions", "Patients with conditions: the variant ids",
     "The base `-v1`/`-v2` ids with an impaired patient: spasticity, tremor, weakness, "
     "contracture, an active or resisting patient (`docs/conditions.md`). Same spaces and "
     "reward as the base id."),
    ("populations", "Patient populations",
     "A new patient (profile x condition) every episode, drawn from the `\"train\"` "
     "population; `patients=\"test\"` gives held-out patients."),
    ("myo", "The musculoskeletal patient: the `-myo` ids",
     "The base `-v2` knee, hip and right-arm reach ids with MyoSuite's legs (80 muscles) or "
     "right arm (63) (`patient_model=\"myo\"`; `pip install \"rehabbot[myo]\"`; "
     "`docs/musculoskeletal-patient.md`). Same spaces and reward as the base id; the muscles "
     "are in `info`, and the patient's conditions act on them."),
)

VERSIONS = {
    "v0": "the paper's reward, eq. (5), and observation (its reference)",
    "v1": "the learnable progress reward, the paper's observation",
    "v2": "the `-v1` task and reward, actions in `Box(-1, 1)`, an observation any learner "
          "can use (start here)",
}


def family_of(env_id: str, entry_point: str, kwargs: dict[str, Any]) -> str:
    """The family page an id belongs to."""
    if entry_point.endswith(":PopulationEnv"):
        return "populations"
    if entry_point.endswith(":BilateralEnv"):
        return "bilateral"
    if kwargs.get("patient_model") == "myo":
        return "myo"
    if "condition" in kwargs:
        return "conditions"
    return {"arm": "arm", "hip": "hip", "knee": "knee"}[kwargs.get("limb", "arm")]


def qualify(target: str, module: Any) -> str:
    """A role's target as a full dotted path: a short name (``PatientPopulation``,
    ``PopulationEnv.build_all``) is looked up among the module's names."""
    tilde = target.startswith("~")
    name = target.lstrip("~")
    head, _, rest = name.partition(".")
    obj = getattr(module, head, None)
    if obj is None or not hasattr(obj, "__qualname__") or name.startswith("rehabbot."):
        return target
    full = f"{obj.__module__}.{obj.__qualname__}" + (f".{rest}" if rest else "")
    return "~" + full if (tilde or not rest) else full


def rst_roles_to_myst(text: str, module: Any = None) -> str:
    """``:class:`x``` (reStructuredText) -> ``{class}`x``` (MyST), with short targets made
    full dotted paths."""
    return re.sub(r"(?<![\w`]):([a-z]+):`([^`]+)`",
                  lambda m: f"{{{m.group(1)}}}`{qualify(m.group(2), module)}`", text)


def docstring_as_markdown(module_name: str, heading_offset: int = 1) -> str:
    """The module docstring of an env, as MyST Markdown with its headings moved down."""
    module = importlib.import_module(module_name)
    text = rst_roles_to_myst(module.__doc__ or "", module)
    lines = []
    for line in text.splitlines():
        match = re.match(r"(#+) (.*)", line)
        if match:
            line = "#" * (len(match.group(1)) + heading_offset - 1) + " " + match.group(2)
        lines.append(line)
    first, _, rest = "\n".join(lines).partition("\n\n")  # the summary paragraph comes first
    return first.strip() + "\n\n" + rest


def describe_space(space: Any) -> str:
    """A short, exact description of a Gymnasium space (Box bounds only when uniform)."""
    import numpy as np

    name = type(space).__name__
    shape = getattr(space, "shape", None)
    dtype = getattr(space, "dtype", None)
    low, high = getattr(space, "low", None), getattr(space, "high", None)
    if low is not None and np.all(low == low.flat[0]) and np.all(high == high.flat[0]):
        return f"`{name}({low.flat[0]:.4g}, {high.flat[0]:.4g}, {shape}, {dtype})`"
    if low is not None:
        return f"`{name}({shape}, {dtype})`, per-entry bounds"
    return f"`{space}`"


def registered_ids() -> list[dict[str, Any]]:
    """Every ``rehabbot/`` id with its registration and the spaces of the env it makes."""
    import gymnasium as gym

    import rehabbot  # noqa: F401  (registers the ids)
    from rehabbot.envs.registration import MYO_VARIANTS

    rows = []
    for env_id, spec in gym.registry.items():
        if not env_id.startswith("rehabbot/"):
            continue
        entry_point = str(spec.entry_point)
        kwargs = dict(spec.kwargs)
        # A -myo id has its base id's spaces (tests/test_myo_patient.py checks it): they are
        # read from the base id, so that the docs build needs no [myo] extra and no muscles.
        made_as = MYO_VARIANTS.get(env_id, env_id)
        with warnings.catch_warnings():  # Gymnasium advises -v2 for the -v0 and -v1 ids
            warnings.simplefilter("ignore")
            env = gym.make(made_as)
        try:
            observation, action = (describe_space(env.observation_space),
                                   describe_space(env.action_space))
        finally:
            env.close()
        rows.append({"id": env_id, "entry_point": entry_point, "kwargs": kwargs,
                     "max_episode_steps": spec.max_episode_steps,
                     "family": family_of(env_id, entry_point, kwargs),
                     "observation": observation, "action": action})
    return rows


def format_kwargs(kwargs: dict[str, Any]) -> str:
    return "<br>".join(f"`{key}={value!r}`" for key, value in kwargs.items()) or "-"


def ids_table(rows: list[dict[str, Any]], link_family: bool = False) -> str:
    """The ids' table, narrow enough for the page's column: the version is in the id, and the
    steps' header (the spec's ``max_episode_steps``) is words that wrap."""
    head = ["id", "registered kwargs", "max. episode steps", "observation space",
            "action space"]
    if link_family:
        head.insert(1, "family")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        cells = [f"`{row['id']}`", format_kwargs(row["kwargs"]),
                 str(row["max_episode_steps"]), row["observation"], row["action"]]
        if link_family:
            cells.insert(1, f"[{row['family']}]({row['family']}.md)")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_if_changed(path: Path, text: str) -> None:
    """Rewrite a page only when its text changed, so that Sphinx rebuilds only what changed."""
    if not path.is_file() or path.read_text(encoding="utf-8") != text:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")


GENERATED = ("<!-- generated by docs/_ext/env_pages.py from gymnasium.registry and the env "
             "classes' docstrings; edit those, not this file -->\n\n")


def write_pages(out_dir: Path) -> list[Path]:
    """Write the family pages and the page of every id into ``out_dir``; return their paths."""
    rows = registered_ids()
    versions = "\n".join(f"- `-{v}`: {text}" for v, text in VERSIONS.items())
    written = []
    for name, title, description in FAMILIES:
        family_rows = [row for row in rows if row["family"] == name]
        if not family_rows:
            continue
        classes = sorted({row["entry_point"] for row in family_rows})
        parts = [GENERATED + f"# {title}\n", description + "\n", "## The ids\n",
                 ids_table(family_rows) + "\n",
                 "`gym.make(id, **kwargs)` accepts every argument of the class below on top of "
                 "the registered ones.\n\n" + versions + "\n"]
        for entry_point in classes:
            module_name, class_name = entry_point.split(":")
            parts.append(f"## {class_name} (`{module_name}`)\n")
            if class_name == "PopulationEnv":
                parts.append(docstring_as_markdown(module_name, heading_offset=2))
                parts.append("Each patient's env is a `RehabEnv`: its spaces, rewards, episode "
                             "end and arguments are on the [arm](arm.md) and [knee](knee.md) "
                             "pages.\n")
            else:
                parts.append(docstring_as_markdown(module_name, heading_offset=2))
        path = out_dir / f"{name}.md"
        write_if_changed(path, "\n".join(parts))
        written.append(path)
    every = [GENERATED + "# Every registered id\n",
             f"`import rehabbot` registers {len(rows)} Gymnasium ids. Each family's page has "
             "the env's spaces, rewards, episode end and arguments.\n", versions + "\n",
             ids_table(rows, link_family=True) + "\n"]
    path = out_dir / "ids.md"
    write_if_changed(path, "\n".join(every))
    written.append(path)
    return written


def _generate(app: Any) -> None:
    write_pages(Path(app.srcdir) / "_generated" / "envs")


def setup(app: Any) -> dict[str, Any]:
    app.connect("builder-inited", _generate)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
