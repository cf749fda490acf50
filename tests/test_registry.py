"""Named registries: lookups with typed errors, live views of the names."""

from __future__ import annotations

import pytest

from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.registry import Registry


def test_entries_keep_their_order_and_views_stay_live() -> None:
    colours: Registry[int] = Registry("colour", InvalidSettingsError)
    names, odd = colours.names(), colours.names(lambda value: value % 2 == 1)
    assert colours.register("red", 1) == 1 and colours.register("green", 2) == 2
    assert list(names) == ["red", "green"] and names == ("red", "green") and names[1] == "green"
    assert "red" in odd and "green" not in odd and len(odd) == 1
    colours.register("blue", 3)
    assert names == ["red", "green", "blue"] and odd == ("red", "blue")
    assert colours.unregister("red") == 1
    assert names == ("green", "blue") and dict(colours) == {"green": 2, "blue": 3}


def test_unknown_names_and_bad_registrations_raise_the_registry_s_error() -> None:
    colours: Registry[int] = Registry("colour", InvalidSettingsError)
    colours.register("red", 1)
    with pytest.raises(InvalidSettingsError, match="unknown colour 'blue'; valid: red"):
        colours.lookup("blue")
    with pytest.raises(InvalidSettingsError, match="unknown colour"):
        colours.lookup(["red"])  # type: ignore[arg-type]
    with pytest.raises(InvalidSettingsError, match="colour 'red' is already registered"):
        colours.register("red", 2)
    with pytest.raises(InvalidSettingsError, match="non-empty name"):
        colours.register("", 2)
    with pytest.raises(TypeError, match="unhashable"):
        hash(colours.names())
