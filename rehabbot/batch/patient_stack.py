"""The patients of a batched env, side by side: one for a single-patient id, every patient of
the population for a population id (``rehab-reach-population-v2``, ``rehab-knee-population-v2``;
:class:`rehabbot.envs.population.PopulationEnv`). Each world draws its patient at every
reset, as the CPU population env draws one per episode.

Every patient's tables come from its own CPU env (:func:`rehabbot.batch.env_tables.read_tables`).
What differs between patients (the profile moves the robot's base, the targets, the home
state, the ranges and the agent observation's scaling; the condition the joints' stiffness,
damping and ranges) is stacked along a leading patient axis; everything else must be the same
for every patient, and is checked. The MuJoCo model fields that differ between patients or
weight levels reach MuJoCo Warp as per-world model fields, indexed ``[patient, level]``.

The tables need only NumPy; the models are put on MuJoCo Warp through MJX.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import jax
import mujoco
import numpy as np

from rehabbot.batch.env_tables import EnvTables
from rehabbot.batch.padding import LAST, stack_padded
from rehabbot.sim.scene import WEIGHT_LEVELS

# The tables that differ between patients (a profile or a condition changes them): stacked
# along a leading patient axis. Every other table must be equal for all patients.
PER_PATIENT_FIELDS: tuple[str, ...] = (
    "setpoint_low_rad", "setpoint_high_rad", "home_qpos", "home_setpoints_rad", "base_pos_m",
    "healthy_low", "healthy_high", "targets_rad", "tool_targets_m", "num_targets",
    "rests_rad", "rom_low_rad", "rom_high_rad", "agent_matrix", "segments_rad",
)
# Per-patient tables with a target axis (second in the patient's own array): patients with
# fewer targets are padded with their last target, the rests and segments after it with 0.
TARGET_FIELDS: tuple[str, ...] = ("targets_rad", "tool_targets_m", "rests_rad", "segments_rad")
ZERO_PADDED_FIELDS: frozenset[str] = frozenset({"rests_rad", "segments_rad"})
# MuJoCo Warp model fields that may differ between patients although MuJoCo Warp does not
# batch them: the dof lengths, read by MuJoCo Warp's sleep only (refused where a model
# enables sleep). Every world gets the first patient's.
UNBATCHED_UNUSED_FIELDS: frozenset[str] = frozenset({"dof_length"})


@dataclass(frozen=True)
class PatientStack:
    """The tables of ``count`` patients: ``shared`` holds the first patient's tables (every
    field not in :data:`PER_PATIENT_FIELDS` is the same for all), ``arrays`` the per-patient
    fields stacked ``(count, ...)``, and ``models`` the MJX model of every patient and
    weight level (:class:`ModelRows`)."""

    shared: EnvTables
    arrays: dict[str, np.ndarray]
    models: ModelRows

    @property
    def count(self) -> int:
        return int(self.arrays["num_targets"].shape[0])


def _equal(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and bool(np.array_equal(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    return a == b


def _stack_arrays(tables: Sequence[EnvTables]) -> dict[str, np.ndarray]:
    count = max(t.targets_rad.shape[1] for t in tables)
    arrays: dict[str, np.ndarray] = {}
    for name in PER_PATIENT_FIELDS:
        rows = [np.asarray(getattr(t, name)) for t in tables]
        if name in TARGET_FIELDS:
            fill = 0.0 if name in ZERO_PADDED_FIELDS else LAST
            rows = [stack_padded(list(r), count, fill) for r in rows]
        shapes = {r.shape for r in rows}
        if len(shapes) != 1:
            raise ValueError(f"the patients' {name} tables have different shapes {sorted(shapes)}")
        arrays[name] = np.stack(rows)
    return arrays


def _static_differences(a: Any, b: Any, prefix: str = "") -> list[str]:
    """The names of the static (non-array-leaf) fields in which two MJX models differ."""
    names = []
    for field in dataclasses.fields(a):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if dataclasses.is_dataclass(x):
            names += _static_differences(x, y, f"{prefix}{field.name}.")
        elif not isinstance(x, jax.Array) and not _equal_static(x, y):
            names.append(prefix + field.name)
    return names


def _equal_static(x: Any, y: Any) -> bool:
    if isinstance(x, tuple | list) and isinstance(y, tuple | list):
        return len(x) == len(y) and all(_equal_static(u, v) for u, v in zip(x, y, strict=True))
    return _equal(x, y)


def _without_unused(model: Any, base: Any) -> Any:
    """``model`` with base's values in the fields MuJoCo Warp leaves unused
    (:data:`UNBATCHED_UNUSED_FIELDS`)."""
    impl = model._impl
    kept = {name: getattr(base._impl, name) for name in UNBATCHED_UNUSED_FIELDS
            if hasattr(impl, name)}
    return model.replace(_impl=impl.replace(**kept))


@dataclass(frozen=True)
class ModelRows:
    """The MJX model of every patient at every weight level, as one model and the leaves that
    differ: ``base`` (the first patient at level 0), its ``treedef``, and ``rows`` mapping a
    leaf's index among ``base``'s leaves to its values ``(patients, levels, ...)``; ``names``
    the differing leaves' paths. ``data_rows``: the fields of a fresh ``mjx.make_data`` that
    differ, which a reset must set per world as well."""

    base: Any
    treedef: Any
    rows: dict[int, np.ndarray]
    names: tuple[str, ...]
    # Data fields that mjx.make_data sets from the model and that a step does not recompute
    # (the world body's geoms: a profile moves the chair), by name: (patients, levels, ...).
    data_rows: dict[str, np.ndarray]


def model_rows(envs: Sequence[Any], physics_model: Callable[[Any], mujoco.MjModel]
               ) -> ModelRows:
    """Put every patient's model at every weight level on MuJoCo Warp (``mjx.put_model``,
    ``impl="warp"``) and keep the leaves that differ. ``physics_model(env)``: the MjModel the
    batched env steps for ``env`` (at its scene's current level). ``ValueError`` for a
    difference MuJoCo Warp cannot take per world (a static field, or a model field it does
    not batch); the fields of :data:`UNBATCHED_UNUSED_FIELDS` keep the first patient's."""
    from jax import tree_util
    from mujoco import mjx
    from mujoco.mjx.warp import types as warp_types

    batchable = warp_types._BATCH_DIM["Model"]  # MuJoCo Warp's per-world model fields
    sleeping = [env.model.opt.enableflags & mujoco.mjtEnableBit.mjENBL_SLEEP for env in envs]
    if any(sleeping):
        raise ValueError("a patient's model enables sleep, which reads dof_length: the "
                         "batched env does not take it per world")
    base, treedef = None, None
    leaves_of: list[list[list[np.ndarray]]] = []
    data_of: list[list[Any]] = []
    for k, env in enumerate(envs):
        scene, start = env.scene, env.scene.weight_level
        per_level, data_per_level = [], []
        for level in WEIGHT_LEVELS:
            scene.set_weight_level(level)
            mj_model = physics_model(env)
            data_per_level.append(mjx.make_data(mj_model, impl="warp", naconmax=1, njmax=1))
            model = mjx.put_model(mj_model, impl="warp")
            if base is None:
                base = model
            model = _without_unused(model, base)
            leaves, tree = tree_util.tree_flatten(model)
            if treedef is None:
                treedef = tree
            elif tree != treedef:
                raise ValueError(f"patient {k} at weight level {level}: the model differs from "
                                 f"patient 0's in {_static_differences(model, base)}, which "
                                 "MuJoCo Warp cannot take per world")
            per_level.append([np.asarray(leaf) for leaf in leaves])
        scene.set_weight_level(start)
        leaves_of.append(per_level)
        data_of.append(data_per_level)
    paths = [tree_util.keystr(path) for path, _ in tree_util.tree_flatten_with_path(base)[0]]
    rows: dict[int, np.ndarray] = {}
    for i, first in enumerate(leaves_of[0][0]):
        values = np.stack([np.stack([level[i] for level in patient]) for patient in leaves_of])
        if np.all(values == first):
            continue
        name = paths[i].rsplit(".", 1)[-1]
        if not batchable.get(name, True):
            raise ValueError(f"the patients' or weight levels' models differ in {paths[i]}, "
                             "which MuJoCo Warp does not take per world")
        rows[i] = values
    return ModelRows(base=base, treedef=treedef, rows=rows,
                     names=tuple(paths[i] for i in rows), data_rows=_data_rows(data_of))


def _data_rows(data_of: list[list[Any]]) -> dict[str, np.ndarray]:
    """The top-level fields of the patients' and levels' fresh MJX data that differ,
    ``(patients, levels, ...)``; ``ValueError`` for a differing field of MuJoCo Warp's own."""
    first = data_of[0][0]
    rows: dict[str, np.ndarray] = {}
    for field in dataclasses.fields(first):
        value = getattr(first, field.name)
        if field.name == "_impl":
            for name in dataclasses.fields(value):
                impl_first = np.asarray(getattr(value, name.name))
                if any(not _equal(np.asarray(getattr(d._impl, name.name)), impl_first)
                       for per_level in data_of for d in per_level):
                    raise ValueError(f"the patients' fresh data differ in _impl.{name.name}, "
                                     "which the batched reset does not set per world")
            continue
        if not isinstance(value, jax.Array):
            continue
        values = np.stack([np.stack([np.asarray(getattr(d, field.name)) for d in per_level])
                           for per_level in data_of])
        if not np.all(values == np.asarray(value)):
            rows[field.name] = values
    return rows


def stack_patients(tables: Sequence[EnvTables], envs: Sequence[Any],
                   physics_model: Callable[[Any], mujoco.MjModel]) -> PatientStack:
    """The patients' tables side by side (module docstring). ``tables`` and ``envs``: each
    patient's, in the population's order; ``physics_model(env)``: the MjModel the batched
    env steps for a patient's CPU env. ``ValueError`` names a table that differs between
    patients but cannot (the scene's structure, the control, the reward's settings)."""
    if not tables or len(tables) != len(envs):
        raise ValueError(f"{len(tables)} patients' tables and {len(envs)} envs")
    models = [env.model for env in envs]
    per_patient = set(PER_PATIENT_FIELDS)
    for field in dataclasses.fields(EnvTables):
        if field.name in per_patient:
            continue
        first = getattr(tables[0], field.name)
        for k, t in enumerate(tables[1:], start=1):
            if not _equal(first, getattr(t, field.name)):
                raise ValueError(f"patient {k}'s {field.name} differs from patient 0's, which "
                                 "the batched env cannot take per world")
    for name in ("nq", "nv", "nu", "nbody", "ngeom", "njnt", "nsite", "neq"):
        sizes = {int(getattr(m, name)) for m in models}
        if len(sizes) != 1:
            raise ValueError(f"the patients' scenes differ in {name} {sorted(sizes)}")
    return PatientStack(shared=tables[0], arrays=_stack_arrays(tables),
                        models=model_rows(envs, physics_model))
