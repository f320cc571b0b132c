"""Layout: offsets from the declaration, and optional groups that must be nested."""

from __future__ import annotations

import pytest

from tether_gym.physics.layout import Field, Layout


def _layout() -> Layout:
    return Layout("row", (Field("a", False, "[-]", "a"), Field("b", True, "[-]", "b"),
                          Field("c", False, "[-]", "c", optional="first"),
                          Field("d", True, "[-]", "d", optional="second"),
                          Field("e", False, "[-]", "e", optional="second")))


def test_offsets_sizes_and_slices_of_nested_groups():
    layout = _layout()
    assert layout.groups == ("first", "second")
    assert layout.index.d == (2, 1)  # after a, b (n values) and c
    n = 3
    assert layout.size(n) == 4
    assert layout.size(n, first=True) == 5
    assert layout.size(n, first=True, second=True) == 9
    assert layout.slices(n, first=True, second=True) == {
        "a": slice(0, 1), "b": slice(1, 4), "c": slice(4, 5), "d": slice(5, 8),
        "e": slice(8, 9)}


def test_a_later_group_alone_is_rejected_naming_the_groups():
    """The offsets of 'second' count 'first': alone it would index past the row."""
    layout = _layout()
    for query in (layout.size, layout.slices, layout.selected):
        args = () if query == layout.selected else (3,)
        with pytest.raises(ValueError, match=r"group 'second' is on but \['first'\]"):
            query(*args, second=True)
        with pytest.raises(ValueError, match=r"group 'second' is on but \['first'\]"):
            query(*args, first=False, second=True)


def test_an_unknown_group_is_rejected():
    with pytest.raises(ValueError, match=r"no optional group \['third'\]; groups: "
                                         r"\['first', 'second'\]"):
        _layout().size(2, third=True)


def test_declaration_errors():
    a, opt = Field("a", False, "[-]", "a"), Field("x", False, "[-]", "x", optional="g")
    with pytest.raises(ValueError, match="repeats a field name"):
        Layout("row", (a, a))
    with pytest.raises(ValueError, match="mandatory field 'a' after an optional one"):
        Layout("row", (opt, a))
    split = (opt, Field("y", False, "[-]", "y", optional="h"),
             Field("z", False, "[-]", "z", optional="g"))
    with pytest.raises(ValueError, match="field 'z' of optional group 'g' is not next to"):
        Layout("row", split)
