"""simulate's keyword arguments are typed (oxyline.options.SimulateOptions) and the type is
the list the run accepts: an option added to one and not the other fails here."""

from __future__ import annotations

import inspect

import pytest

import oxyline
from oxyline.options import SimulateOptions
from oxyline.run import OPTIONS


def test_the_typed_options_are_the_accepted_ones() -> None:
    assert set(SimulateOptions.__annotations__) == set(OPTIONS)


@pytest.mark.parametrize("function", [oxyline.simulate, oxyline.simulate_to_zarr])
def test_public_signatures_show_the_options(function: object) -> None:
    kwargs = inspect.signature(function).parameters["overrides"]  # type: ignore[arg-type]
    assert kwargs.kind is inspect.Parameter.VAR_KEYWORD
    assert kwargs.annotation == "Unpack[SimulateOptions]"


def test_an_option_outside_the_type_is_refused() -> None:
    with pytest.raises(oxyline.ModelError, match="unknown option.*cycels"):
        oxyline.simulate("bifurcation", cycels=2)  # type: ignore[call-arg]
