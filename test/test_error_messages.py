"""Error texts a newcomer meets first: each names the right file,
line and field, once."""
import pytest

from pearl_pomdp.errors import ModelFormatError
from pearl_pomdp.model.pomdp_format import parse_pomdp

TIGER = """discount: 0.95
values: reward
states: tiger-left tiger-right
actions: listen open-left open-right
observations: tiger-left tiger-right
start: uniform
T:listen
identity
T:open-left
uniform
T:open-right
uniform
O:listen
0.85 0.15
0.15 0.85
O:open-left
uniform
O:open-right
uniform
R:listen : * : * : * -1
R:open-left : tiger-left : * : * -100
R:open-left : tiger-right : * : * 10
R:open-right : tiger-left : * : * 10
R:open-right : tiger-right : * : * -100
"""


def _error(text: str) -> str:
    with pytest.raises(ModelFormatError) as info:
        parse_pomdp(text, source="bad.pomdp")
    return str(info.value)


def test_the_text_parses_before_it_is_broken():
    assert parse_pomdp(TIGER, source="tiger.pomdp").num_states == 2


def test_unknown_action_has_one_colon_after_the_keyword():
    msg = _error(TIGER.replace("T:listen", "T:lisen"))
    assert msg == "bad.pomdp:7: T: unknown action 'lisen' (known: listen, open-left, open-right)"


@pytest.mark.parametrize("old, new, line, row", [
    ("0.85 0.15\n0.15 0.85", "0.75 0.15\n0.15 0.85", 14, "tiger-left"),    # first matrix row
    ("0.85 0.15\n0.15 0.85", "0.85 0.15\n0.15 0.75", 15, "tiger-right"),   # second matrix row
])
def test_row_sum_error_names_the_line_of_the_matrix_row(old, new, line, row):
    msg = _error(TIGER.replace(old, new))
    assert msg.startswith(f"bad.pomdp:{line}: O: listen : {row}: row sums to 0.9, expected 1")


def test_row_sum_error_of_a_one_row_statement_names_the_row_line():
    text = TIGER.replace("O:listen\n0.85 0.15\n0.15 0.85", "O:listen : tiger-left\n0.85 0.05\nO:listen : tiger-right\n0.15 0.85")
    assert _error(text).startswith("bad.pomdp:14: O: listen : tiger-left: row sums to 0.9")
