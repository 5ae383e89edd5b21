"""``python -m rehabbot``: the ``rehabbot`` command."""

import sys

from rehabbot.cli import main

sys.exit(main())
