"""The import rules of docs/architecture.md, checked on the real import graph.

The rule table is read from docs/architecture.md (between the ``import-rules`` markers), so it
is written once. Every module of labkit, labkit.drivers and labkit.analysis is parsed (AST, no
import): ``import`` and ``from ... import`` anywhere in the file (module level, inside
functions, under ``TYPE_CHECKING``) and ``importlib.import_module("labkit...")`` calls whose
name starts with a constant.
"""

from __future__ import annotations

import ast
import re
import tomllib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "architecture.md"
FIRST_PARTY = "labkit"

# Violations that exist today and have an owner working on them (issue 16). Each entry is
# (importing module, imported module). The test fails on any violation not listed here AND on
# any entry here that no longer occurs, so this list can only shrink.
PENDING: dict[tuple[str, str], str] = {
}


# --------------------------------------------------------------------------- the rule table

@dataclass(frozen=True)
class Rule:
    importer: str
    forbidden: tuple[str, ...]
    allowed: tuple[str, ...]
    why: str


def _names(cell: str) -> tuple[str, ...]:
    return tuple(re.findall(r"`([\w.]+)`", cell))


def parse_rules(markdown: str) -> list[Rule]:
    """Rows of the table between ``<!-- import-rules:start -->`` and ``<!-- import-rules:end -->``.

    The first column may name several importers; each gets its own :class:`Rule`.
    """
    m = re.search(r"<!-- import-rules:start -->(.*?)<!-- import-rules:end -->", markdown, re.S)
    if m is None:
        raise ValueError("docs/architecture.md: no <!-- import-rules:start/end --> table")
    rules: list[Rule] = []
    for line in m.group(1).strip().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 4 or cells[0] == "importer" or set(cells[0]) <= set("-: "):
            continue
        importers, forbidden, allowed = _names(cells[0]), _names(cells[1]), _names(cells[2])
        if not importers or not forbidden:
            raise ValueError(f"docs/architecture.md: import rule row without modules: {line!r}")
        rules.extend(Rule(imp, forbidden, allowed, cells[3]) for imp in importers)
    return rules


def under(name: str, prefix: str) -> bool:
    """``name`` is ``prefix`` or a module inside it."""
    return name == prefix or name.startswith(prefix + ".")


def rule_for(module: str, rules: list[Rule]) -> Rule | None:
    """The row of the longest importer that contains ``module`` (None: no rule applies)."""
    best = [r for r in rules if under(module, r.importer)]
    return max(best, key=lambda r: len(r.importer)) if best else None


def breaks(module: str, target: str, rules: list[Rule]) -> Rule | None:
    """The rule that ``module`` importing ``target`` breaks, or None."""
    rule = rule_for(module, rules)
    if rule is None or any(under(target, a) for a in rule.allowed):
        return None
    return rule if any(under(target, f) for f in rule.forbidden) else None


# --------------------------------------------------------------------------- the import graph

def package_roots(pyproject: Path = ROOT / "pyproject.toml") -> dict[str, Path]:
    """Top-level mapped package -> folder, from ``[tool.setuptools] package-dir``."""
    table = tomllib.loads(pyproject.read_text())["tool"]["setuptools"]
    return {name: ROOT / folder for name, folder in table["package-dir"].items()}


def iter_modules(roots: dict[str, Path]) -> Iterator[tuple[str, Path]]:
    """(dotted module name, file) for every ``.py`` file under each mapped folder.

    A folder mapped to its own package (``labkit.drivers`` -> ``drivers/``) is walked once, under
    the name its mapping gives it.
    """
    mapped = {folder.resolve() for folder in roots.values()}
    for pkg, folder in roots.items():
        for path in sorted(folder.rglob("*.py")):
            rel = path.relative_to(folder)
            # Skip files inside a folder that another mapping owns (none today; keeps it exact).
            if any(p.resolve() in mapped and p.resolve() != folder.resolve() for p in path.parents):
                continue
            parts = list(rel.with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            yield ".".join([pkg, *parts]), path


def _constant_prefix(node: ast.expr) -> str | None:
    """The leading constant text of a str or f-string expression."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr) and node.values:
        first = node.values[0]
        if isinstance(first, ast.Constant) and isinstance(first.value, str):
            return first.value
    return None


def imports_of(source: str, module: str, *, is_package: bool) -> list[tuple[str, int]]:
    """Every first-party module name ``source`` imports, with its line number.

    ``from a.b import c`` yields ``a.b`` and ``a.b.c`` (the caller keeps the names that are
    modules). Relative imports are resolved against ``module``. For ``import_module`` with an
    f-string the constant prefix up to its last dot is taken (``f"labkit.commands.{x}"`` ->
    ``labkit.commands``).
    """
    out: list[tuple[str, int]] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out.extend((a.name, node.lineno) for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_package else module.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.append((mod, node.lineno))
            out.extend((f"{mod}.{a.name}", node.lineno) for a in node.names if a.name != "*")
        elif isinstance(node, ast.Call) and node.args:
            func = node.func
            fname = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if fname == "import_module":
                text = _constant_prefix(node.args[0])
                if text is not None:
                    full = isinstance(node.args[0], ast.Constant)
                    out.append((text if full else text.rpartition(".")[0], node.lineno))
    return [(name, line) for name, line in out if under(name, FIRST_PARTY)]


@dataclass(frozen=True)
class Edge:
    importer: str
    target: str
    where: str          # file:line


def import_graph(roots: dict[str, Path] | None = None) -> tuple[set[str], list[Edge]]:
    """All modules, and every import between them (targets reduced to existing modules)."""
    files = dict(iter_modules(roots or package_roots()))
    edges: list[Edge] = []
    for name, path in files.items():
        for target, line in imports_of(path.read_text(), name, is_package=path.name == "__init__.py"):
            if target in files:
                edges.append(Edge(name, target, f"{path.relative_to(ROOT)}:{line}"))
    return set(files), edges


def violations(edges: Iterable[Edge], rules: list[Rule]) -> dict[tuple[str, str], list[str]]:
    """(importer, target) -> where, for every import a rule forbids."""
    found: dict[tuple[str, str], list[str]] = {}
    for e in edges:
        if breaks(e.importer, e.target, rules) is not None:
            found.setdefault((e.importer, e.target), []).append(e.where)
    return found


def subpackage(module: str) -> str:
    """The unit of the no-cycle rule: ``labkit.X`` for everything under it (``labkit`` itself alone).

    The command line is one unit: ``labkit.cli`` discovers ``labkit.commands``, and the commands
    share its argument helpers.
    """
    unit = ".".join(module.split(".")[:2])
    return "labkit.cli" if unit in ("labkit.commands", "labkit.__main__") else unit


def find_cycle(edges: Iterable[tuple[str, str]]) -> list[str] | None:
    """One cycle of the directed graph (as a closed path), or None."""
    graph: dict[str, set[str]] = {}
    for a, b in edges:
        if a != b:
            graph.setdefault(a, set()).add(b)
    state: dict[str, int] = {}          # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return [*stack[stack.index(m):], m]
            if m not in state:
                found = visit(m)
                if found:
                    return found
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state:
            found = visit(n)
            if found:
                return found
    return None


# --------------------------------------------------------------------------- the checker itself

SYNTH_RULES = """
<!-- import-rules:start -->
| importer | must not import | allowed | why |
|---|---|---|---|
| `labkit.drivers` | `labkit.sim`, `labkit.cli` | | drivers only |
| `labkit.experiments` | `labkit.lab` | `labkit.lab.client` | via the client |
| `labkit.experiments.session`, `labkit.demo` | `labkit.cli` | | starts the lab |
<!-- import-rules:end -->
"""


def test_rule_table_parses_with_allowed_and_longest_importer():
    rules = parse_rules(SYNTH_RULES)
    assert [r.importer for r in rules] == ["labkit.drivers", "labkit.experiments",
                                          "labkit.experiments.session", "labkit.demo"]
    assert breaks("labkit.drivers.scope", "labkit.sim.core", rules) is not None
    assert breaks("labkit.drivers.scope", "labkit.simx", rules) is None          # prefix, not substring
    assert breaks("labkit.drivers.scope", "labkit.errors", rules) is None
    assert breaks("labkit.experiments.rig", "labkit.lab.core", rules) is not None
    assert breaks("labkit.experiments.rig", "labkit.lab.client", rules) is None   # allowed
    assert breaks("labkit.experiments.session", "labkit.lab", rules) is None      # its own row wins
    assert breaks("labkit.analysis.frf", "labkit.cli", rules) is None             # no row


def test_imports_are_found_in_every_form():
    src = (
        "import labkit.sim.core\n"
        "from labkit.errors import InputError\n"
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n"
        "    from labkit.lab import client\n"
        "def f(name):\n"
        "    from . import base\n"
        "    from ..sim import params\n"
        "    import importlib\n"
        "    importlib.import_module(f'labkit.commands.{name}')\n"
        "    return importlib.import_module('labkit.cli')\n"
    )
    got = {n for n, _ in imports_of(src, "labkit.drivers.scope", is_package=False)}
    assert {"labkit.sim.core", "labkit.errors", "labkit.errors.InputError", "labkit.lab",
            "labkit.lab.client", "labkit.drivers", "labkit.drivers.base", "labkit.sim",
            "labkit.sim.params", "labkit.commands", "labkit.cli"} <= got
    assert not any(n.startswith("typing") or n == "importlib" for n in got)
    # In a package's __init__, "." is the package itself.
    got_pkg = {n for n, _ in imports_of("from .base import X\n", "labkit.drivers", is_package=True)}
    assert "labkit.drivers.base" in got_pkg


def test_cycle_finder():
    assert find_cycle([("a", "b"), ("b", "c")]) is None
    cyc = find_cycle([("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")])
    assert cyc is not None and cyc[0] == cyc[-1] and set(cyc) == {"a", "b", "c"}


# --------------------------------------------------------------------------- the real graph

@pytest.fixture(scope="module")
def graph() -> tuple[set[str], list[Edge]]:
    return import_graph()


@pytest.fixture(scope="module")
def rules() -> list[Rule]:
    return parse_rules(DOC.read_text())


def test_graph_sees_the_three_mapped_folders(graph):
    modules, edges = graph
    assert {"labkit", "labkit.cli", "labkit.drivers", "labkit.drivers.base", "labkit.analysis",
            "labkit.analysis.frf", "labkit.sim.core", "labkit.experiments.runner"} <= modules
    # A known edge of each kind, so a parser that silently finds nothing cannot pass.
    pairs = {(e.importer, e.target) for e in edges}
    assert ("labkit.drivers.base", "labkit.errors") in pairs
    assert ("labkit.cli", "labkit.commands") in pairs


def test_every_rule_names_existing_modules(graph, rules):
    modules, _ = graph
    for r in rules:
        for name in (r.importer, *r.forbidden, *r.allowed):
            assert any(under(m, name) for m in modules), f"docs/architecture.md rule names {name}, no such module"


def test_import_rules_hold(graph, rules):
    _, edges = graph
    found = violations(edges, rules)
    new = {k: v for k, v in found.items() if k not in PENDING}
    stale = sorted(k for k in PENDING if k not in found)
    lines = [f"{imp} imports {tgt} ({', '.join(where)}): {breaks(imp, tgt, rules).why}"  # type: ignore[union-attr]
             for (imp, tgt), where in sorted(new.items())]
    assert not new, "imports docs/architecture.md forbids:\n" + "\n".join(lines)
    assert not stale, f"fixed, remove from PENDING in tests/test_imports.py: {stale}"


def test_only_the_cli_imports_the_cli(graph):
    _, edges = graph
    cli_side = ("labkit.cli", "labkit.commands", "labkit.__main__")
    bad = sorted(f"{e.importer} -> {e.target} ({e.where})" for e in edges
                 if any(under(e.target, c) for c in cli_side[:2])
                 and not any(under(e.importer, c) for c in cli_side)
                 and (e.importer, e.target) not in PENDING)
    assert not bad, "library code imports the CLI:\n" + "\n".join(bad)


def test_subpackages_form_no_cycle(graph):
    _, edges = graph
    # The root package is base (everyone reads labkit.__version__); its one function,
    # labkit.open, is a lazy facade over labkit.files, so its outgoing imports are left out.
    pairs = {(subpackage(e.importer), subpackage(e.target)) for e in edges
             if (e.importer, e.target) not in PENDING and e.importer != FIRST_PARTY}
    cycle = find_cycle(pairs)
    assert cycle is None, "sub-packages import each other in a cycle: " + " -> ".join(cycle or [])
