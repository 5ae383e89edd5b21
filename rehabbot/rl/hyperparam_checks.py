"""Checks of single hyperparameter values, before anything trains: the valid range of each
numeric constructor argument (:data:`VALUE_RANGES`, with the strings and ``None`` some of them
also take), booleans for :data:`BOOL_KEYS`, ``train_freq`` as ``n`` or ``[n, unit]``, no NaN or
infinity anywhere (:func:`check_value`); numbers written as YAML strings (:func:`coerce_number`),
counts (:func:`as_count`) and ``"lin_<float>"`` schedules (:func:`parse_schedule`); values as
JSON (:func:`jsonable`, classes by dotted name).

:mod:`rehabbot.rl.hyperparams` reads whole files and mappings with these.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

from rehabbot.common.errors import UsageError


class HyperparameterError(UsageError):
    """A bad hyperparameter file, key or value; the message names the file and the key."""


# Keys that may also be "lin_<initial value>" (a linear schedule down to 0).
SCHEDULE_KEYS = ("learning_rate", "clip_range", "clip_range_vf")
# key -> (low, high, low_open, integer): the ranges of the numeric constructor arguments,
# checked before training (a learning rate of -1, a gamma of 2 or an infinite entropy
# coefficient used to train to completion; a NaN learning rate failed later as a "non-finite
# action"). Bools, NaN and infinities are refused for every key. Keys that also take a
# string or None: see _SPECIAL_VALUES.
VALUE_RANGES: dict[str, tuple[float, float, bool, bool]] = {
    "learning_rate": (0.0, 1.0, True, False),
    "gamma": (0.0, 1.0, True, False),
    "gae_lambda": (0.0, 1.0, False, False),
    "tau": (0.0, 1.0, True, False),
    "ent_coef": (0.0, math.inf, False, False),
    "vf_coef": (0.0, math.inf, False, False),
    "max_grad_norm": (0.0, math.inf, True, False),
    "clip_range": (0.0, math.inf, True, False),
    "clip_range_vf": (0.0, math.inf, True, False),
    "target_kl": (0.0, math.inf, True, False),
    "target_policy_noise": (0.0, math.inf, False, False),
    "target_noise_clip": (0.0, math.inf, False, False),
    "target_entropy": (-math.inf, math.inf, False, False),
    "batch_size": (1, math.inf, False, True),
    "buffer_size": (1, math.inf, False, True),
    "n_steps": (1, math.inf, False, True),
    "n_epochs": (1, math.inf, False, True),
    "learning_starts": (0, math.inf, False, True),
    "gradient_steps": (1, math.inf, False, True),
    "policy_delay": (1, math.inf, False, True),
    "target_update_interval": (1, math.inf, False, True),
    "sde_sample_freq": (1, math.inf, False, True),
    "top_quantiles_to_drop_per_net": (0, math.inf, False, True),
    "stats_window_size": (1, math.inf, False, True),
}
# Non-numeric values a key of VALUE_RANGES also takes (as SB3 reads them).
_SPECIAL_VALUES: dict[str, tuple[Any, ...]] = {
    "ent_coef": ("auto",),  # and "auto_<initial value>"
    "target_entropy": ("auto",),
    "clip_range_vf": (None,),
    "target_kl": (None,),
    "gradient_steps": (-1,),  # as many gradient steps as env steps
    "sde_sample_freq": (-1,),  # only at the start of each rollout
}
BOOL_KEYS = ("use_sde", "use_sde_at_warmup", "normalize_advantage", "optimize_memory_usage",
             "share_features_extractor")
TRAIN_FREQ_UNITS = ("step", "episode")
_NUMBER_RE = re.compile(r"^[+-]?(?:\d[\d_]*(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?$")
_INT_RE = re.compile(r"^[+-]?\d[\d_]*$")


def coerce_number(value: Any) -> Any:
    """``"3e-4"`` -> 0.0003 and ``"1_000"`` -> 1000 (PyYAML reads ``3e-4`` as a string)."""
    if isinstance(value, str) and _NUMBER_RE.match(value.strip()):
        text = value.strip().replace("_", "")
        return int(text) if _INT_RE.match(text) else float(text)
    return value


def as_count(value: Any, what: str, minimum: int = 1,
             error: type[Exception] = HyperparameterError) -> int:
    """``value`` as an integer >= ``minimum`` (``"1e5"`` and ``100000.0`` count too); else
    ``error`` naming ``what``."""
    number = coerce_number(value)
    if isinstance(number, float) and number.is_integer():
        number = int(number)
    if isinstance(number, bool) or not isinstance(number, int) or number < minimum:
        raise error(f"{what} must be an integer >= {minimum}, got {value!r}")
    return number


def _range_text(key: str, extras: bool = True) -> str:
    low, high, low_open, integer = VALUE_RANGES[key]
    kind = "an integer" if integer else "a finite number"
    if low == -math.inf and high == math.inf:
        bounds = ""
    elif high == math.inf:
        bounds = f" {'>' if low_open else '>='} {low:g}"
    else:
        bounds = f" in {'(' if low_open else '['}{low:g}, {high:g}]"
    extra = [repr(v) for v in _SPECIAL_VALUES.get(key, ())]
    if key == "ent_coef":
        extra.append("'auto_<initial value>'")
    if key in ("learning_rate", "clip_range", "clip_range_vf"):
        extra.append("'lin_<initial value>'")
    return kind + bounds + (f" (or {', '.join(extra)})" if extra and extras else "")


def _in_range(key: str, value: Any) -> bool:
    low, high, low_open, integer = VALUE_RANGES[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    if not math.isfinite(value) or value < low or value > high or (low_open and value <= low):
        return False
    return not integer or float(value).is_integer()


def check_value(key: str, value: Any, where: str) -> Any:
    """``value`` of constructor argument ``key`` (after :func:`coerce_number`), or
    :class:`HyperparameterError` naming the key, the value and the valid range: the ranges of
    :data:`VALUE_RANGES`, booleans for :data:`BOOL_KEYS`, ``train_freq`` as ``n`` or
    ``[n, "step"|"episode"]``, and no NaN or infinity anywhere."""
    def refuse(what: str) -> HyperparameterError:
        return HyperparameterError(f"{where}: {key}={value!r} must be {what}")

    if key in VALUE_RANGES:
        if value in _SPECIAL_VALUES.get(key, ()) and not isinstance(value, bool):
            return value
        text = value.strip() if isinstance(value, str) else None
        if text is not None and key == "ent_coef" and text.startswith("auto_"):
            start = coerce_number(text[len("auto_"):])
            if not _in_range(key, start) or start <= 0:
                raise refuse("'auto_<initial value>' with an initial value that is a finite "
                             "number > 0")
            return value
        if text is not None and text.startswith("lin_") and key in SCHEDULE_KEYS:
            start = coerce_number(text[len("lin_"):])
            if not _in_range(key, start):
                raise refuse("'lin_<initial value>' with an initial value that is "
                             + _range_text(key, extras=False))
            return value
        if callable(value) and key in SCHEDULE_KEYS:
            return value  # a schedule given from Python
        if not _in_range(key, value):
            raise refuse(_range_text(key))
        return value
    if key in BOOL_KEYS and not isinstance(value, bool):
        raise refuse("true or false")
    if key == "train_freq":
        freq, unit = (value, "step") if not isinstance(value, (list, tuple)) else (
            tuple(value) if len(value) == 2 else (None, None))
        if isinstance(freq, float) and freq.is_integer():
            freq = int(freq)
        if isinstance(freq, bool) or not isinstance(freq, int) or freq < 1 \
                or unit not in TRAIN_FREQ_UNITS:
            raise refuse("an integer >= 1 or [n, 'step' | 'episode']")
        return value
    if isinstance(value, float) and not math.isfinite(value):
        raise refuse("a finite number")
    return value


def parse_schedule(value: Any, key: str, where: str) -> Any:
    """``"lin_<float>"`` as SB3's linear schedule from that value to 0; any other value as
    it is."""
    if isinstance(value, str) and value.strip().startswith("lin_"):
        try:
            start = float(value.strip()[len("lin_"):])
        except ValueError as err:
            raise HyperparameterError(f"{where}: {key}: bad linear schedule {value!r} "
                                "(expected lin_<float>, e.g. lin_3e-4)") from err
        if not math.isfinite(start):
            raise HyperparameterError(f"{where}: {key}: bad linear schedule {value!r}")
        from stable_baselines3.common.utils import LinearSchedule

        # progress_remaining goes 1 -> 0 over the run: start -> 0, linearly.
        return LinearSchedule(start, 0.0, 1.0)
    return value


def jsonable(value: Any) -> Any:
    """A JSON-able version of a hyperparameter value (classes by dotted name)."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return value if math.isfinite(value) else repr(value)
    if isinstance(value, Mapping):
        return {str(key): jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(item) for item in value]
    if isinstance(value, type):
        return f"{value.__module__}.{value.__qualname__}"
    if callable(value) and isinstance(getattr(value, "__qualname__", None), str):
        return f"{value.__module__}.{value.__qualname__}"  # e.g. flax.linen.relu
    item = getattr(value, "item", None)
    if callable(item) and getattr(value, "shape", None) == ():
        return jsonable(item())
    return repr(value)
