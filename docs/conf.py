"""Sphinx configuration: Markdown (MyST) pages, built offline with warnings as errors.

Three things are generated or checked from the code at build time, so the docs cannot drift from it:

* ``case_reference.md``: written from :func:`porefsi.case.config.schema_markdown` (git-ignored);
* the body of ``cli_reference.md``: the ``--help`` of ``porefsi`` and of every subcommand, from
  :func:`porefsi.cli.build_parser`, put in place of the marker line of the committed stub when
  Sphinx reads the page (nothing is written to disk);
* the ``>>>`` examples of :data:`DOCTEST_PAGES` are run with :mod:`doctest` when the build starts;
  a failing example is a warning, so ``sphinx-build -W`` (``tox -e docs``) fails. Set
  ``POREFSI_DOCS_SKIP_DOCTEST=1`` to skip them while editing layout. ``tests/test_docs.py`` runs
  the same examples in the default test suite.
"""

import argparse
import doctest
import io
import os
import sys
import time
from pathlib import Path

# Before numpy is imported: single-threaded BLAS (DESIGN §4), no display for matplotlib/pyvista.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

from porefsi import __version__  # noqa: E402
from porefsi.case.config import schema_markdown  # noqa: E402
from porefsi.cli import build_parser  # noqa: E402

project = "porefsi"
author = "porefsi developers"
copyright = "porefsi developers"  # noqa: A001
release = __version__
version = __version__
extensions = ["myst_parser", "sphinx.ext.mathjax"]
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build", "studies", "README.md"]
html_theme = "alabaster"
html_theme_options = {"page_width": "1180px", "sidebar_width": "240px"}
suppress_warnings = ["myst.header"]

#: Pages whose ``>>>`` examples are run at build time (and by tests/test_docs.py).
DOCTEST_PAGES = ("user_guide.md", "api.md")
DOCTEST_FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
CLI_MARKER = "<!-- generated: porefsi --help of every subcommand -->"
CLI_COLUMNS = 100

# The case-file reference is generated from the schema the code validates against.
(HERE / "case_reference.md").write_text(
    "# Case-file reference\n\n"
    "Generated from `porefsi.case.config` when the docs are built: the table is the schema the case "
    "loader validates against (an unknown section or key, a wrong type or an out-of-range value is a "
    "`ConfigError` naming the key). Every key is optional; the defaults are the seed paper's table 2 "
    "set-up on the built-in 120³ Berea sample. How to write and run a case: [user guide](user_guide.md).\n\n"
    + schema_markdown(),
    encoding="utf-8",
)


def cli_reference_markdown() -> str:
    """Markdown with the ``--help`` text of ``porefsi`` and of each subcommand, in parser order."""
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(CLI_COLUMNS)  # argparse wraps to the terminal width: fix it
    try:
        parser = build_parser()
        out = ["## `porefsi`", "", "```text", parser.format_help().rstrip(), "```", ""]
        for action in parser._actions:
            if not isinstance(action, argparse._SubParsersAction):
                continue
            summaries = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                out += [f"## `porefsi {name}`", ""]
                if summaries.get(name):
                    out += [summaries[name][0].upper() + summaries[name][1:] + ".", ""]
                out += ["```text", sub.format_help().rstrip(), "```", ""]
        return "\n".join(out)
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old


def _fill_cli_reference(app, docname, source):
    if docname != "cli_reference":
        return
    if CLI_MARKER not in source[0]:
        from sphinx.util import logging

        logging.getLogger(__name__).warning("cli_reference.md: marker %r not found", CLI_MARKER)
        return
    source[0] = source[0].replace(CLI_MARKER, cli_reference_markdown())


def run_page_doctests(page: Path) -> tuple[int, int, str]:
    """Run the ``>>>`` examples of ``page``; return (failed, attempted, report)."""
    text = page.read_text(encoding="utf-8")
    test = doctest.DocTestParser().get_doctest(text, {"__name__": "__docs__"}, page.name, str(page), 0)
    runner = doctest.DocTestRunner(optionflags=DOCTEST_FLAGS)
    report = io.StringIO()
    runner.run(test, out=report.write)  # the runner captures what the examples print itself
    return runner.failures, runner.tries, report.getvalue()


def _run_doctests(app):
    if os.environ.get("POREFSI_DOCS_SKIP_DOCTEST"):
        return
    from sphinx.util import logging

    log = logging.getLogger(__name__)
    for name in DOCTEST_PAGES:
        t = time.perf_counter()
        failed, tried, report = run_page_doctests(HERE / name)
        if failed:
            log.warning("%s: %d of %d doctest examples failed\n%s", name, failed, tried, report)
        elif tried == 0:
            log.warning("%s: no doctest examples found", name)
        else:
            log.info("%s: %d doctest examples passed in %.1f s", name, tried, time.perf_counter() - t)


def setup(app):
    """Register the CLI-reference generator and the build-time doctests."""
    app.connect("source-read", _fill_cli_reference)
    app.connect("builder-inited", _run_doctests)
    return {"parallel_read_safe": True}
