"""``PopulationEnv``: a new patient every episode, drawn from a :class:`PatientPopulation`.

## Description
The env holds one :class:`~rehabbot.envs.rehab_env.RehabEnv` per patient of the population
(every pair of its profiles and conditions), each built the first time it is drawn, and
passes every ``reset``, ``step`` and ``render`` to the patient of the episode. The spaces are
the same for every patient of an id (checked as each is built), so one policy serves them all.

## Arguments

==================== ======================================================================
``patients``         default ``"train"``: a
                     :class:`~rehabbot.sim.populations.PatientPopulation`, a dict of its
                     fields, or the name of a shipped one (``"train"``, ``"test"``;
                     :data:`rehabbot.sim.populations.POPULATIONS`), or of an envelope
                     cohort drawn for this env's limb and robot (``"envelope-train"``,
                     ``"envelope-validation"``, ``"envelope-test"``,
                     ``"envelope-test-conditions"``;
                     :mod:`rehabbot.sim.envelope`)
``conditions``       default ``None`` (all): the population's conditions to draw from, as
                     indices into ``population.conditions`` or the conditions themselves
                     (a ``PatientCondition`` or a dict of its fields), one or a sequence;
                     every profile is kept. ``conditions=3`` on ``"train"`` gives its three
                     profiles with MAS 2 only. The env's ``population`` is then that subset
                     (:meth:`~rehabbot.sim.populations.PatientPopulation.with_conditions`,
                     named ``"train[conditions 3]"``), and patient indices count in it.
                     ``ValueError`` names a bad or repeated entry and lists the valid ones.
                     The default draws exactly as before
``**kwargs``         every other keyword is a :class:`~rehabbot.envs.config.RehabEnvConfig`
                     field (not ``profile`` or ``condition``, which the population sets),
                     validated when the env is built
==================== ======================================================================

The ``-v2`` population ids (``rehab-reach-population-v2``, ``rehab-knee-population-v2``)
pass ``observation="agent"`` and ``action_scale="unit"`` to every patient's env: the agent
observation's space does not depend on the patient (its ranges are relative), so one policy
serves the population.

## Episodes
``reset(seed=s)`` seeds the env's ``np_random``; each reset draws the patient uniformly from it,
then resets that patient's env with a seed drawn from it too, so a seed fixes the whole
sequence of patients, exercises and weight levels. ``reset(options={"patient": k})`` picks
patient ``k`` (an index into :attr:`PatientPopulation.patients`); ``"exercise"`` and
``"weight_level"`` pass through. ``info["patient"]`` is the episode's patient index.

A patient who cannot do the exercises (``ValueError`` when its env is built) is reported with
its profile and condition the first time it is drawn; :meth:`PopulationEnv.build_all` builds
every patient at once to check a population up front. A population with ``skip_infeasible``
(the envelope cohorts: a heavy patient resisting at 15 % of its strength pushes harder than
the cuff may hold) leaves such a patient out instead: it is drawn again, and
``env.refused_patients`` maps its index to the reason. Drawing again keeps the draw uniform
over the patients the scene takes, and the same for a seed.

Each patient's env is built once, the first time it is drawn (about 0.1 s and 3 MB for a
one-limb scene), and kept: changing the patient per episode costs no scene rebuild
(``benchmarks/performance/patient_switch_throughput.py`` measures the cost against a fixed
patient).
"""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym

from rehabbot.common.checks import check_number, check_options
from rehabbot.envs.config import NUMBER_RANGES, RENDER_MODES, RehabEnvConfig
from rehabbot.envs.env_base import RESET_OPTIONS
from rehabbot.envs.rehab_env import RehabEnv
from rehabbot.envs.time_limit import MakeTimeLimit
from rehabbot.sim.populations import PatientPopulation, as_population

POPULATION_RESET_OPTIONS = (*RESET_OPTIONS, "patient")


class PopulationEnv(MakeTimeLimit, gym.Env):
    """A patient drawn from ``patients`` every episode (see the module docstring)."""

    metadata: ClassVar[dict] = {"render_modes": list(RENDER_MODES), "render_fps": 50}

    def __init__(self, patients: PatientPopulation | dict | str = "train",
                 conditions: Any = None, **kwargs: Any) -> None:
        for name in ("profile", "condition"):
            if name in kwargs:
                raise ValueError(f"PopulationEnv sets {name!r} from its population; pass "
                                 f"patients= (or conditions=, a subset of the population's) "
                                 f"instead of {name}=")
        self.config = RehabEnvConfig(**kwargs)  # ValueError naming a bad kwarg, now
        population = as_population(patients, self.config.limb, self.config.robot)
        self.population = population if conditions is None \
            else population.with_conditions(conditions)
        self._kwargs = dict(kwargs)
        self._envs: dict[int, RehabEnv] = {}
        self.refused_patients: dict[int, str] = {}
        self._patient = 0
        feasible = next((k for k in range(len(self.population.patients))
                         if not self._refuses(k)), None)
        if feasible is None:
            raise ValueError(f"no patient of population {self.population.name!r} can do these "
                             f"exercises: {self.refused_patients}")
        self._patient = feasible
        first = self._env_of(feasible)
        self.observation_space = first.observation_space
        self.action_space = first.action_space
        self.render_mode = first.render_mode
        self.metadata = dict(first.metadata)

    # -- Gymnasium API -------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = check_options(options, POPULATION_RESET_OPTIONS)
        patients = self.population.patients
        drawn = int(self.np_random.integers(len(patients)))
        patient = options.pop("patient", None)
        if patient is None:
            patient = drawn
            while self._refuses(patient):  # a patient the scene refuses is drawn again
                patient = int(self.np_random.integers(len(patients)))
        elif isinstance(patient, bool) or patient not in range(len(patients)):
            raise ValueError(f"patient={patient!r} is not one of {list(range(len(patients)))} "
                             f"(population {self.population.name!r})")
        env = self._env_of(int(patient))
        self._patient = int(patient)
        obs, info = env.reset(seed=int(self.np_random.integers(2**31 - 1)), options=options)
        info["patient"] = self._patient
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.current_env.step(action)
        info["patient"] = self._patient
        return obs, reward, terminated, truncated, info

    # ``step`` in its three parts (:meth:`rehabbot.envs.core.RehabEnvCore.prepare_step`), for
    # a vector env: the episode's patient's.
    def prepare_step(self, action) -> tuple[Any, int]:
        return self.current_env.prepare_step(action)

    def advance_physics(self) -> None:
        self.current_env.advance_physics()

    def finish_step(self, applied: tuple[Any, int]):
        obs, reward, terminated, truncated, info = self.current_env.finish_step(applied)
        info["patient"] = self._patient
        return obs, reward, terminated, truncated, info

    def render(self):
        return self.current_env.render()

    def close(self) -> None:
        for env in self._envs.values():
            env.close()

    # -- time limit ----------------------------------------------------------------------
    def set_time_limit(self, max_episode_steps: int) -> None:
        """Make ``max_episode_steps`` the horizon of every patient's env (built or not)."""
        low, high, _integer = NUMBER_RANGES["max_episode_steps"]
        limit = check_number("max_episode_steps", max_episode_steps, low, high, integer=True)
        if limit == self.config.max_episode_steps:
            return
        self.config = self.config.replace(max_episode_steps=limit)
        self._kwargs["max_episode_steps"] = limit
        for env in self._envs.values():
            env.set_time_limit(limit)

    # -- patients ------------------------------------------------------------------------
    @property
    def current_env(self) -> RehabEnv:
        """The env of the episode's patient."""
        return self._envs[self._patient]

    @property
    def current_patient(self) -> int:
        """The episode's patient: an index into ``population.patients``."""
        return self._patient

    def patient_env(self, k: int) -> RehabEnv:
        """Patient ``k``'s env (an index into ``population.patients``), built now if it was
        not yet (``ValueError`` for a bad index, or a patient who cannot do the exercises)."""
        if isinstance(k, bool) or k not in range(len(self.population.patients)):
            raise ValueError(f"patient={k!r} is not one of "
                             f"{list(range(len(self.population.patients)))} "
                             f"(population {self.population.name!r})")
        return self._env_of(int(k))

    def build_all(self) -> None:
        """Build every patient's env now (``ValueError`` for one who cannot do the
        exercises; with the population's ``skip_infeasible``, they are listed in
        :attr:`refused_patients` instead)."""
        for k in range(len(self.population.patients)):
            if not self._refuses(k):
                self._env_of(k)

    @property
    def feasible_patients(self) -> tuple[int, ...]:
        """The patients the scene takes, building every patient's env to find out."""
        self.build_all()
        return tuple(k for k in range(len(self.population.patients))
                     if k not in self.refused_patients)

    def _refuses(self, k: int) -> bool:
        """Whether the scene refuses patient ``k`` of a ``skip_infeasible`` population (its
        env is built to find out; the reason goes to :attr:`refused_patients`)."""
        if not self.population.skip_infeasible or k in self._envs:
            return False
        if k not in self.refused_patients:
            try:
                self._env_of(k)
            except ValueError as err:
                self.refused_patients[k] = str(err)
        return k in self.refused_patients

    def _env_of(self, k: int) -> RehabEnv:
        env = self._envs.get(k)
        if env is not None:
            return env
        if k in self.refused_patients:
            raise ValueError(self.refused_patients[k])
        profile, condition = self.population.patients[k]
        try:
            env = RehabEnv(profile=profile, condition=condition, **self._kwargs)
        except ValueError as err:
            raise ValueError(f"patient {k} of population {self.population.name!r} ({profile}, "
                             f"{condition.describe()}) cannot do these exercises: {err}") from err
        if self._envs:
            first = next(iter(self._envs.values()))
            if env.observation_space != first.observation_space \
                    or env.action_space != first.action_space:
                raise ValueError(f"patient {k} of population {self.population.name!r} has other "
                                 "spaces than the first patient's")
        self._envs[k] = env
        return env

    def __getattr__(self, name: str) -> Any:
        # Everything else (layout, target_sequence, robot, controller, dt, ...) is the
        # episode's patient's env's.
        envs = self.__dict__.get("_envs")
        if not envs:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return getattr(envs[self.__dict__["_patient"]], name)

