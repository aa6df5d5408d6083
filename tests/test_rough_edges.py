"""Rough edges a new user meets (issue 13, item 10)."""

from __future__ import annotations

import argparse
import pickle

import numpy as np
import pytest

import oxyline
from oxyline import cli


def _actions(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.Action]]:
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out += [(f"{name} {n}", a) for n, a in _actions(sub)]
        elif not isinstance(action, argparse._HelpAction):
            out.append((action.dest, action))
    return out


def test_every_cli_option_has_help_text() -> None:
    missing = [name for name, action in _actions(cli._parser()) if not action.help]
    assert missing == []


def test_solver_failure_is_said_once(monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    def fail(*args: object, **kwargs: object) -> None:
        raise oxyline.SolverError("solver failed: Newton did not converge at t = 0.1 s")

    monkeypatch.setattr(oxyline, "simulate", fail)
    assert cli.main(["run", "bifurcation", "--quiet"]) == 1
    assert capsys.readouterr().err == \
        "error: solver failed: Newton did not converge at t = 0.1 s\n"


@pytest.mark.parametrize("name", ["bifurcation", "paper-bifurcated"])
def test_pickled_result_is_its_data_once(name: str) -> None:
    """A Result pickles its arrays once (the vessel/segment blocks are views of ``data``,
    rebuilt on loading); before, each view was pickled as a copy (twice the data)."""
    res = oxyline.simulate(name, cycles=1)
    data = res.data.nbytes + sum(s.vessel_data.nbytes + s.segment_data.nbytes
                                 + s.balance_data.nbytes for s in res.species.values())
    blob = pickle.dumps(res)
    assert len(blob) <= 1.05 * data + 50_000  # names, settings and pickle framing
    back = pickle.loads(blob)
    assert np.array_equal(back.segment_flow, res.segment_flow)
    assert np.array_equal(back.pressure_out, res.pressure_out)
    assert back.settings == res.settings and back.vessels == res.vessels
    if res.species:
        assert np.array_equal(back.po2_out, res.po2_out, equal_nan=True)
