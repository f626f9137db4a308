"""The fakes the tick-level tests run on must keep obeying the interfaces they stand in for.

A fake that drifts from its interface (a method renamed in drivers/, a parameter added) would let
the skill and tree tests pass against behaviour no real device has. These compare every method of
each interface with the fake's, by name and parameter names, and check the events sink of the
tree tests against the cell's own.
"""

from __future__ import annotations

import inspect

import pytest

from cell.runner import CellState
from drivers.arm import Arm
from drivers.clock import Clock
from drivers.ft_sensor import ForceTorqueSensor
from drivers.gripper import Gripper
from drivers.machine import Machine, TimedMachine
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper
from tests.trees.helpers import Recorder
from trees.context import Events

PAIRS = [
    (Arm, FakeArm),
    (Gripper, FakeGripper),
    (ForceTorqueSensor, FakeFT),
    (Clock, FakeClock),
    (Machine, TimedMachine),
    (Events, Recorder),
]


def interface_members(proto: type) -> dict[str, object]:
    return {name: v for name, v in vars(proto).items() if not name.startswith("_")}


@pytest.mark.parametrize(("proto", "fake"), PAIRS, ids=lambda c: c.__name__)
def test_a_fake_has_every_method_of_its_interface_with_the_same_parameters(proto, fake) -> None:
    members = interface_members(proto)
    assert members, proto  # the interface was found at all
    for name, member in members.items():
        assert hasattr(fake, name), f"{fake.__name__} lacks {proto.__name__}.{name}"
        ours = getattr(fake, name)
        if isinstance(member, property):
            assert isinstance(ours, property), f"{fake.__name__}.{name} must be a property"
            continue
        want = list(inspect.signature(member).parameters)
        got = list(inspect.signature(ours).parameters)
        assert got == want, f"{fake.__name__}.{name}{got} vs {proto.__name__}.{name}{want}"


@pytest.mark.parametrize(("proto", "fake"), PAIRS[:4], ids=lambda c: c.__name__)
def test_a_fake_instance_passes_its_interfaces_runtime_check(proto, fake) -> None:
    assert isinstance(fake(), proto)


def test_the_gripper_fake_has_the_data_its_interface_declares() -> None:
    for name in Gripper.__annotations__:
        value = getattr(FakeGripper(), name)
        assert isinstance(value, float) and value > 0, name


@pytest.mark.parametrize("sink", [Recorder, CellState], ids=lambda c: c.__name__)
def test_the_test_sink_keeps_the_first_stop_reason_as_the_cell_does(sink) -> None:
    s = sink()
    assert s.stopped is None
    s.stop("part lost")
    s.stop("a later reason")
    assert s.stopped == "part lost"
