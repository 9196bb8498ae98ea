"""One module per medium: the registry loads only the medium a spec names, and no medium imports another."""

from __future__ import annotations

import json
import subprocess
import sys
from importlib import import_module
from pathlib import Path

import pytest
from module_imports import imports_of

import vstig_hw.links
from vstig_hw.links import LinkSpec, examples, grammar, notes, parse
from vstig_hw.links.registry import SCHEMES

LINKS_DIR = Path(vstig_hw.links.__file__).parent
MEDIA = sorted({module for module, _ in SCHEMES.values()})
HEAVY = ("can", "serial", "zenoh", "rclpy", "vstig_msgs")  # python-can, pyserial, eclipse-zenoh, ROS 2


def _loaded_after(code: str) -> set[str]:
    """The modules a fresh interpreter holds after running `code`."""
    probe = f"import json, sys\n{code}\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True)
    return set(json.loads(done.stdout))


def _unwanted(loaded: set[str], media: tuple[str, ...], libraries: tuple[str, ...]) -> list[str]:
    transports = tuple(f"vstig_hw.transports.{name}" for name in ("serial", "zenoh", "can", "blabbermouth", "ros2"))
    return sorted(name for name in loaded
                  if name.split(".")[0] in libraries or name in transports
                  or name in {f"vstig_hw.links.{medium}" for medium in media})


def test_parsing_a_can_spec_loads_no_other_medium() -> None:
    loaded = _loaded_after("import vstig_hw.links as links\nlinks.parse('can:socketcan:vcan0?extended=1')")
    assert "vstig_hw.links.can" in loaded
    assert not _unwanted(loaded, ("serial", "zenoh", "blabbermouth"), ("serial", "zenoh"))


@pytest.mark.parametrize("spec", ["serial:/dev/ttyUSB0?framing=epuck4", "kilobot-ohc:/dev/ttyUSB0",
                                  "zenoh:lab?scout=1", "blabbermouth:k1,k2?size=64&deployment=lab.toml",
                                  "ros2:lab?domain=3&discovery=subnet"])
def test_parsing_a_spec_loads_no_library_and_no_transport(spec: str) -> None:
    medium = SCHEMES[spec.partition(":")[0]][0]
    loaded = _loaded_after(f"import vstig_hw.links as links\nlinks.parse({spec!r})")
    assert f"vstig_hw.links.{medium}" in loaded
    assert not _unwanted(loaded, tuple(m for m in MEDIA if m != medium), HEAVY)


def test_the_help_text_loads_every_medium_but_no_library() -> None:
    loaded = _loaded_after("import vstig_hw.links as links\nlinks.grammar(); links.examples(); links.notes()")
    assert {f"vstig_hw.links.{medium}" for medium in MEDIA} <= loaded
    assert not _unwanted(loaded, (), HEAVY)


@pytest.mark.parametrize("path", sorted(LINKS_DIR.glob("*.py")), ids=lambda p: p.name)
def test_no_module_imports_a_medium_other_than_itself(path: Path) -> None:
    others = {f"vstig_hw.links.{medium}" for medium in MEDIA if medium != path.stem}
    imported = imports_of(path, "vstig_hw.links")
    bad = sorted(name for name in imported if any(name == o or name.startswith(o + ".") for o in others))
    assert not bad, f"{path.name} imports {bad}"


@pytest.mark.parametrize("scheme", sorted(SCHEMES))
def test_every_scheme_names_a_medium_with_a_parser_and_help(scheme: str) -> None:
    module_name, parser = SCHEMES[scheme]
    module = import_module(f"vstig_hw.links.{module_name}")
    assert callable(getattr(module, parser))
    assert module.GRAMMAR and module.EXAMPLES and set(module.EXAMPLES) == set(module.NOTES)
    assert set(module.EXAMPLES) <= set(examples()) and set(module.GRAMMAR) <= set(grammar())
    spec = parse(next(e for e in examples()[scheme] if e.startswith(f"{scheme}:")))
    assert isinstance(spec, LinkSpec) and spec.kind == scheme


def test_help_text_lists_every_kind_once_in_the_order_of_the_registry() -> None:
    assert list(examples()) == ["can", "serial", "kilobot-ohc", "bittybuzz", "xbee", "rosbuzz", "blabbermouth", "zenoh",
                                "ros2", "mavlink"]
    assert list(notes()) == list(examples())
    assert grammar()[0].startswith("can:") and grammar()[-1].startswith("mavlink:")


def test_a_link_spec_type_accepts_parsed_specs_only() -> None:
    assert not isinstance("can:virtual:lab", LinkSpec)
    with pytest.raises(ValueError, match="unknown kind 'tcp'; a spec starts with can:, serial:, kilobot-ohc:"):
        parse("tcp:localhost")
