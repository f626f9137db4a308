"""`cell soak` in the twin: the tree's answer to single injected faults, the person between runs,
every part accounted from the simulated state, the faults configuration, and the CLI end to end."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from cell.config import config_from_text, load_config
from trees.yaml_lines import ConfigError

CONFIG = """\
sim:
  seed: 0
bin:
  parts: {parts}
workflow:
  machining_time_s: 0.5
log:
  tick_log: null
  state_file: null
  journal: null
"""


def _soak(cycles: int, on_twin: Callable[[Any], None], parts: int = 2) -> dict[str, Any]:
    from cell.assemble import prepare
    from lab.soak_cmd import Soak
    from sim.faults import no_faults

    config, doc = config_from_text(CONFIG.format(parts=parts))
    prep = prepare(config, doc)
    return Soak(prep, no_faults(), 0, 0, cycles, quiet=True, on_twin=on_twin).run()


def _force(name: str) -> Callable[[Any], None]:
    done = {"n": 0}

    def on_twin(injector: Any) -> None:
        if done["n"] == 0:
            injector.force(name)
        done["n"] += 1

    return on_twin


def _accounted(r: dict[str, Any]) -> None:
    found = sum(r["parts"].values()) + sum(r["removed_by_operator"].values())
    assert found + r["shipped"]["parts"] == r["spawned"] and r["unaccounted"] == 0


def test_a_missed_grasp_is_put_back_and_retried() -> None:
    r = _soak(1, _force("missed_grasp"))
    assert r["faults"]["injected"]["missed_grasp"] == 1
    assert r["aborts_by_reason"].get("grasp: missed") == 1, r["aborts_by_reason"]
    assert r["cycles_done"] == 1 and r["judged_ok"].get("packed") == 1  # the retry packed it
    assert r["unhandled_exceptions"] == 0 and r["operator_interventions"] == 0
    _accounted(r)


def test_a_lost_camera_frame_fails_the_look_and_the_retry_goes_on() -> None:
    r = _soak(1, _force("camera_lost"))
    assert r["faults"]["injected"]["camera_lost"] == 1
    assert r["aborts_by_reason"].get("perceive: device_lost") == 1, r["aborts_by_reason"]
    assert r["cycles_done"] == 1 and r["unhandled_exceptions"] == 0
    _accounted(r)


def test_a_part_dropped_in_transit_falls_and_the_person_clears_it() -> None:
    r = _soak(2, _force("drop_in_transit"), parts=2)
    assert r["faults"]["injected"]["drop_in_transit"] == 1
    assert r["stops_by_reason"], r["aborts_by_reason"]  # the cell stopped for a person
    # The part fell out of the cell (the floor, or the machine's top): never into the box.
    assert r["removed_by_operator"]["on_floor"] + r["removed_by_operator"]["in_slot"] >= 1
    assert r["operator_interventions"] >= 1 and r["cycles_attempted"] == 2
    assert r["cycles_done"] == 1  # after the reset the cell goes on and packs the other part
    _accounted(r)


def test_an_exception_escaping_the_tree_is_counted_and_a_fresh_twin_goes_on() -> None:
    calls = {"twins": 0}

    def on_twin(injector: Any) -> None:
        calls["twins"] += 1
        if calls["twins"] == 1:

            def broken(*_: Any, **__: Any) -> None:
                raise RuntimeError("driver bug")

            injector.arm.inner.move_to = broken

    r = _soak(1, on_twin, parts=1)
    assert r["unhandled_exceptions"] == 1
    assert "RuntimeError: driver bug" in r["exceptions"][0]["error"]
    assert any("driver bug" in line for line in r["exceptions"][0]["traceback"])
    assert r["twins"] == 2 and r["cycles_done"] == 1
    _accounted(r)


# ------------------------------------------------------------------------- configuration
def test_faults_section_validates_names_and_rates(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("faults:\n  enabled: true\n  rates:\n    gremlins: 0.1\n")
    with pytest.raises(ConfigError) as exc:
        load_config(bad)
    text = str(exc.value)
    assert f"{bad}:4: faults.rates.gremlins: unknown key" in text and "missed_grasp" in text
    bad.write_text("faults:\n  rates:\n    ft_spike: 1.5\n")
    with pytest.raises(ConfigError, match=r"bad.yaml:3: faults.rates.ft_spike: .*1.5"):
        load_config(bad)
    bad.write_text("faults:\n  rates:\n    ft_spike: -0.1\n")
    with pytest.raises(ConfigError, match="faults.rates.ft_spike"):
        load_config(bad)
    config, _ = config_from_text("faults:\n  enabled: true\n  seed: 4\n  rates: {ft_spike: 1}\n")
    assert config.faults.enabled and config.faults.seed == 4 and config.faults.rates.ft_spike == 1


def test_cli_refuses_a_bad_faults_section(tmp_path: Path) -> None:
    cfg = tmp_path / "cell.yaml"
    cfg.write_text("faults:\n  rates:\n    camera_lost: 1.5\n")
    r = subprocess.run(
        [sys.executable, "-m", "cell.cli", "soak", "--config", str(cfg), "--cycles", "1"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2
    assert "cell soak: error:" in r.stderr and "faults.rates.camera_lost" in r.stderr
    assert "Traceback" not in r.stderr


# ------------------------------------------------------------------------------ the CLI
def test_cell_soak_two_cycles_end_to_end(tmp_path: Path) -> None:
    cfg = tmp_path / "cell.yaml"
    cfg.write_text(CONFIG.format(parts=2))
    out = tmp_path / "soak.json"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "cell.cli",
            "soak",
            "--config",
            str(cfg),
            "--cycles",
            "2",
            "--faults",
            "default",
            "--seed",
            "0",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode in (0, 1), r.stderr
    s = json.loads(out.read_text())
    assert s["cycles"] == 2 and s["cycles_attempted"] >= 2
    assert set(s["parts"]) == {"in_bin", "in_hand", "in_slot", "packed", "on_floor"}
    assert s["unhandled_exceptions"] == len(s["exceptions"])
    assert isinstance(s["aborts_by_reason"], dict)
    assert s["faults"]["rates"]["missed_grasp"] == 0.03  # --faults default
    assert sum(s["faults"]["opportunities"].values()) > 0
    _accounted(s)
    assert r.returncode == (0 if s["unhandled_exceptions"] == 0 else 1)


def _one_cycle_with(
    fault: str, after_event: str, in_leaf: str = "", at_step: str = ""
) -> tuple[Any, Any, dict[str, int], Any]:
    """One cycle of the shipped tree in a fresh twin with ``fault`` forced at the first chance
    after the workflow event ``after_event`` (and, given ``in_leaf``, once the running leaf's
    name is that; given ``at_step`` too, once its skill's step is that): (result, state, parts,
    injector)."""
    from cell.assemble import open_backend, prepare
    from cell.runner import TickLog, TickLoop
    from sim.faults import no_faults, twin_injector

    config, doc = config_from_text(CONFIG.format(parts=1))
    prep = prepare(config, doc)
    backend = open_backend(prep)
    injector = twin_injector(backend, no_faults(), 0)
    backend.wrap_devices(injector.wrap)
    prep.ctx.devices = backend.devices
    prep.ctx.limits.cycles = 1
    forced = {"done": False}

    def on_tick(tick: int) -> None:
        if forced["done"] or not any(e["kind"] == after_event for e in prep.state.events):
            return
        tip = prep.root.tip()
        if at_step and getattr(getattr(tip, "skill", None), "step", None) != at_step:
            return
        if not in_leaf or (tip is not None and tip.name == in_leaf):
            injector.force(fault)
            forced["done"] = True

    loop = TickLoop(
        prep.root, backend, prep.state, TickLog(None), 125.0, wrench=lambda: None, on_tick=on_tick
    )
    try:
        result = loop.run(300.0)
        parts = backend.account()
    finally:
        backend.close()
    assert forced["done"]
    return result, prep.state, parts, injector


def test_a_missed_grasp_in_the_slot_is_retried_not_a_stop() -> None:
    """The part is still in the slot after a missed pinch there: the shipped tree looks and
    grasps again instead of calling a person."""
    # The next close after machining is the pinch in the slot.
    result, state, parts, injector = _one_cycle_with("missed_grasp", "machined")
    assert injector.injected["missed_grasp"] == 1
    assert any("closed on nothing" in a["reason"] for a in state.aborts)
    assert result.status == "success" and state.stop_reason is None
    assert parts["packed"] == 1



def test_an_ft_spike_while_packing_is_retried_with_the_part_held_not_a_stop() -> None:
    """A spike on the way to the box aborts that motion with the part still in the hole grasp:
    the shipped tree checks the part is held and packs again instead of calling a person."""
    result, state, parts, injector = _one_cycle_with(
        "ft_spike", "picked_from_slot", in_leaf="pack in box"
    )
    assert injector.injected["ft_spike"] == 1
    spikes = [a["reason"] for a in state.aborts if "force-torque abort" in a["reason"]]
    assert spikes and spikes[0].startswith("pack in box"), state.aborts
    assert result.status == "success" and state.stop_reason is None
    assert parts["packed"] == 1 and parts["in_hand"] == 0


@pytest.mark.parametrize(
    ("fault", "after", "leaf", "step", "finisher"),
    [
        ("protective_stop", "picked_from_slot", "pack in box", "let go", "LeaveBox"),
        ("ft_spike", "picked", "feed slot", "let go", "LeaveSlot"),
        ("protective_stop", "machined", "pick from slot", "holding the part", "LiftFromSlot"),
    ],
)
def test_a_step_stopped_past_its_hand_over_is_finished_not_a_stop(
    fault: str, after: str, leaf: str, step: str, finisher: str,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A fault on the first motion after the part changed hands (the packing's and the feed's
    let go, the pick's checked pinch) stops the step with the part already where it belongs:
    the shipped tree finishes the step from where the arm stands instead of calling a person,
    and the twin judges the part packed. (A protective stop: the twin's arm, like the UR's
    controller, takes the next motion command after it; the cell's own UR driver asks a
    person to unlock one.)"""
    from trees import behaviours

    finished: list[str] = []
    cls = getattr(behaviours, finisher)
    original = cls.on_success

    def on_success(self: Any) -> None:
        finished.append(type(self).__name__)
        original(self)

    monkeypatch.setattr(cls, "on_success", on_success)
    result, state, parts, injector = _one_cycle_with(fault, after, in_leaf=leaf, at_step=step)
    assert finished == [finisher]  # the rest was done by the finisher, once
    assert injector.injected[fault] == 1
    assert len(state.aborts) == 1, state.aborts  # the fault's, and nothing after it
    assert result.status == "success" and state.stop_reason is None, state.stop_reason
    assert parts["packed"] == 1 and parts["in_hand"] == 0 and parts["in_slot"] == 0
    kinds = [e["kind"] for e in state.events]
    assert kinds.count("fed") == kinds.count("picked_from_slot") == kinds.count("packed") == 1


def test_a_part_dropped_on_the_way_to_the_box_is_not_packed_again() -> None:
    """With the hand empty the retry's condition fails: the cell stops for a person rather than
    run the packing with nothing held."""
    result, state, parts, injector = _one_cycle_with("drop_in_transit", "picked_from_slot")
    assert injector.injected["drop_in_transit"] == 1
    assert result.status == "failure"
    assert state.stop_reason and "part lost between the slot and the box" in state.stop_reason
    assert parts["packed"] == 0


def test_a_short_ft_link_loss_while_packing_is_waited_out_not_a_stop() -> None:
    """The FT stream drops for 5-50 samples during the packing: the motion is stopped at once,
    the retry waits for the link and packs; the cell does not stop (safety.ft_link_grace_s)."""
    result, state, parts, injector = _one_cycle_with(
        "link_lost", "picked_from_slot", in_leaf="pack in box"
    )
    assert injector.injected["link_lost"] == 1
    assert any("force-torque sensor lost" in a["reason"] for a in state.aborts), state.aborts
    assert result.status == "success" and state.stop_reason is None
    assert parts["packed"] == 1 and parts["in_hand"] == 0


def _report(**over: Any) -> dict[str, Any]:
    base: dict[str, Any] = {
        "cycles": 3, "cycles_attempted": 3, "cycles_done": 2, "unhandled_exceptions": 0,
        "exceptions": [], "spawned": 10, "unaccounted": 0, "operator_interventions": 1,
        "false_bin_empty": 0, "bin_refills": 1, "twins": 1,
        "parts": {"in_bin": 7, "in_hand": 0, "in_slot": 0, "packed": 2, "on_floor": 0},
        "removed_by_operator": {"in_bin": 0, "in_hand": 1, "in_slot": 0, "on_floor": 0},
        "shipped": {"boxes": 0, "parts": 0}, "aborts_by_reason": {"timeout": 1},
        "stops_by_reason": {"x": 1}, "events": {"picked": 3}, "judged_ok": {"picked": 3},
        "runs": [{"status": "success"}], "seed": 0, "sim_time_s": 100.0, "wall_s": 50.0,
        "interrupted": False,
        "faults": {"seed": 0, "rates": {"ft_spike": 0.1}, "opportunities": {"ft_spike": 5},
                   "drawn": {"ft_spike": 1}, "injected": {"ft_spike": 1}},
    }
    base.update(over)
    return base


def test_shard_reports_add_up_into_one_report() -> None:
    from lab.soak_cmd import merge_reports

    a = _report()
    b = _report(
        seed=10000019, unhandled_exceptions=1, exceptions=[{"run": 1, "error": "E"}],
        aborts_by_reason={"timeout": 2, "missed": 1}, unaccounted=0,
        faults={"seed": 10000019, "rates": {"ft_spike": 0.1}, "opportunities": {"ft_spike": 7},
                "drawn": {"ft_spike": 0}, "injected": {"ft_spike": 0}},
    )
    m = merge_reports([a, b], wall=60.0)
    assert m["cycles"] == 6 and m["cycles_done"] == 4 and m["spawned"] == 20
    assert m["unhandled_exceptions"] == 1 and m["exceptions"][0]["shard"] == 1
    assert m["parts"]["in_bin"] == 14 and m["removed_by_operator"]["in_hand"] == 2
    assert m["aborts_by_reason"] == {"timeout": 3, "missed": 1}
    assert m["faults"]["opportunities"] == {"ft_spike": 12} and m["faults"]["seed"] == [0, 10000019]
    assert m["wall_s"] == 60.0 and m["wall_s_per_cycle"] == 10.0
    assert [s["seed"] for s in m["shards"]] == [0, 10000019] and m["runs"][1]["shard"] == 1


def test_the_person_ships_a_box_whose_part_stands_off_its_place() -> None:
    from cell.assemble import prepare
    from lab.soak_cmd import Soak
    from sim.faults import no_faults

    config, doc = config_from_text(CONFIG.format(parts=1))
    prep = prepare(config, doc)
    soak = Soak(prep, no_faults(), 0, 0, 1, quiet=True)
    soak._open_twin(prep)
    try:
        backend = soak.backend
        assert soak._box_in_order([])  # an empty box, nothing recorded
        soak.filled = {0}
        assert not soak._box_in_order([])  # recorded filled, but the box is empty
        from sim.part_body import upright_pose

        x, y = soak.place_xy[0]
        z = prep.geometry.tray_places[0][2]
        body = backend._spawn(upright_pose(backend.part, x - 0.001, y, z))
        backend.bodies.append(body)
        assert soak._box_in_order([body])  # 1 mm off its place: in order
        backend.remove_part(body)
        off = backend._spawn(upright_pose(backend.part, x - 0.008, y, z))
        backend.bodies.append(off)
        assert off.tilt() > 1.5  # upright: only the offset is wrong
        assert not soak._box_in_order([off])  # 8 mm off: the person ships the box
    finally:
        backend.close()


def test_cli_refuses_zero_workers() -> None:
    r = subprocess.run(
        [sys.executable, "-m", "cell.cli", "soak", "--cycles", "1", "--workers", "0"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2 and "--workers" in r.stderr and "Traceback" not in r.stderr
