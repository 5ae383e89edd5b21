"""Random-action soak test: every registered id in every control mode, looking for exceptions,
non-finite values, observations outside the space and memory growth.

The logic lives in :mod:`rehabbot.soak` (see that module for what it measures and how to read
the figures). Usage::

    python benchmarks/soak.py [--steps 1000000] [--seed 0] [--env ID ...] [--mode MODE ...]
                              [--workers 1] [--out FILE.json] [--quiet]
"""

import sys

from rehabbot.soak import main

if __name__ == "__main__":
    sys.exit(main())
