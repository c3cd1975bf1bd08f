"""Count the places outside a vendor's own packages that name a vendor.

A vendor's own packages are ``fcmaster/protocol/<vendor>/`` and ``fcmaster/sim/<vendor>/``.
Two counts, for a tree given as the first argument (default: this checkout):

- ``lines``: source lines matching the words the review looked for (``danfoss``,
  ``mitsubishi``, ``enc``, ``fc``, the codec classes), comments and docstrings included —
  the same as ``grep -rnE "danfoss|mitsubishi|\\benc\\b|\\bfc\\b|FcCodec|MitsubishiCodec|
  EncCodec" fcmaster --include=*.py`` without the vendor packages;
- ``code``: what can branch — a string constant equal to a protocol id outside a docstring,
  and an import of a vendor package — by module.

    python benchmarks/vendor_names.py [TREE]
"""

from __future__ import annotations

import ast
import re
import sys
from collections import Counter
from pathlib import Path

VENDORS = ("danfoss_fc", "mitsubishi", "enc")
IDS = ("danfoss-fc", "mitsubishi", "enc")
WORDS = re.compile(r"danfoss|mitsubishi|\benc\b|\bfc\b|FcCodec|MitsubishiCodec|EncCodec")


def _outside(tree: Path) -> list[Path]:
    package = tree / "fcmaster"
    own = [package / layer / v for layer in ("protocol", "sim") for v in VENDORS]
    return sorted(p for p in package.rglob("*.py") if not any(p.is_relative_to(o) for o in own))


def _docstrings(module: ast.Module) -> set[int]:
    ids = set()
    for node in ast.walk(module):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                ids.add(id(body[0].value))
    return ids


def _code_places(path: Path) -> int:
    module = ast.parse(path.read_text(encoding="utf-8"))
    docs = _docstrings(module)
    count = 0
    for node in ast.walk(module):
        if isinstance(node, ast.Constant) and node.value in IDS and id(node) not in docs:
            count += 1
        elif isinstance(node, ast.ImportFrom) and node.module:
            parts = node.module.split(".")
            names = [a.name for a in node.names]
            if any(v in parts for v in VENDORS) or (
                node.module in ("fcmaster.protocol", "fcmaster.sim")
                and any(n in VENDORS for n in names)
            ):
                count += 1
    return count


def main() -> None:
    """Print both counts and the modules behind the second."""
    tree = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent.parent)
    lines = 0
    code: Counter[str] = Counter()
    for path in _outside(tree):
        text = path.read_text(encoding="utf-8")
        lines += sum(1 for line in text.splitlines() if WORDS.search(line))
        places = _code_places(path)
        if places:
            code[str(path.relative_to(tree))] = places
    print(f"lines naming a vendor outside its packages: {lines}")
    print(f"code places (protocol-id strings, vendor imports): {sum(code.values())}")
    for module, places in code.most_common():
        print(f"  {places:3d}  {module}")


if __name__ == "__main__":
    main()
