"""The import graph of porefsi: packages in layers, no module cycle, no reach into another
package's private modules, the public API names what it says (issue 14).

The layers, bottom to top (a module may import its own package and anything below it)::

    errors, units, _version, _schema, _lazy, _numba, _memory   helpers of every layer
    image                                                segmented images
    network                                              pore networks from images
    io, plot                                             files (results, checkpoints, VTK) and figures
    flow, solid, integrators, stokes                     the physics of each side
    coupling                                             the two-way coupled loop, from option objects
    case                                                 case files -> options -> runs
    sweep                                                many cases
    cli                                                  the command line
    __main__                                             ``python -m porefsi``

``import`` statements anywhere in a module count (also those inside functions: a deferred
import that goes upward is still a dependency upward). ``from porefsi.pkg import name`` counts as
a dependency on the module that defines ``name`` (the packages re-export lazily, ``_EXPORTS``).
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

import porefsi

ROOT = Path(porefsi.__file__).resolve().parent
LAYERS = (
    {"errors", "units", "_version", "_schema", "_lazy", "_numba", "_memory", "porefsi"},
    {"image"},
    {"network"},
    {"io", "plot"},
    {"flow", "solid", "integrators", "stokes"},
    {"coupling"},
    {"case"},
    {"sweep"},
    {"cli"},
    {"__main__"},
)
RANK = {pkg: i for i, layer in enumerate(LAYERS) for pkg in layer}
#: Module cycles known and owned elsewhere (kept visible here until fixed): none left.
KNOWN_CYCLES: list[set[str]] = []


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in ROOT.rglob("*.py")}


def _exports(package: str) -> dict:
    """The ``_EXPORTS`` (name -> module) of a package ``__init__`` (empty without)."""
    tree = ast.parse(MODULES[package].read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(getattr(t, "id", None) in ("_EXPORTS", "_LAZY") for t in targets):
                return ast.literal_eval(node.value)
    return {}


def _targets(node) -> list[str]:
    """The porefsi modules an import statement depends on."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name in MODULES]
    if not (isinstance(node, ast.ImportFrom) and node.level == 0 and node.module in MODULES):
        return []
    mod, out = node.module, []
    is_package = MODULES[mod].name == "__init__.py"
    for alias in node.names:
        if is_package and f"{mod}.{alias.name}" in MODULES:
            out.append(f"{mod}.{alias.name}")
        elif is_package and alias.name in _exports(mod):
            out.append(_exports(mod)[alias.name])
        else:
            out.append(mod)
    return out


def import_graph() -> dict[str, set[str]]:
    """Module -> the porefsi modules it imports."""
    graph = {}
    for name, path in MODULES.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            deps.update(_targets(node))
        graph[name] = deps - {name}
    return graph


def package_of(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "porefsi"


def package_graph() -> dict[str, set[str]]:
    """Package -> the packages it imports (the graph the docs show)."""
    out: dict[str, set[str]] = {}
    for mod, deps in import_graph().items():
        out.setdefault(package_of(mod), set()).update(package_of(d) for d in deps)
    return {k: v - {k} for k, v in out.items()}


def strongly_connected(graph: dict[str, set[str]]) -> list[set[str]]:
    """The components of more than one node (Tarjan), i.e. the cycles."""
    index, low, stack, on, comps = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(comp)

    for v in list(graph):
        if v not in index:
            visit(v)
    return comps


def test_every_package_has_a_layer():
    assert {package_of(m) for m in MODULES} <= set(RANK)


def test_packages_import_only_their_own_layer_or_below():
    up = [f"{m} -> {d}" for m, deps in import_graph().items() for d in deps
          if RANK[package_of(d)] > RANK[package_of(m)]
          or (RANK[package_of(d)] == RANK[package_of(m)] and package_of(d) != package_of(m)
              and RANK[package_of(m)] > 0)]
    assert not up, "imports going up (or sideways) the layers:\n" + "\n".join(sorted(up))


def test_the_package_graph_is_acyclic():
    assert strongly_connected(package_graph()) == []


def test_no_module_cycle():
    cycles = [c for c in strongly_connected(import_graph()) if c not in KNOWN_CYCLES]
    assert not cycles, f"module import cycles: {cycles}"


def test_cycle_finder_finds_a_planted_cycle():
    assert strongly_connected({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [{"a", "b", "c"}]
    g = import_graph()
    g["porefsi.image.io"].add("porefsi.case.run")  # image importing the top floor closes a loop
    assert any("porefsi.image.io" in c for c in strongly_connected(g))


def _named_modules(path: Path) -> list[str]:
    """The porefsi modules an import statement of ``path`` names (as written, not resolved)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names if a.name.startswith("porefsi")]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("porefsi"):
            out.append(node.module)
            out += [f"{node.module}.{a.name}" for a in node.names if f"{node.module}.{a.name}" in MODULES]
    return out


def test_no_private_module_of_another_package_is_imported():
    """A module may use its own package's private modules (``_kernels``), not another package's:
    what a package shares it re-exports from its ``__init__`` (its ``__all__``)."""
    bad = []
    for m, path in MODULES.items():
        for d in _named_modules(path):
            private = [p for p in d.split(".")[2:] if p.startswith("_") and not p.startswith("__")]
            if private and package_of(d) != package_of(m):
                bad.append(f"{m} -> {d}")
    assert not bad, "reaches into another package's private modules:\n" + "\n".join(sorted(bad))


@pytest.mark.parametrize("package", sorted(m for m, p in MODULES.items() if p.name == "__init__.py"))
def test_every_package_declares_its_api(package):
    mod = importlib.import_module(package)
    assert isinstance(getattr(mod, "__all__", None), (list, tuple)) and mod.__all__, f"{package} has no __all__"
    missing = [n for n in mod.__all__ if not hasattr(mod, n)]
    assert not missing, f"{package}.__all__ names what it does not have: {missing}"
    assert len(set(mod.__all__)) == len(mod.__all__)


def test_exported_names_are_not_shadowed_by_submodules():
    """A package name that is also a submodule's name (``integrators.quasistatic``) must still be the
    function once every submodule is imported (a lazily resolved name would turn into the module)."""
    import pkgutil
    from types import ModuleType

    for m in pkgutil.walk_packages(porefsi.__path__, "porefsi."):
        if m.name != "porefsi.__main__":
            importlib.import_module(m.name)
    shadowed = [f"{pkg}.{n}" for pkg, p in MODULES.items() if p.name == "__init__.py"
                for n in importlib.import_module(pkg).__all__
                if isinstance(getattr(importlib.import_module(pkg), n), ModuleType)]
    assert not shadowed, f"exported names that are modules: {shadowed}"


def test_the_api_page_lists_every_public_name():
    """docs/api.md names every name ``porefsi`` exports (and the page's example runs: tests/test_docs.py)."""
    page = (ROOT.parent / "docs" / "api.md").read_text(encoding="utf-8")
    missing = [n for n in porefsi.__all__ if n != "__version__" and f"`{n}`" not in page]
    assert not missing, f"docs/api.md does not list {missing}"


CASES = ROOT.parent / "cases"


def _public(module: str, name: str) -> bool:
    """Whether ``from module import name`` uses porefsi's public API."""
    parts = module.split(".")
    if any(p.startswith("_") for p in parts) or len(parts) > 2:
        return False  # a private module, or a module inside a subpackage: not the API
    mod = importlib.import_module(module)
    if name in getattr(mod, "__all__", ()):
        return True
    # a public subpackage or module of porefsi itself (``from porefsi import plot``)
    return module == "porefsi" and not name.startswith("_") and f"porefsi.{name}" in MODULES


def test_public_rule_refuses_private_and_deep_imports():
    assert _public("porefsi", "CoupledRun") and _public("porefsi.coupling", "GeometricUpdate")
    assert _public("porefsi", "plot") and _public("porefsi.plot", "render_solid")
    assert not _public("porefsi.coupling.loop", "CoupledRun")  # a module inside a subpackage
    assert not _public("porefsi.coupling", "same_topology")  # not in the package's __all__
    assert not _public("porefsi.flow._drainage_checkpoint", "simulator_state")


@pytest.mark.parametrize("path", sorted(CASES.rglob("*.py")), ids=lambda p: str(p.relative_to(CASES)))
def test_cases_use_only_the_public_api(path):
    """The case scripts are examples for users: they import porefsi's public API only (``porefsi`` and
    the ``__all__`` of its subpackages), and their shared helpers from ``cases/_common.py``."""
    bad = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            bad += [a.name for a in node.names if a.name.startswith("porefsi") and a.name != "porefsi"]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("porefsi"):
            bad += [f"{node.module}.{a.name}" for a in node.names if not _public(node.module, a.name)]
    assert not bad, f"{path.name} uses porefsi beyond its public API: {bad}"


# ---- size: one concept per function (issue 14) -------------------------------------------------
#: Longest function (lines from ``def`` to its last line, docstring included) and most parameters
#: (``self``/``cls`` not counted) allowed in porefsi/; dataclass constructors are generated, so exempt.
MAX_LINES = 80
MAX_PARAMS = 8


def _functions(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            a = node.args
            names = [x.arg for x in (*a.posonlyargs, *a.args, *a.kwonlyargs)]
            n = len(names) + (a.vararg is not None) + (a.kwarg is not None)
            if names and names[0] in ("self", "cls"):
                n -= 1
            yield node.name, node.lineno, node.end_lineno - node.lineno + 1, n


def oversized(source: str) -> list[tuple[str, int, int, int]]:
    """(name, line, lines, parameters) of every function over :data:`MAX_LINES` or :data:`MAX_PARAMS`."""
    return [f for f in _functions(ast.parse(source)) if f[2] > MAX_LINES or f[3] > MAX_PARAMS]


def test_no_function_is_too_long_or_takes_too_many_parameters():
    found = [f"{path.relative_to(ROOT.parent)}:{line} {name} ({n_lines} lines, {n_par} parameters)"
             for path in sorted(ROOT.rglob("*.py"))
             for name, line, n_lines, n_par in oversized(path.read_text(encoding="utf-8"))]
    assert not found, "split these into named stages / option objects:\n" + "\n".join(found)


def test_size_rule_sees_a_planted_long_function_and_option_soup():
    long = "def f():\n" + "    x = 1\n" * MAX_LINES
    soup = "def g(self, " + ", ".join(f"a{i}" for i in range(MAX_PARAMS + 1)) + "):\n    pass\n"
    fine = "def h(self, " + ", ".join(f"a{i}" for i in range(MAX_PARAMS)) + "):\n    pass\n"
    assert [f[0] for f in oversized(long + soup + fine)] == ["f", "g"]
