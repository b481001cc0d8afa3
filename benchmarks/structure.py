"""The shape of the estimation code: ``python benchmarks/structure.py``.

Prints, read from the source (nothing runs):

* every function (methods and nested functions included) in ``src/rideid/estimate/`` longer than 80 lines;
* the branches of the three orchestrators — the single-model fit (``fit/identify.py``), the fit with unknown
  roads or tracks as built (``fit/anyroad.py``) and the model choice (``choice/model_choice.py``) — counted as
  ``if`` statements plus conditional expressions (``ast.If`` + ``ast.IfExp``; an ``elif`` is an ``if``).

Issue 50's figures were taken on the tree before ``estimate/`` was split into folders; the same count on that
tree (commit e0fe98b) gave identify 116, anyroad 105, model_choice 88: 309 in all.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "src" / "rideid" / "estimate"
ORCHESTRATORS = ("fit/identify.py", "fit/anyroad.py", "choice/model_choice.py")
LONG = 80


def long_functions(root: Path = ROOT, limit: int = LONG) -> list[tuple[int, str, str]]:
    """``(lines, file, qualified name)`` of every function over ``limit`` lines below ``root``, longest first."""
    out = []
    for path in sorted(root.rglob("*.py")):
        tree, rel = ast.parse(path.read_text(), str(path)), str(path.relative_to(root))

        def walk(node, prefix, rel=rel):
            for child in ast.iter_child_nodes(node):
                name = prefix
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                    name = f"{prefix}{child.name}"
                    if not isinstance(child, ast.ClassDef) and child.end_lineno - child.lineno + 1 > limit:
                        out.append((child.end_lineno - child.lineno + 1, rel, name))
                    name += "."
                walk(child, name, rel)
        walk(tree, "")
    return sorted(out, reverse=True)


def branches(path: Path) -> int:
    """``if`` statements plus conditional expressions in a module."""
    return sum(isinstance(n, (ast.If, ast.IfExp)) for n in ast.walk(ast.parse(path.read_text(), str(path))))


def main() -> int:
    longs = long_functions()
    print(f"functions over {LONG} lines in estimate/: {len(longs)}")
    for n, f, name in longs:
        print(f"  {n:4d}  {f}  {name}")
    counts = {f: branches(ROOT / f) for f in ORCHESTRATORS}
    print(f"orchestrators' branches: {sum(counts.values())} "
          f"({', '.join(f'{f} {n}' for f, n in counts.items())})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
