"""The whole trained models behind the zoo's agents (the SB3/SBX zips, critics and optimiser
state included), for fine-tuning: not shipped in the package, fetched once, verified by the
SHA-256 that each agent's metadata pins (``full_model_sha256``), and loaded without unpickling.

============================================ ==============================================
``load_full_model(env_id, algo)``            the model, ready for ``learn``; when it is not
                                             on this machine, a
                                             :class:`~rehabbot.rl.zoo.ZooError` with the
                                             ``rehabbot zoo fetch`` command that gets it
``find_full_model(env_id, algo)``            its verified file: beside the agent's ``.npz``
                                             (a zoo exported with ``rehabbot zoo export
                                             --full``), else in the cache
``fetch_full_model(env_id, algo, source)``   a verified copy from ``source`` into the cache
                                             (``rehabbot zoo fetch ENV/ALGO --from SOURCE``)
``cache_dir()``                              ``$REHABBOT_CACHE_DIR``, else the platform's user
                                             cache folder (``~/.cache/rehabbot`` on Linux)
``ship_full_model(model_path, out_npz)``     copy a run's ``model.zip`` beside a zoo file
                                             (``rehabbot zoo export --full``)
============================================ ==============================================

**Why they are not in the package.** The zips of the ``-v2`` agents are many times the size
of their NumPy actors, and a core install cannot even load them (they need PyTorch or JAX):
every install would carry them for the few users who fine-tune
(``benchmarks/packaging/install_size.py`` measures it). The actors, which is what ``rehabbot
evaluate zoo:...`` and ``rehabbot.zoo.load`` run, stay in the package.

**Where a full model comes from** (``source``, tried in this order; every copy is hashed
and refused unless its SHA-256 is the agent's ``full_model_sha256``, so a source needs no
trust):

* an ``http://`` or ``https://`` URL: of the zip itself (``.../sac.zip``), or of a folder
  laid out as the zoo (``.../`` + ``<env>/<agent>.zip``);
* a ``.zip`` file (a release download, a run's ``model.zip``);
* a folder: ``<env>/<agent>.zip`` in it (an unpacked archive of the zoo), its
  ``rehabbot/zoo/<env>/<agent>.zip`` (a checkout that still holds the files), its
  ``model.zip`` (a run folder), and, when the folder is in a git clone of the rehabbot
  repository, that clone's history: commit :data:`HISTORY_COMMIT` holds every shipped
  agent's full model under ``rehabbot/zoo/``, so a clone gets them offline
  (``rehabbot zoo fetch --all --from .``).

The copy is written to the cache under a temporary name and renamed when verified (an
interrupted or refused fetch leaves nothing), as ``<cache>/full-models/<env>/<agent>-<first
16 hex digits of its SHA-256>.zip``: agents of two zoos with the same name never share a
file.
"""

from __future__ import annotations

import hashlib
import os
import re
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym

from rehabbot.common.errors import UsageError
from rehabbot.common.files import atomic_save_verified
from rehabbot.envs.registration import env_short_name
from rehabbot.rl.zoo import ZooError, agent_name, available, load

#: A commit of the rehabbot repository whose tree holds every shipped agent's full model, at
#: ``rehabbot/zoo/<env>/<agent>.zip`` (``tests/test_zoo.py`` checks each against its agent's
#: SHA-256 when it runs in a clone).
HISTORY_COMMIT = "cc3e26d1145b2d607f768c53869b74853987f946"
HISTORY_ZOO = "rehabbot/zoo"
CACHE_DIR_ENV = "REHABBOT_CACHE_DIR"
FULL_MODELS = "full-models"
SUFFIX = ".zip"
URL_SCHEMES = ("http://", "https://")
URL_TIMEOUT_S = 60.0
MAX_DOWNLOAD_BYTES = 1 << 30  # a full model is a few MB; a server sending more is refused
CHUNK_BYTES = 1 << 20
SHA256_RE = re.compile(r"^[0-9a-f]{64}$")

__all__ = ["CACHE_DIR_ENV", "HISTORY_COMMIT", "Fetched", "FullModel", "cache_dir",
           "fetch_command", "fetch_full_model", "find_full_model", "full_model", "full_models",
           "load_full_model", "ship_full_model"]


class SourceError(ZooError):
    """A source that does not hold the file, or cannot be read (names it and why)."""


# --------------------------------------------------------------------------- where


def cache_dir() -> Path:
    """``$REHABBOT_CACHE_DIR`` if set, else the user's cache folder: ``$XDG_CACHE_HOME`` or
    ``~/.cache`` on Linux (``rehabbot/`` in it), ``~/Library/Caches/rehabbot`` on macOS,
    ``%LOCALAPPDATA%\\rehabbot\\Cache`` on Windows."""
    override = os.environ.get(CACHE_DIR_ENV)
    if override:
        return Path(override).expanduser()
    home = Path.home()
    if sys.platform == "win32":
        local = os.environ.get("LOCALAPPDATA")
        return (Path(local) if local else home / "AppData" / "Local") / "rehabbot" / "Cache"
    if sys.platform == "darwin":
        return home / "Library" / "Caches" / "rehabbot"
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    return (Path(xdg) if Path(xdg).is_absolute() else home / ".cache") / "rehabbot"


@dataclass(frozen=True)
class FullModel:
    """What the zoo knows of an agent's full model: its name (``rehab-knee-v2/sac``), the
    SHA-256 its metadata pins, and the two places it is looked for."""

    env_id: str
    agent: str
    sha256: str
    beside: Path
    cached: Path
    metadata: dict

    @property
    def name(self) -> str:
        return f"{env_short_name(self.env_id)}/{self.agent}"

    @property
    def history_path(self) -> str:
        return f"{HISTORY_ZOO}/{env_short_name(self.env_id)}/{self.agent}{SUFFIX}"


def full_model(env_id: str, algo: str) -> FullModel:
    """The full model behind the zoo's agent ``env_id``/``algo`` (whether or not it is here).

    Raises:
        UsageError: no such agent, or an agent exported without its model (no
            ``full_model_sha256``: there is none to get).
        ZooError: a damaged agent file, or a ``full_model_sha256`` that is not a SHA-256.
    """
    policy = load(env_id, algo)
    meta = policy.metadata
    agent = agent_name(meta["algo"], meta.get("env_kwargs"), meta.get("backend"))
    name = f"{env_short_name(policy.env_id)}/{agent}"
    sha = meta.get("full_model_sha256")
    if sha is None:
        raise UsageError(f"the zoo keeps only the actor of {name} (it was exported without "
                         "--full, so there is no full model to load); load(...) gives the "
                         "actor")
    if not isinstance(sha, str) or not SHA256_RE.match(sha):
        raise ZooError(f"{policy.path} has full_model_sha256 {sha!r}, not a SHA-256")
    cached = cache_dir() / FULL_MODELS / env_short_name(policy.env_id) / f"{agent}-{sha[:16]}"
    return FullModel(env_id=policy.env_id, agent=agent, sha256=sha,
                     beside=policy.path.with_suffix(SUFFIX), cached=cached.with_suffix(SUFFIX),
                     metadata=meta)


def full_models() -> list[FullModel]:
    """Every agent of the zoo that has a full model, in the order of
    :func:`~rehabbot.rl.zoo.available`."""
    found = []
    for env_id, algo in available():
        if "full_model_sha256" in load(env_id, algo).metadata:
            found.append(full_model(env_id, algo))
    return found


def file_sha256(path: Path) -> str:
    """The SHA-256 of a file, read in chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        while chunk := stream.read(CHUNK_BYTES):
            digest.update(chunk)
    return digest.hexdigest()


def _verified(path: Path, model: FullModel) -> Path | None:
    """``path`` if it is there and is the model; None if it is not there.

    Raises:
        ZooError: it is there but its SHA-256 differs (naming it).
    """
    if not path.is_file():
        return None
    actual = file_sha256(path)
    if actual != model.sha256:
        raise ZooError(f"{path} is not the model this agent was exported from (its SHA-256 "
                       f"{actual} differs from the agent's full_model_sha256 "
                       f"{model.sha256}); delete it, then {fetch_command(model)}")
    return path


def find_full_model(env_id: str, algo: str) -> Path:
    """The verified file of the agent's full model: beside its ``.npz``, else in the cache.

    Raises:
        UsageError: the agent has no full model (:func:`full_model`).
        ZooError: it is not on this machine (the message gives the command that fetches
            it), or a copy whose SHA-256 differs.
    """
    return _find(full_model(env_id, algo))


def _find(model: FullModel) -> Path:
    for path in (model.beside, model.cached):
        if _verified(path, model) is not None:
            return path
    raise ZooError(f"the full model of {model.name} is not on this machine (looked for "
                   f"{model.beside} and {model.cached}); {fetch_command(model)}")


def load_full_model(env_id: str, algo: str, env: gym.Env | None = None) -> Any:
    """The trained model (SB3 or SBX, with its critics) behind the zoo's agent for ``env_id``
    and ``algo``, loaded without unpickling anything
    (:func:`rehabbot.rl.safe_load.load_safely`): ``model.learn(...)`` fine-tunes it. ``env``
    (default: the agent's env, made with its kwargs) gives the spaces and is the env it
    trains on. Needs the model's library (``rehabbot[train]`` or ``rehabbot[jax]``).

    Raises:
        UsageError: no such agent, or the zoo keeps only its actor.
        ZooError: the file is not on this machine (the message says how to fetch it), or is
            not the one the agent was exported with (SHA-256).
    """
    from rehabbot.rl.algorithms import algo_class
    from rehabbot.rl.safe_load import load_safely

    model = full_model(env_id, algo)
    path = _find(model)
    meta = model.metadata
    env = env if env is not None else gym.make(meta["env_id"], **(meta.get("env_kwargs") or {}))
    manifest = {"algo": meta["algo"], "hyperparameters": meta.get("hyperparameters")}
    return load_safely(algo_class(meta["algo"], meta["backend"]), path, env, meta["algo"],
                       meta["backend"], manifest)


# --------------------------------------------------------------------------- fetching


def _git(folder: Path, *args: str, **run: Any) -> subprocess.CompletedProcess:
    """``git -C folder ARGS`` (no hooks or file-system monitor run by what it reads)."""
    return subprocess.run(["git", "-C", str(folder), "-c", "core.fsmonitor=false", *args],
                          capture_output=True, check=False, **run)


def history_clone(folder: Path, model: FullModel) -> Path | None:
    """The top of the git clone that ``folder`` is in, if its history holds ``model``'s
    file at :data:`HISTORY_COMMIT`; else None (no git, no clone, a shallow clone...)."""
    try:
        found = _git(folder, "cat-file", "-e", f"{HISTORY_COMMIT}:{model.history_path}")
        if found.returncode != 0:
            return None
        top = _git(folder, "rev-parse", "--show-toplevel", text=True)
    except OSError:  # no git, or no such folder
        return None
    return Path(top.stdout.strip()) if top.returncode == 0 and top.stdout.strip() else \
        Path(folder)


def _suggested_source(model: FullModel) -> str | None:
    """A clone whose history holds the model: this package's own, or the working
    folder's."""
    here = Path(__file__).resolve().parents[2]
    for folder in dict.fromkeys((here, Path.cwd())):
        clone = history_clone(folder, model)
        if clone is not None:
            return str(clone)
    return None


def fetch_command(model: FullModel) -> str:
    """The sentence with the command that fetches ``model``: ``--from`` the clone whose
    history holds it, when one is found, else ``--from CLONE`` explained."""
    source = _suggested_source(model)
    command = f"rehabbot zoo fetch {model.name} --from"
    if source is not None:
        return f"get it with `{command} {_quote(source)}`"
    return (f"get it with `{command} CLONE`, where CLONE is a git clone of the rehabbot "
            f"repository (its history holds the file at commit {HISTORY_COMMIT}), or "
            f"--from a folder, .zip file or http(s) URL that holds "
            f"{model.name}{SUFFIX} (docs/zoo.md)")


def _quote(text: str) -> str:
    import shlex

    return shlex.quote(text)


Chunks = Callable[[], Iterator[bytes]]


def _file_chunks(path: Path) -> Chunks:
    def read() -> Iterator[bytes]:
        try:
            with open(path, "rb") as stream:
                while chunk := stream.read(CHUNK_BYTES):
                    yield chunk
        except OSError as err:
            raise SourceError(f"cannot read {path}: {err.strerror or err}") from err
    return read


def _url_chunks(url: str) -> Chunks:
    def read() -> Iterator[bytes]:
        import urllib.error
        import urllib.request

        try:
            with urllib.request.urlopen(url, timeout=URL_TIMEOUT_S) as response:
                received = 0
                while chunk := response.read(CHUNK_BYTES):
                    received += len(chunk)
                    if received > MAX_DOWNLOAD_BYTES:
                        raise SourceError(f"{url} sends more than {MAX_DOWNLOAD_BYTES:,} "
                                          "bytes; a full model is a few MB")
                    yield chunk
        except SourceError:
            raise
        except urllib.error.HTTPError as err:
            raise SourceError(f"{url}: HTTP {err.code} {err.reason}") from err
        except (urllib.error.URLError, OSError, ValueError) as err:
            reason = getattr(err, "reason", None) or err
            raise SourceError(f"cannot download {url}: {reason}") from err
    return read


def _git_chunks(clone: Path, model: FullModel) -> Chunks:
    spec = f"{HISTORY_COMMIT}:{model.history_path}"

    def read() -> Iterator[bytes]:
        try:
            process = subprocess.Popen(
                ["git", "-C", str(clone), "-c", "core.fsmonitor=false", "cat-file", "blob",
                 spec], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        except OSError as err:
            raise SourceError(f"cannot run git: {err.strerror or err}") from err
        try:
            assert process.stdout is not None
            while chunk := process.stdout.read(CHUNK_BYTES):
                yield chunk
        finally:
            if process.poll() is None:
                process.kill()
            _out, err = process.communicate()
        if process.returncode != 0:
            raise SourceError(f"git cannot read {spec} in {clone}: "
                              f"{err.decode(errors='replace').strip()}")
    return read


def _candidates(source: str, model: FullModel) -> Iterator[tuple[str, Chunks | None, str]]:
    """``(where, chunks, why_not)`` for each place of ``source`` that may hold the model:
    ``chunks`` reads it, or is None with ``why_not`` saying why it is not there."""
    file_name = f"{env_short_name(model.env_id)}/{model.agent}{SUFFIX}"
    if source.startswith(URL_SCHEMES):
        url = source if source.lower().endswith(SUFFIX) else f"{source.rstrip('/')}/{file_name}"
        yield url, _url_chunks(url), ""
        return
    path = Path(source).expanduser()
    if path.is_file():
        yield str(path), _file_chunks(path), ""
        return
    if not path.is_dir():
        raise UsageError(f"--from {source!r}: no such file or folder, and not an http(s) URL")
    for candidate in (path / file_name, path / HISTORY_ZOO / file_name, path / "model.zip"):
        if candidate.is_file():
            yield str(candidate), _file_chunks(candidate), ""
    clone = history_clone(path, model)
    if clone is not None:
        yield (f"{model.history_path} in the git history of {clone} at commit "
               f"{HISTORY_COMMIT[:12]}"), _git_chunks(clone, model), ""
    else:
        yield str(path.resolve()), None, (
            f"not a git clone whose history holds {model.history_path} at {HISTORY_COMMIT} "
            "(a shallow clone lacks it: git fetch --unshallow)")


class _MismatchError(ZooError):
    """A source's file whose SHA-256 is not the agent's."""


def _install(chunks: Chunks, target: Path, sha256: str) -> None:
    """Stream ``chunks`` to ``target`` through a temporary file, refusing it unless its
    SHA-256 is ``sha256``; a full disk is an OutputError naming ``target``."""

    def save(tmp: str) -> None:
        digest = hashlib.sha256()
        with open(tmp, "wb") as stream:
            for chunk in chunks():
                digest.update(chunk)
                stream.write(chunk)
        if digest.hexdigest() != sha256:
            raise _MismatchError(f"its SHA-256 is {digest.hexdigest()}, not the agent's "
                            f"full_model_sha256 {sha256}")

    def verify(tmp: Path) -> None:
        if file_sha256(tmp) != sha256:
            raise ValueError("its SHA-256 changed on the way to the disk")

    target.parent.mkdir(parents=True, exist_ok=True)  # the cache: created with its parents
    atomic_save_verified(target, save, verify)


@dataclass(frozen=True)
class Fetched:
    """What :func:`fetch_full_model` did: the verified file, where it came from (None: it
    was already here)."""

    path: Path
    origin: str | None
    model: FullModel


def fetch_full_model(env_id: str, algo: str, source: str | Path) -> Fetched:
    """Put a verified copy of the agent's full model in the cache, from ``source`` (a URL,
    a file or a folder: the module's docstring). Nothing is fetched when a verified copy is
    already here.

    Raises:
        UsageError: no such agent, an agent without a full model, a ``source`` that is
            neither a file, a folder nor an http(s) URL.
        ZooError: ``source`` holds no file with the agent's SHA-256 (the message says what
            each place held).
        OutputError: the cache cannot be written (a full disk), naming the file.
    """
    model = full_model(env_id, algo)
    for path in (model.beside, model.cached):
        if _verified(path, model) is not None:
            return Fetched(path=path, origin=None, model=model)
    refused = []
    for where, chunks, why_not in _candidates(str(source), model):
        if chunks is None:
            refused.append(f"{where}: {why_not}")
            continue
        try:
            _install(chunks, model.cached, model.sha256)
        except (_MismatchError, SourceError) as err:
            refused.append(f"{where}: {err}")
            continue
        return Fetched(path=model.cached, origin=where, model=model)
    raise ZooError(f"no verified copy of {model.name}'s full model (SHA-256 {model.sha256}) "
                   f"at {source}: " + "; ".join(refused))


# --------------------------------------------------------------------------- exporting


def ship_full_model(model_path: str | Path, out_npz: Path) -> dict[str, str]:
    """Copy a run's ``model.zip`` beside the zoo file ``out_npz`` (atomically, read back);
    the metadata entry that binds the two (``full_model_sha256``).

    Raises:
        OutputError: the copy cannot be written (a full disk), naming it.
    """
    source = Path(model_path)
    if source.is_dir():
        source = source / "model.zip"
    sha256 = file_sha256(source)
    target = Path(out_npz).with_suffix(SUFFIX)
    _install(_file_chunks(source), target, sha256)
    return {"full_model_sha256": sha256}
