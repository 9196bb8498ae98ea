"""The gateway, the Python API and the CLI reach a medium through its Link, never past it (links/link.py's promise).

An AST walk of vstig_hw/gateway/, vstig_hw/api/ and cli/ fails on `x.framing` or `x.transport` where `x` is not
`self` (a module's own attribute of those names is its own) or a capture `record` (whose `framing` is a framing's
name), outside the two places the promise names: the
compiled path's choice of its Receiver, Encoder and read (gateway/compiled.py, which the C twin needs the
framing's parameters and the transport's declared CompiledHandle for) and the ROS 2 part (gateway/ros2.py,
which publishes through the ROS 2 transport and stamps its framing).
"""

from __future__ import annotations

import ast
from pathlib import Path

import vstig_hw

ROOT = Path(vstig_hw.__file__).resolve().parents[1]
CHECKED = (ROOT / "vstig_hw" / "gateway", ROOT / "vstig_hw" / "api", ROOT / "cli")
ALLOWED = {ROOT / "vstig_hw" / "gateway" / "compiled.py", ROOT / "vstig_hw" / "gateway" / "ros2.py"}
PAST_THE_LINK = ("framing", "transport")
NOT_LINKS = ("self", "cls", "record")  # a module's own attributes, and a capture Record's framing name


def reaches_past_a_link(source: str) -> list[str]:
    """`x.framing` / `x.transport` where x is not `self`, and getattr(x, "framing"...), as `line: code`."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr in PAST_THE_LINK:
            if not (isinstance(node.value, ast.Name) and node.value.id in NOT_LINKS):
                found.append(f"{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("getattr", "hasattr") \
                and any(isinstance(arg, ast.Constant) and arg.value in PAST_THE_LINK for arg in node.args):
            found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


def test_the_gateway_the_api_and_the_cli_reach_no_medium_past_its_link() -> None:
    modules = [path for folder in CHECKED for path in sorted(folder.rglob("*.py")) if path not in ALLOWED]
    assert len(modules) > 50
    found = [f"{path.relative_to(ROOT)}:{line}" for path in modules for line in reaches_past_a_link(path.read_text())]
    assert found == []


def test_the_walk_finds_a_reach_past_a_link_and_lets_a_modules_own_attribute_be() -> None:
    source = ("def f(node, link):\n"
              "    link.framing.capture_name\n"
              "    getattr(node.links[0], 'transport')\n"
              "class Part:\n"
              "    def g(self):\n"
              "        return self.transport\n")
    assert sorted(reaches_past_a_link(source)) == ["2: link.framing", "3: getattr(node.links[0], 'transport')"]


def test_the_allowed_places_exist_and_still_need_it() -> None:
    """An exception that no longer reaches past a link is dropped from the promise (and from ALLOWED)."""
    assert all(reaches_past_a_link(path.read_text()) for path in ALLOWED)
