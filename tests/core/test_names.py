"""A method's name parses into its parts and back, and a wrong one is refused
in one line naming the part."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bench.core.names import MethodName, MethodNameError

part = st.from_regex(r"[a-z][a-z0-9_]{0,11}", fullmatch=True)


@given(method=part, prior=st.none() | part, variant=st.none() | part, tuned=st.booleans())
def test_a_name_round_trips_through_its_text(method, prior, variant, tuned):
    name = MethodName(method, prior, variant, tuned)
    assert MethodName.parse(str(name)) == name
    assert name.run == MethodName(method, prior) and name.hybrid == (prior is not None)


def test_the_three_kinds_of_name_are_told_apart():
    assert MethodName.parse("feasible+gp") == MethodName("gp", prior="feasible")
    assert MethodName.parse("syrenets@pruned") == MethodName("syrenets", variant="pruned")
    assert MethodName.parse("feasible+gp tuned").tuned and MethodName.parse("feasible+gp tuned").parts == ("feasible", "gp")
    assert str(MethodName.parse("syrenets").with_tuned().with_variant("pruned")) == "syrenets@pruned tuned"


@pytest.mark.parametrize("text, says", [("a+b+c", "cannot be a hybrid"), ("+gp", "prior ''"), ("gp@", "variant ''"),
                                        ("g p", "method 'g p'"), ("", "method ''")])
def test_a_wrong_name_is_refused_naming_its_part(text, says):
    with pytest.raises(MethodNameError) as exc:
        MethodName.parse(text)
    assert says in str(exc.value) and "\n" not in str(exc.value)
    assert exc.value.hybrid == (text.count("+") > 0)  # whether the name meant a hybrid
