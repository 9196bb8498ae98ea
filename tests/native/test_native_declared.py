"""The C reads and calls on Python objects only names their types declare.

vstig_hw/_cext/module.c holds the one list of the names the compiled data path uses, each with the Python type
it belongs to; the extension exports it as `DECLARED`. A rename on the Python side that the C does not follow
fails here, not at run time on a robot's link.
"""

from __future__ import annotations

import importlib
import inspect
from types import ModuleType
from typing import Any

import pytest

from vstig_hw.gateway.delivery_state import DeliveryState
from vstig_hw.transports.base import CompiledHandle


def _owner(where: str) -> Any:
    module_name, _, qualname = where.partition(":")
    owner: Any = importlib.import_module(module_name)
    for part in qualname.split(".") if qualname else ():
        owner = getattr(owner, part)
    return owner


def _declared(owner: Any, name: str) -> bool:
    """A slot, a class annotation, or an attribute of the class (a method, property or class constant)."""
    if isinstance(owner, ModuleType) or hasattr(owner, name):
        return hasattr(owner, name)
    return any(name in getattr(klass, "__slots__", ()) or name in inspect.get_annotations(klass)
               for klass in getattr(owner, "__mro__", ()))


def test_every_name_the_c_uses_is_declared_on_its_type(compiled: ModuleType) -> None:
    undeclared = [f"{where}.{name}" for where, names in compiled.DECLARED.items() for name in names
                  if not _declared(_owner(where), name)]
    assert undeclared == [], f"the C uses names its types do not declare: {undeclared}"


def test_the_state_shared_with_the_node_and_the_transports_is_exactly_their_slots(compiled: ModuleType) -> None:
    # these two exist for the C alone: every slot is one it uses, and it uses nothing else on them
    declared = compiled.DECLARED
    assert set(declared["vstig_hw.gateway.delivery_state:DeliveryState"]) == set(DeliveryState.__slots__)
    assert set(declared["vstig_hw.transports.base:CompiledHandle"]) == set(CompiledHandle.__slots__)


def test_no_private_name_is_used(compiled: ModuleType) -> None:
    private = [f"{where}.{name}" for where, names in compiled.DECLARED.items() for name in names
               if name.startswith("_")]
    assert private == []


@pytest.mark.parametrize("renamed", ["retry_at", "wake"])
def test_the_check_fails_for_a_name_a_type_no_longer_declares(renamed: str) -> None:
    # the check itself can fail: a slot gone from the declared type is found undeclared
    stripped = type("Stripped", (), {"__slots__": tuple(s for s in DeliveryState.__slots__ if s != renamed)})
    assert not _declared(stripped, renamed)
    assert _declared(DeliveryState, renamed)
