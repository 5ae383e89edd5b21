"""The API pages build without the ``[gpu]``, ``[myo]`` and ``[jax]`` extras (``make docs`` builds
the site in a venv with ``.[docs]`` alone): checked here, in a subprocess where those libraries
cannot be imported, whatever this venv has.

docs/_ext/api_pages.py lists the modules from the source tree, without importing them, and
docs/_ext/optional_imports.py mocks the missing libraries for autodoc, with stand-ins that keep
the batched ``State`` a dataclass and ``RslVecEnv``'s signature its own.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

BLOCKED = ("jax", "flax", "optax", "warp", "mujoco.mjx", "rsl_rl", "tensordict", "myo_sim",
           "sbx", "ray", "imageio", "imageio_ffmpeg")

SCRIPT = r"""
import dataclasses, importlib.abc, inspect, json, sys

BLOCKED = tuple(sys.argv[1].split(","))


class NotInstalled(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if any(name == blocked or name.startswith(blocked + ".") for blocked in BLOCKED):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


sys.meta_path.insert(0, NotInstalled())
sys.path[:0] = ["docs/_ext", "."]
import api_pages
import optional_imports
from sphinx.ext.autodoc.mock import mock

listed = api_pages.modules_of("rehabbot.batch") + api_pages.modules_of("rehabbot.rl")
mocked = optional_imports.mocked_imports()
with mock(mocked):
    import rehabbot.batch
    import rehabbot.batch.state
    import rehabbot.rl.rsl_vec_env
state_fields = [field.name for field in dataclasses.fields(rehabbot.batch.state.State)]
rsl_parameters = list(inspect.signature(rehabbot.rl.rsl_vec_env.RslVecEnv).parameters)
print(json.dumps({"listed": listed, "mocked": mocked, "state_fields": state_fields,
                  "rsl_parameters": rsl_parameters}))
"""


@pytest.mark.slow
def test_the_api_modules_import_for_autodoc_with_the_gpu_and_myo_libraries_missing():
    pytest.importorskip("sphinx", reason="the docs extra is not installed")
    result = subprocess.run([sys.executable, "-c", SCRIPT, ",".join(BLOCKED)], cwd=ROOT,
                            capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr[-3000:]
    seen = json.loads(result.stdout.strip().splitlines()[-1])
    assert {"rehabbot.batch.env", "rehabbot.batch.state", "rehabbot.rl.rsl_vec_env"} \
        <= set(seen["listed"])
    # flax and rsl_rl get stand-ins; the rest are mocked.
    assert set(seen["mocked"]) == set(BLOCKED) - {"flax", "rsl_rl"}
    assert seen["state_fields"] == ["data", "obs", "reward", "done", "metrics", "info"]
    assert seen["rsl_parameters"] == ["env_id", "num_envs", "seed", "env_kwargs"]
