"""The CLI's argument types for numbers and output paths: every count is bounded above and
below, every float finite, and a user's ``--out`` is never built out of missing folders."""

from __future__ import annotations

import argparse

import pytest

from rehabbot.cli.errors import bounded_float, bounded_int
from rehabbot.common.errors import UsageError
from rehabbot.common.files import check_parent_exists


@pytest.mark.parametrize("text, value", [("1", 1), ("1000", 1000), ("1e6", 1_000_000),
                                         ("1000000000", 1_000_000_000)])
def test_bounded_int_takes_integers_in_range(text: str, value: int) -> None:
    assert bounded_int(1, 10**9)(text) == value


@pytest.mark.parametrize("text", ["0", "-1", "1e26", "1000000001", "2.5", "nan", "inf", "ten",
                                  ""])
def test_bounded_int_names_what_it_refuses(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=r"\[1, 1,000,000,000\]") as err:
        bounded_int(1, 10**9)(text)
    assert repr(text) in str(err.value)


@pytest.mark.parametrize("text", ["nan", "inf", "-inf", "0", "-0.5", "1e7", "x"])
def test_bounded_float_refuses_non_finite_and_out_of_range(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=r"\(0, 1e\+06\]") as err:
        bounded_float(0.0, 1e6, low_open=True)(text)
    assert repr(text) in str(err.value)
    assert bounded_float(0.0, 1e6, low_open=True)("0.25") == 0.25
    assert bounded_float(0.0, 1e6)("0") == 0.0


def test_an_out_path_needs_its_folder(tmp_path) -> None:
    assert check_parent_exists(tmp_path / "new.gif") == tmp_path / "new.gif"
    missing = tmp_path / "no" / "such" / "x.gif"
    with pytest.raises(UsageError, match="does not exist") as err:
        check_parent_exists(missing)
    assert str(missing.parent) in str(err.value)
    assert not (tmp_path / "no").exists()
    (tmp_path / "file").write_text("")
    with pytest.raises(UsageError, match="is not a folder"):
        check_parent_exists(tmp_path / "file" / "x.gif")
