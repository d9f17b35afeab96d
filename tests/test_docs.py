"""The docs pages: every relative link and image resolves, the user-guide examples run, and the
Sphinx build passes with warnings as errors.

The link and example checks need no Sphinx; :func:`test_docs_build` runs the build itself (what
``tox -e docs`` runs; Sphinx and MyST come with the ``test`` extra) and is skipped, with the reason,
only where Sphinx is not installed.
"""

from __future__ import annotations

import doctest
import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"
PAGES = sorted(DOCS.glob("*.md"))
#: Pages written by docs/conf.py at build time (git-ignored), which links may point to.
GENERATED = {"case_reference.md"}
#: Pages whose ``>>>`` examples must run (docs/conf.py runs the same list at build time).
DOCTEST_PAGES = ("user_guide.md", "api.md")

_FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
_INLINE_CODE = re.compile(r"`[^`\n]*`")
# [text](target) and ![alt](target); the text may hold one level of brackets.
_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
_HEADING = re.compile(r"^#{1,3}\s+(.*?)\s*$", re.M)  # myst_heading_anchors = 3


def _strip_code(text: str) -> str:
    return _INLINE_CODE.sub("", _FENCE.sub("", text))


def relative_links(text: str) -> list[str]:
    """Targets of the Markdown links and images of ``text`` that point inside the docs."""
    out = []
    for target in _LINK.findall(_strip_code(text)):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith("#"):
            continue  # URL (http:, mailto:, ...) or same-page anchor
        out.append(target)
    return out


def _slug(heading: str) -> str:
    """Anchor of a heading as MyST makes them (``myst_heading_anchors``, mdit-py-plugins' slugify)."""
    text = re.sub(r"[`*]", "", heading.strip())  # Markdown markup is not part of the title text
    text = re.sub(r"\$[^$]*\$", "", text)  # nor is inline math: MyST drops it (and keeps the space before it)
    return re.sub(r"[^\w\u4e00-\u9fff\- ]", "", text.lower().replace(" ", "-"))


def test_link_extraction_finds_links_and_skips_code_and_urls():
    text = ("See [a](a.md), ![img](figures/x.png) and [b](b.md#sec).\n"
            "`[not](code.md)` [web](https://example.org) [here](#local)\n"
            "```\n[in](fence.md)\n```\n")
    assert relative_links(text) == ["a.md", "figures/x.png", "b.md#sec"]


def test_slug_matches_myst_style():
    assert _slug("Python: step by step") == "python-step-by-step"
    assert _slug("`NET.vtp`: ParaView") == "netvtp-paraview"
    # measured on the Sphinx 9 / MyST 5 build: the math of the heading leaves its space behind
    assert _slug(r"(b) Solid time integration at large $\omega\Delta t$") == "b-solid-time-integration-at-large-"


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_relative_links_and_images_exist(page):
    missing = []
    for target in relative_links(page.read_text(encoding="utf-8")):
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if dest.name in GENERATED and dest.parent == DOCS:
            continue
        if not dest.exists():
            missing.append(target)
            continue
        if anchor and dest.suffix == ".md":
            slugs = {_slug(h) for h in _HEADING.findall(_FENCE.sub("", dest.read_text(encoding="utf-8")))}
            if anchor not in slugs:
                missing.append(target)
    assert not missing, f"{page.name}: broken relative links/images {missing}"


def test_every_page_is_reachable_from_the_index():
    """Every page is named in an index.md toctree (Sphinx -W fails otherwise)."""
    index = (DOCS / "index.md").read_text(encoding="utf-8")
    entries = []
    for block in re.findall(r"```\{toctree\}(.*?)```", index, re.S):
        entries += [ln.strip() for ln in block.splitlines() if ln.strip() and not ln.strip().startswith(":")]
    names = {p.stem for p in PAGES} | {Path(g).stem for g in GENERATED}
    reached = {n for n in names for e in entries if Path(n).match(e) or n == e}
    assert names - {"index"} <= reached, f"pages in no toctree: {sorted(names - {'index'} - reached)}"


def toml_blocks(text: str) -> list[str]:
    """Bodies of the fenced ```toml blocks of ``text``."""
    return re.findall(r"^```toml\n(.*?)^```", text, re.M | re.S)


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_case_file_examples_are_valid_cases(page):
    """Every TOML block in the docs is a valid case file: no unknown key, no out-of-range value."""
    import tomllib

    from porefsi.case.config import case_from_dict

    for block in toml_blocks(page.read_text(encoding="utf-8")):
        case_from_dict(tomllib.loads(block), where=page.name)


@pytest.mark.parametrize("name", DOCTEST_PAGES)
def test_page_examples_run(name, monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    result = doctest.testfile(str(DOCS / name), module_relative=False, verbose=False, report=True,
                              optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 20, f"{name}: only {result.attempted} examples found"
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed (see output)"


@pytest.mark.skipif(importlib.util.find_spec("sphinx") is None,
                    reason="Sphinx is not installed (pip install '.[test]' or '.[docs]')")
def test_docs_build(tmp_path):
    """``sphinx-build -W --keep-going`` as ``tox -e docs`` runs it (~3 s), into ``tmp_path``.

    The user-guide examples, which the build also runs, are skipped here
    (``POREFSI_DOCS_SKIP_DOCTEST``): :func:`test_page_examples_run` runs them.
    """
    env = dict(os.environ, POREFSI_DOCS_SKIP_DOCTEST="1")
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", "-d", str(tmp_path / "doctrees"),
           str(DOCS), str(tmp_path / "html")]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, f"sphinx-build failed (exit {proc.returncode}):\n{proc.stderr[-4000:]}"
    built = {p.stem for p in (tmp_path / "html").glob("*.html")}
    assert {p.stem for p in PAGES} <= built, f"pages not built: {sorted({p.stem for p in PAGES} - built)}"
