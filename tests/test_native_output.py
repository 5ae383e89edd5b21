"""rehabbot.common.native_output: a named line written to the C stderr is dropped; every other
line, and the named one outside the block, reaches the terminal."""

from __future__ import annotations

import os
import warnings

import pytest

from rehabbot.common.native_output import dropping_stderr_lines


def test_the_named_lines_are_dropped_and_the_rest_passed_on(capfd):
    with dropping_stderr_lines("known noise"):
        os.write(2, b"lib: known noise, twice\nlib: something else\n")
        warnings.warn("a known noise from Python", stacklevel=1)
    os.write(2, b"lib: known noise after the block\n")
    err = capfd.readouterr().err
    assert "something else" in err
    assert "known noise, twice" not in err and "from Python" not in err
    assert "known noise after the block" in err


def test_no_fragment_is_refused():
    with pytest.raises(ValueError, match="fragments"), dropping_stderr_lines():
        pass
