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


def test_slices_are_computed_once_and_handed_out_as_copies():
    """The slices are cached per (n, switches): a caller that edits its dict changes
    neither the next caller's nor another n's, and switches given in any order agree."""
    layout = _layout()
    first = layout.slices(2, first=True, second=True)
    first["a"] = slice(7, 9)
    del first["e"]
    again = layout.slices(2, second=True, first=True)
    assert again == {"a": slice(0, 1), "b": slice(1, 3), "c": slice(3, 4), "d": slice(4, 6),
                     "e": slice(6, 7)}
    assert layout.slices(3)["b"] == slice(1, 4) and layout.slices(2)["b"] == slice(1, 3)
    with pytest.raises(ValueError, match="second"):  # a refused switch is never cached
        layout.slices(2, second=True)
    with pytest.raises(ValueError, match="second"):
        layout.slices(2, second=True)


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
