"""The exceptions RehabBot raises on purpose, so that callers (and the ``rehabbot`` command)
can tell a user's mistake from a failure of the machine or of a file.

================== =============================================================== ==========
class              raised when                                                     CLI exit
================== =============================================================== ==========
``UsageError``     a bad argument, id, option or setting given by the user         2
                   (also a ``ValueError``)
``DataError``      a file that should hold a run, a model, a trace or settings is  1
                   missing, damaged or of another kind (also a ``ValueError``)
``OutputError``    an output folder or file cannot be created or written           1
                   (also an ``OSError``)
``RehabbotError``  the base class of the three                                     1
================== =============================================================== ==========

Plain ``ValueError`` from an env's constructor (a bad kwarg) counts as a usage error too.
"""

from __future__ import annotations


class RehabbotError(Exception):
    """Base class of the errors RehabBot raises on purpose."""


class UsageError(RehabbotError, ValueError):
    """A bad argument, id, option or setting given by the user."""


class DataError(RehabbotError, ValueError):
    """A file that should hold a run, a model, a trace or settings is missing or damaged."""


class OutputError(RehabbotError, OSError):
    """An output folder or file cannot be created or written."""
