"""One thread for PyTorch in the CLI's own processes, unless the user chose otherwise.

PyTorch runs a small policy network on as many threads as the machine has cores by default;
for one small network that is slower than one thread, and many times slower when other
processes share the cores (measured: 14x under load). So the commands that run a network
(``rehabbot evaluate``, ``rehabbot render``; ``rehabbot train`` sets it in its own
library code) use one thread unless ``OMP_NUM_THREADS`` is set, and the commands the CLI prints
for another program to run start with :data:`THREADS_PREFIX`.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

THREADS_PREFIX = "OMP_NUM_THREADS=1 "
THREADS_NOTE = ("(OMP_NUM_THREADS=1: PyTorch on one CPU thread is faster for these small "
                "networks, and much faster while other processes share the cores)")


def one_torch_thread(specs: Sequence[str]) -> bool:
    """Set PyTorch to one thread unless ``OMP_NUM_THREADS`` is set, when one of the policy
    ``specs`` may run it (a model file or ``module:attr``; the expert, ``aan``, ``random`` and
    zoo agents need no PyTorch, which is then not imported). Returns whether it was set."""
    from rehabbot.rl.policies import POLICY_KEYWORDS
    from rehabbot.rl.zoo import is_zoo_spec

    if os.environ.get("OMP_NUM_THREADS"):
        return False
    if all(spec in POLICY_KEYWORDS or is_zoo_spec(spec) for spec in specs):
        return False
    torch = sys.modules.get("torch")
    if torch is None:
        try:
            import torch
        except ImportError:
            return False
    torch.set_num_threads(1)
    return True
