"""Complexity ratchet: ruff's C901 (cyclomatic complexity > 10) and PLR0913 (> 5 arguments),
and functions longer than 100 lines, checked against the offenders listed in
``.ci/complexity_baseline.txt``.

A new offender fails the check (split the function, or pass a dataclass); an offender that
was fixed must leave the list (the count can only fall). ``--update`` rewrites the list.
Also printed: C901 offenders per 1,000 lines of code in each top-level folder.

Usage: python .ci/complexity.py [--update]
"""
from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BASELINE = ROOT / ".ci" / "complexity_baseline.txt"
FOLDERS = ("labkit", "drivers", "analysis")
MAX_LINES = 100


def _function_at(tree: ast.Module, row: int) -> str:
    best = ""
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.lineno == row:
            best = node.name
    return best or f"line {row}"


def offenders() -> set[str]:
    proc = subprocess.run(["ruff", "check", *FOLDERS, "--select", "C901,PLR0913", "--output-format", "json",
                           "--exit-zero", "-q"], cwd=ROOT, capture_output=True, text=True, check=True)
    found: set[str] = set()
    trees: dict[str, ast.Module] = {}
    for item in json.loads(proc.stdout or "[]"):
        rel = str(Path(item["filename"]).resolve().relative_to(ROOT))
        tree = trees.setdefault(rel, ast.parse((ROOT / rel).read_text(encoding="utf-8")))
        found.add(f"{item['code']} {rel}::{_function_at(tree, item['location']['row'])}")
    for folder in FOLDERS:
        for src in sorted((ROOT / folder).rglob("*.py")):
            rel = str(src.relative_to(ROOT))
            for node in ast.walk(ast.parse(src.read_text(encoding="utf-8"))):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    if (node.end_lineno or node.lineno) - node.lineno + 1 > MAX_LINES:
                        found.add(f"LONG {rel}::{node.name}")
    return found


def density(found: set[str]) -> dict[str, float]:
    out = {}
    for folder in FOLDERS:
        lines = sum(len(p.read_text(encoding="utf-8").splitlines()) for p in (ROOT / folder).rglob("*.py"))
        c901 = sum(1 for f in found if f.startswith(f"C901 {folder}/"))
        out[folder] = round(1000 * c901 / max(lines, 1), 2)
    return out


def main() -> int:
    found = offenders()
    if "--update" in sys.argv:
        BASELINE.write_text("\n".join(sorted(found)) + "\n", encoding="utf-8")
    listed = {ln.strip() for ln in BASELINE.read_text(encoding="utf-8").splitlines() if ln.strip()}
    new, fixed = sorted(found - listed), sorted(listed - found)
    print(f"complexity: {len(found)} offenders (C901 > 10, PLR0913 > 5 arguments, functions > {MAX_LINES} lines); "
          f"C901 per 1,000 lines: {density(found)}")
    for item in new:
        print(f"  new offender (split it or pass a dataclass): {item}")
    for item in fixed:
        print(f"  fixed, remove from .ci/complexity_baseline.txt: {item}")
    return 1 if new or fixed else 0


if __name__ == "__main__":
    sys.exit(main())
