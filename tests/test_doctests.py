"""The runnable examples in the public API's docstrings (simulate, the forward models, the emulator's load and
predict, calibrate, designs and campaigns, each study's load) run as tests, so the documentation cannot drift from
the code. Each module is run with :mod:`doctest` (ELLIPSIS on); a module listed here must hold at least one
example."""
from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = (
    "lvcore.execution.bounded_cache",
    "lvcore.execution.restart",
    "lvcore.mechanics.simulate",
    "lvcore.core.forward",
    "lvcore.emulator.io",
    "lvcore.emulator.model",
    "lvcore.emulator.forward",
    "lvcore.inference.calibrate",
    "lvcore.inference.request",
    "lvcore.studies.sbc",
    "lvcore.studies.information",
    "lvcore.studies.fibre_discrepancy",
    "lvcore.studies.operators",
    "lvcore.studies.operators_realistic",
    "lvcore.studies.bo_fibres",
    "lvcore.studies.bo_mismatch",
    "lvcore.studies.mismatch",
    "lvcore.studies.findings",
    "lvcore.studies.registry",
    "lvcore.campaigns.designs",
    "lvcore.campaigns.runner",
)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert result.attempted > 0, f"{name} has no docstring example"
    assert result.failed == 0, f"{result.failed} of {result.attempted} docstring example(s) of {name} failed"
