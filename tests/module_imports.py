"""What a module imports, read from its source (no import runs): for the tests that keep packages apart."""

from __future__ import annotations

import ast
from pathlib import Path


def imports_of(path: Path, package: str) -> set[str]:
    """Absolute names of every module `path` imports, relative imports resolved against `package` (the module's
    own); `from . import x` names `package.x`."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                names.add(node.module or "")
            else:
                base = package.rsplit(".", node.level - 1)[0]
                names.add(f"{base}.{node.module}" if node.module else base)
                names.update(f"{base}.{alias.name}" for alias in node.names if not node.module)
    return names
