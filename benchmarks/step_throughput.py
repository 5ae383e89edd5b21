"""Env step throughput of every registered id against the raw physics of the same model.

The benchmark lives in :mod:`rehabbot.throughput` so that the installed ``rehabbot bench``
command runs it too; see that module for the method. Usage::

    python benchmarks/step_throughput.py [--steps 2000] [--repeats 5] [--ids ID ...] [--json F]
"""

import sys

from rehabbot.throughput import main

if __name__ == "__main__":
    sys.exit(main())
