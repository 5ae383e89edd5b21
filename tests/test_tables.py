"""The one table writer (rehabbot/common/text_tables.py)."""

import pytest

from rehabbot.common.text_tables import format_cell, markdown_table, text_table


def test_markdown_table_pads_escapes_and_aligns():
    text = markdown_table(["env", "success"], [["a|b", 0.5], ["knee", None]],
                          align=["left", "right"], digits=2)
    assert text.splitlines() == [
        "| env  | success |",
        "| ---- | ------: |",
        "| a\\|b |    0.50 |",
        "| knee |       - |",
    ]


def test_text_table_has_a_rule_and_no_trailing_spaces():
    text = text_table(["trial", "status"], [["s0", "done"], ["s10", None]])
    assert text.splitlines() == ["trial  status", "-----  ------", "s0     done", "s10    -"]


def test_format_cell():
    assert format_cell(None) == "-"
    assert format_cell(True) == "yes"
    assert format_cell(1 / 3, 3) == "0.333"
    assert format_cell(7) == "7"


@pytest.mark.parametrize("rows", [[["only one"]], [["a", "b", "c"]]])
def test_a_row_of_the_wrong_width_is_refused_naming_it(rows):
    with pytest.raises(ValueError, match="row 0 has"):
        markdown_table(["x", "y"], rows)


def test_bad_alignment_is_refused():
    with pytest.raises(ValueError, match="'middle'"):
        text_table(["x"], [["1"]], align=["middle"])
