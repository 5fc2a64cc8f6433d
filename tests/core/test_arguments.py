"""The command line's number types against generated input."""

from __future__ import annotations

import argparse
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bench.core.arguments import noise_level, nonnegative, nonnegative_int, positive, positive_int

_texts = st.one_of(
    st.text(max_size=12),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-10**30, max_value=10**30).map(str),
    st.sampled_from(["nan", "inf", "-inf", "1e400", "-0", "0.0", " 3 ", "1_000", "0x10", "2.5"]),
)


@given(_texts)
def test_each_type_returns_a_valid_value_or_refuses_the_text(text):
    for kind, ok in ((positive, lambda v: v > 0 and math.isfinite(v)),
                     (nonnegative, lambda v: v >= 0 and math.isfinite(v)),
                     (positive_int, lambda v: isinstance(v, int) and v > 0),
                     (nonnegative_int, lambda v: isinstance(v, int) and v >= 0)):
        try:
            value = kind(text)
        except argparse.ArgumentTypeError as exc:
            assert "\n" not in str(exc) and str(exc).startswith("must be")
        else:
            assert ok(value), (kind.__name__, text, value)
    try:
        level = noise_level(text)
    except argparse.ArgumentTypeError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("a noise level is")
    else:
        assert 0 <= level < 10, (text, level)


@pytest.mark.parametrize("kind, text", [(positive, "0"), (positive, "nan"), (positive, "inf"), (nonnegative, "-1e-9"),
                                        (nonnegative, "nan"), (positive_int, "0"), (positive_int, "2.5"),
                                        (positive_int, "-3"), (nonnegative_int, "-1"), (nonnegative_int, "0.5")])
def test_the_edges_are_refused(kind, text):
    with pytest.raises(argparse.ArgumentTypeError, match="must be"):
        kind(text)


def test_good_values_pass_through():
    assert positive("2.5") == 2.5 and nonnegative("0") == 0.0 and positive_int("7") == 7 and nonnegative_int("0") == 0
