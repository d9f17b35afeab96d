"""Sphinx configuration: Markdown (MyST) pages, built offline with warnings as errors."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from porefsi import __version__  # noqa: E402
from porefsi.case.config import schema_markdown  # noqa: E402

project = "porefsi"
author = "porefsi developers"
release = __version__
extensions = ["myst_parser", "sphinx.ext.mathjax"]
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build", "studies", "README.md"]
html_theme = "alabaster"
suppress_warnings = ["myst.header"]

# The case-file reference is generated from the schema the code validates against.
(Path(__file__).parent / "case_reference.md").write_text(
    "# Case-file reference\n\nGenerated from `porefsi.case.config` at build time.\n\n" + schema_markdown(),
    encoding="utf-8",
)
