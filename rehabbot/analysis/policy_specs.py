"""What the clinical evaluator accepts as a policy, resolved against the env it makes.

================================= ===============================================================
spec                              resolved to
================================= ===============================================================
``"expert"``, ``"aan"``,          the named policies of :func:`rehabbot.rl.policies.load_policy`
``"random"``, a model path,
``"zoo:ENV/ALGO"``
``"module:attr"``                 the attribute ``attr`` of the imported module ``module`` (the
                                  current folder is importable), then as an object below
an object with ``predict``        used as it is: SB3's ``predict(obs, deterministic=...) ->
                                  (action, state)``; one that holds another env (an
                                  ``AssistAsNeeded(env)`` built on the user's env) is refused:
                                  it would read that env's state, so pass its class
a class, or a callable without    called once with the evaluator's env, ``factory(env)``; what it
``predict`` (a factory)           returns must have ``predict`` (``AssistAsNeeded``,
                                  ``ScriptedExpert`` and ``lambda env: MyPolicy(env)`` all work)
================================= ===============================================================

A custom policy's label (its output folder) is its ``label`` attribute if it has one, else its
class's name. Every mistake (a module that is not found, a missing attribute, an object without
``predict``, a factory that fails) is a :class:`~rehabbot.common.errors.UsageError` naming the
spec.
"""

from __future__ import annotations

import importlib
import os
import re
import sys
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym

from rehabbot.common.errors import UsageError
from rehabbot.rl.policies import LoadedPolicy, load_policy
from rehabbot.rl.zoo import is_zoo_spec

PolicySpec = str | Any  # a name (see the module docstring), a policy object or a factory
MODULE_ATTR_RE = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")
CUSTOM_KIND = "custom"


def is_module_spec(spec: Any) -> bool:
    """Whether ``spec`` is a ``module:attr`` string (not ``zoo:...``, not an existing file)."""
    return (isinstance(spec, str) and not is_zoo_spec(spec) and MODULE_ATTR_RE.match(spec)
            is not None and not os.path.exists(spec))


def is_named_spec(spec: Any) -> bool:
    """Whether ``spec`` is one of :func:`rehabbot.rl.policies.load_policy`'s names: a keyword,
    a model path or a zoo agent (the specs that may name the env to run in)."""
    return isinstance(spec, (str, os.PathLike)) and not is_module_spec(spec)


def describe_spec(spec: Any) -> str:
    """``spec`` as the user would recognise it in a message."""
    if isinstance(spec, (str, os.PathLike)):
        return repr(str(spec))
    return f"{type(spec).__name__} object" if not isinstance(spec, type) else spec.__name__


def import_attribute(spec: str) -> Any:
    """The object ``module:attr`` names (``attr`` may be dotted), imported with the current
    folder importable.

    Raises:
        UsageError: the module is not found, or has no such attribute (naming ``spec``).
    """
    module_name, _, attr = spec.partition(":")
    added = os.getcwd() not in sys.path and "" not in sys.path
    if added:
        sys.path.insert(0, os.getcwd())
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as err:
        if err.name is not None and module_name.startswith(err.name):
            raise UsageError(f"policy {spec!r}: no module named {err.name!r} (give "
                             "module:attr with the module importable from the current folder "
                             "or PYTHONPATH)") from err
        raise UsageError(f"policy {spec!r}: importing {module_name!r} failed: {err}") from err
    finally:
        if added:
            sys.path.remove(os.getcwd())
    value: Any = module
    for part in attr.split("."):
        if not hasattr(value, part):
            raise UsageError(f"policy {spec!r}: module {module_name!r} has no attribute "
                             f"{attr!r}")
        value = getattr(value, part)
    return value


def custom_label(policy: Any) -> str:
    """A custom policy's label: its ``label`` attribute (a string), else its class name."""
    label = getattr(policy, "label", None)
    if label is None:
        return type(policy).__name__
    if not isinstance(label, str):
        raise UsageError(f"policy {type(policy).__name__}: its label {label!r} must be a "
                         "string")
    return label


def bound_env(policy: Any) -> gym.Env | None:
    """The env a policy object holds among its attributes (``ScriptedExpert``,
    ``AssistAsNeeded``: ``.env``), None if it holds none."""
    for value in vars(policy).values() if hasattr(policy, "__dict__") else ():
        if isinstance(value, gym.Env):
            return value
    return None


def _from_object(value: Any, env: gym.Env, shown: str) -> Any:
    """``value`` itself if it has ``predict`` (and is not a class), else ``value(env)``."""
    if not isinstance(value, type) and callable(getattr(value, "predict", None)):
        held = bound_env(value)
        if held is not None and held.unwrapped is not env.unwrapped:
            name = type(value).__name__
            raise UsageError(f"policy {shown}: it reads the state of the env it was built "
                             "with, not of the env the evaluator runs; pass the class "
                             f"({name}) or a factory (lambda env: {name}(env, ...)) instead, "
                             "and the evaluator builds it with its own env")
        return value
    if not callable(value):
        raise UsageError(f"policy {shown}: a {type(value).__name__} has no predict(obs, "
                         "deterministic=...) method and is not a class or factory taking the "
                         "env")
    try:
        policy = value(env)
    except (ValueError, TypeError) as err:
        raise UsageError(f"policy {shown}: calling it with the env failed ({type(err).__name__}: "
                         f"{err}); a class or factory must take the env as its one "
                         "argument") from err
    if not callable(getattr(policy, "predict", None)):
        raise UsageError(f"policy {shown}: called with the env, it returned a "
                         f"{type(policy).__name__}, which has no predict(obs, deterministic=...) "
                         "method")
    return policy


def resolve_policy(spec: PolicySpec, env: gym.Env, seed: int | None = None) -> LoadedPolicy:
    """The policy ``spec`` names (see the module docstring), ready to act in ``env``."""
    if is_named_spec(spec):
        return load_policy(spec, env, seed=seed)
    shown = repr(spec) if isinstance(spec, str) else describe_spec(spec)
    value = import_attribute(spec) if isinstance(spec, str) else spec
    policy = _from_object(value, env, shown)
    loaded = LoadedPolicy(policy=policy, label=custom_label(policy), kind=CUSTOM_KIND)
    if isinstance(spec, str):
        loaded.model_path = None
        loaded.manifest = {"spec": spec}
    return loaded


def check_distinct_labels(policies: Sequence[LoadedPolicy]) -> None:
    """``UsageError`` if two policies share a label (their files would go to one folder)."""
    seen: set[str] = set()
    for policy in policies:
        if policy.label in seen:
            raise UsageError(f"two policies are labelled {policy.label!r}; their results would "
                             "share one folder (give each custom policy a distinct `label` "
                             "attribute, or evaluate them separately)")
        seen.add(policy.label)


Factory = Callable[[gym.Env], Any]
