"""The bounds of the numbers the ``train``, ``demo``, ``render``, ``sweep``, ``view`` and
``snapshot`` commands take, as argparse types (:func:`rehabbot.cli.errors.bounded_int`,
:func:`~rehabbot.cli.errors.bounded_float`): a value outside them (``0`` steps, ``-1``
episodes, ``1e26`` steps, ``nan`` seconds) is a usage error naming the option and the value,
before any work starts.

Why these bounds:

- seeds below ``2**31``, and step counts below ``2**31`` too: a run seeds its model with the
  seed plus the steps done, which NumPy's legacy seeding (used by Stable-Baselines3) takes only
  below ``2**32``;
- images up to the scenes' offscreen buffer, 1280 x 960 px (``rehabbot.sim.scene_build``; a
  test checks the two agree);
- the patient's height and mass, and the wrist weight level, by the library's own ranges
  (:data:`rehabbot.sim.patient.HEIGHT_RANGE_M`, ``MASS_RANGE_KG``,
  :data:`rehabbot.sim.scene.WEIGHT_LEVELS`), read when the option is given (importing them
  imports MuJoCo, which ``rehabbot --help`` does not);
- the other counts at values far beyond any use that still finish (10 000 evaluation
  episodes, 100 000 expert episodes, 2**20 parallel envs).
"""

from __future__ import annotations

from collections.abc import Callable

from rehabbot.cli.errors import bounded_float, bounded_int

MAX_SEED = 2**31 - 1
MAX_TIMESTEPS = 2**31 - 1
MAX_N_ENVS = 2**20  # CPU envs, or the batched backend's worlds
MAX_EPISODES = 10_000
MAX_DEMOS = 100_000
MAX_TIME_LIMIT_S = 1e7  # about 115 days
MAX_VIEW_SECONDS = 86_400.0
MAX_FRAME_EVERY = 10_000  # beyond the longest episode: one frame
MAX_IMAGE_WIDTH_PX = 1280  # the scenes' offscreen buffer (rehabbot.sim.scene_build)
MAX_IMAGE_HEIGHT_PX = 960
MAX_CPUS = 4096

seed = bounded_int(0, MAX_SEED)
timesteps = bounded_int(1, MAX_TIMESTEPS)
step_period = bounded_int(0, MAX_TIMESTEPS)  # a frequency in env steps; 0: never
n_envs = bounded_int(1, MAX_N_ENVS)
episodes = bounded_int(1, MAX_EPISODES)
demos = bounded_int(0, MAX_DEMOS)
time_limit_s = bounded_float(0.0, MAX_TIME_LIMIT_S, low_open=True)
view_seconds = bounded_float(0.0, MAX_VIEW_SECONDS, low_open=True)
frame_every = bounded_int(1, MAX_FRAME_EVERY)
width_px = bounded_int(1, MAX_IMAGE_WIDTH_PX)
height_px = bounded_int(1, MAX_IMAGE_HEIGHT_PX)
cpus = bounded_int(1, MAX_CPUS)


def _library_range(name: str) -> tuple[float, float]:
    if name == "weight_level":
        from rehabbot.sim.scene import WEIGHT_LEVELS

        return min(WEIGHT_LEVELS), max(WEIGHT_LEVELS)
    from rehabbot.sim.patient import HEIGHT_RANGE_M, MASS_RANGE_KG

    return {"height_m": HEIGHT_RANGE_M, "mass_kg": MASS_RANGE_KG}[name]


def library_float(name: str) -> Callable[[str], float]:
    """A number in the library's range for ``name`` (``height_m``, ``mass_kg``)."""

    def parse(text: str) -> float:
        low, high = _library_range(name)
        return bounded_float(low, high)(text)

    parse.__name__ = "float"
    return parse


def library_int(name: str) -> Callable[[str], int]:
    """An integer in the library's range for ``name`` (``weight_level``)."""

    def parse(text: str) -> int:
        low, high = _library_range(name)
        return bounded_int(int(low), int(high))(text)

    parse.__name__ = "int"
    return parse
