"""The ``Examples`` sections of the library's docstrings run and print what they show.

Every module of ``porefsi`` is imported (an import that fails is a failure here too) and every
docstring example block in it is run with :mod:`doctest`, with the flags the docs pages use.
This is what ``pytest --doctest-modules porefsi`` would do, kept as a test module so that the
default selection (``python -m pytest``, which collects ``tests/``) runs it, and so that losing
the examples is noticed (:func:`test_the_examples_are_found`). Under 2 s: the examples use small
lattices and synthetic images; no optional peer (OpenPNM, PoreSpy) is imported.
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import porefsi

FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
MODULES = sorted(m.name for m in pkgutil.walk_packages(porefsi.__path__, "porefsi.") if m.name != "porefsi.__main__")


def _tests(name: str) -> list[doctest.DocTest]:
    mod = importlib.import_module(name)
    return [t for t in doctest.DocTestFinder(exclude_empty=True).find(mod, name) if t.examples]


def test_the_examples_are_found():
    found = {name: sum(len(t.examples) for t in _tests(name)) for name in MODULES}
    with_examples = {n for n, k in found.items() if k}
    # the modules whose public functions carry examples today (grow this set, never shrink it)
    assert {"porefsi.flow.drainage", "porefsi.flow.permeability", "porefsi.image.io", "porefsi.image.ops",
            "porefsi.network.convert", "porefsi.network.extract"} <= with_examples
    assert sum(found.values()) >= 40


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)  # an example that writes a file writes it here
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    report: list[str] = []
    for test in _tests(name):
        runner.run(test, out=report.append)
    assert runner.failures == 0, f"{runner.failures} of {runner.tries} examples failed:\n" + "".join(report)
