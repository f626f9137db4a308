"""The web monitor as people use it: a short `cell sim --monitor` watched through its JSON API and
in headless Chromium, and the recorded run served by `cell replay --serve` with its slider.

One real run (the twin, the shipped cell) serves the whole module: the live tests ask while it
runs; the replay tests read the log it left. The browser tests skip, saying what to install, where
Chromium is absent; the API tests run everywhere.
"""

from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from cell.errors import UserError
from cell.monitor.model import Fold, RunModel
from cell.monitor.server import is_loopback, parse_address
from tests.cdp import Browser, find_chromium

ROOT = Path(__file__).resolve().parents[2]
STATUSES = {"RUNNING", "SUCCESS", "FAILURE", "INVALID"}


def get(url: str, timeout: float = 10.0) -> Any:
    with urllib.request.urlopen(url, timeout=timeout) as r:
        return json.loads(r.read())


def wait_url(proc: subprocess.Popen[str], pattern: str, timeout: float = 120.0) -> str:
    """The URL the command prints on stderr, read as it comes."""
    deadline = time.monotonic() + timeout
    assert proc.stderr is not None
    seen = []
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            if proc.poll() is not None:
                break
            continue
        seen.append(line)
        m = re.search(pattern, line)
        if m:
            return m.group(1)
    raise AssertionError(f"no URL printed: {''.join(seen)}")


class LiveRun:
    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "cell.cli",
                "sim",
                "--cycles",
                "1",
                "--max-sim-time",
                "45",
                "--quiet",
                "--monitor",
                "127.0.0.1:0",
                "--json",
                str(tmp / "summary.json"),
            ],
            cwd=tmp,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )
        self.url = wait_url(self.proc, r"monitor on (http://127\.0\.0\.1:\d+/)")
        self.log = tmp / "out" / "cell_ticks.jsonl"

    def running(self) -> bool:
        return self.proc.poll() is None

    def finish(self) -> int:
        self.proc.communicate(timeout=600)
        return self.proc.returncode


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveRun]:
    run = LiveRun(tmp_path_factory.mktemp("mon-live"))
    yield run
    if run.running():
        run.proc.kill()
        run.proc.communicate()


# ------------------------------------------------------------------------------ live, JSON
def test_the_live_api_follows_the_run(live: LiveRun) -> None:
    assert live.running()
    first = get(live.url + "api/tree")
    deadline = time.monotonic() + 60
    while first["tick"] == 0 and time.monotonic() < deadline:
        time.sleep(0.2)
        first = get(live.url + "api/tree")
    assert set(first) >= {"tick", "t", "nodes"}
    assert isinstance(first["tick"], int) and isinstance(first["t"], float)
    nodes = first["nodes"]
    ids = {n["id"] for n in nodes}
    for n in nodes:
        assert set(n) >= {"id", "name", "type", "status", "feedback", "children"}
        assert n["status"] in STATUSES
        assert set(n["children"]) <= ids
    assert nodes[0]["name"] == "cell" and nodes[0]["status"] == "RUNNING"
    # A motion leaf is shown inside its guard and its timeout, with their limits.
    guard = next(n for n in nodes if n["type"] == "ft_guard" and n["name"] == "tilt ft guard")
    assert guard["limits"] == {"force_n": 90.0, "torque_nm": 8.0}
    # Statuses change as the cell works: ask until the tip moved on.
    statuses = {n["name"]: n["status"] for n in nodes}
    later = first
    while time.monotonic() < deadline:
        time.sleep(0.5)
        later = get(live.url + "api/tree")
        if {n["name"]: n["status"] for n in later["nodes"]} != statuses:
            break
    assert later["tick"] > first["tick"]
    assert {n["name"]: n["status"] for n in later["nodes"]} != statuses
    state = get(live.url + "api/state")
    assert state["live"] is True and state["running"] is True
    assert state["wrench"]["t"] and len(state["wrench"]["w"][0]) == 6
    assert state["limits"]["force_n"] > 0
    events = get(live.url + "api/events")
    assert isinstance(events, list)


def test_the_monitor_is_read_only(live: LiveRun) -> None:
    for method in ("POST", "PUT", "DELETE"):
        req = urllib.request.Request(live.url + "api/tree", data=b"{}", method=method)
        with pytest.raises(urllib.error.HTTPError) as info:
            urllib.request.urlopen(req, timeout=10)
        assert info.value.code == 405


# --------------------------------------------------------------------------- live, browser
needs_chromium = pytest.mark.skipif(
    find_chromium() is None,
    reason="headless Chromium is not installed (apt-get install chromium)",
)


def _shown(b: Browser) -> dict[str, str]:
    return b.js(
        "Object.fromEntries([...document.querySelectorAll('#tree .row')]"
        ".map(r => [r.querySelector('.name').textContent, r.dataset.status]))"
    )


@needs_chromium
def test_the_live_page_shows_statuses_change(live: LiveRun, tmp_path: Path) -> None:
    from PIL import Image, ImageChops

    assert live.running()
    with Browser() as b:
        b.open(live.url)
        b.wait_for(
            "document.body.dataset.tick > 0 && document.querySelectorAll('#tree .row').length > 10"
        )
        one = _shown(b)
        tick_one = int(b.js("document.body.dataset.tick"))
        shot_one = b.screenshot(tmp_path / "live_1.png")
        deadline = time.monotonic() + 60
        two = one
        while two == one and time.monotonic() < deadline:
            time.sleep(0.5)
            two = _shown(b)
        time.sleep(0.3)
        shot_two = b.screenshot(tmp_path / "live_2.png")
        tick_two = int(b.js("document.body.dataset.tick"))
        assert tick_two > tick_one
        assert two != one, "no node changed status on the page"
        assert "RUNNING" in one.values() and "RUNNING" in two.values()
        assert b.js("document.getElementById('mode').textContent") == "live"
        # The camera's frame and its detections are drawn once the cell has looked.
        b.wait_for("document.querySelectorAll('#frame-svg polygon').length > 0", timeout=60)
        assert b.js("document.getElementById('frame-img').naturalWidth") == 320
    a = Image.open(io.BytesIO(shot_one)).convert("RGB")
    c = Image.open(io.BytesIO(shot_two)).convert("RGB")
    tree_box = (0, 100, 700, 900)  # the tree panel: the statuses' colours differ
    assert ImageChops.difference(a.crop(tree_box), c.crop(tree_box)).getbbox() is not None


# ----------------------------------------------------------------------------- after the run
@pytest.fixture(scope="module")
def replay(live: LiveRun) -> Iterator[tuple[str, Path]]:
    assert live.finish() in (0, 1)  # 1: cut by --max-sim-time, as asked
    proc = subprocess.Popen(
        [sys.executable, "-m", "cell.cli", "replay", str(live.log), "--serve", "127.0.0.1:0"],
        cwd=live.tmp,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    proc.stderr = proc.stdout  # wait_url reads what it prints
    url = wait_url(proc, r"serving (http://127\.0\.0\.1:\d+/)")
    yield url, live.log
    proc.stderr = None  # it was stdout, lent to wait_url
    proc.terminate()
    proc.communicate(timeout=30)


def test_the_log_holds_what_the_page_needs(live: LiveRun, replay: tuple[str, Path]) -> None:
    lines = [json.loads(x) for x in live.log.read_text().splitlines()]
    header = lines[0]["header"]
    assert header["format"] == 2 and header["tree"][0]["name"] == "cell"
    assert any("wrench" in ln and not ln["changed"] for ln in lines[1:])  # a wrench change alone
    frames = [ln["frame"] for ln in lines[1:] if "frame" in ln]
    assert frames and all((live.log.parent / f["file"]).is_file() for f in frames)
    assert any(isinstance(ln.get("blackboard", {}).get("/part/detections"), list) for ln in lines)


def test_the_replay_api_steps_through_the_run(replay: tuple[str, Path]) -> None:
    url, log = replay
    tl = get(url + "api/timeline")
    assert tl["live"] is False and tl["lines"] > 10
    assert tl["marks"]["first_failure"] is not None  # "slot holds part" fails at the start
    ticks = []
    for at in (0, tl["lines"] // 2, tl["lines"] - 1):
        tree = get(url + f"api/tree?at={at}")
        assert tree["tick"] == tl["tick"][at]
        ticks.append(tree["tick"])
    assert ticks == sorted(ticks) and ticks[0] < ticks[-1]
    # The state at the last line is the run's end: the same statuses the whole log folds to.
    fold = Fold()
    lines = [json.loads(x) for x in log.read_text().splitlines()[1:]]
    for line in lines:
        fold.apply(line)
    end = get(url + f"api/tree?at={tl['lines'] - 1}")
    assert {n["name"]: n["status"] for n in end["nodes"]} == {
        name: fold.status.get(name, "INVALID") for name in (n["name"] for n in end["nodes"])
    }
    assert len(get(url + "api/events")) == len(fold.events) + len(fold.aborts)


def test_the_page_carries_what_it_shows_first(replay: tuple[str, Path]) -> None:
    """The first paint needs no request of its own: the page holds the timeline and the
    tree, state and events at ``?at=`` (the start by default), as the API gives them."""
    import re
    import urllib.request

    url, _ = replay
    tl = get(url + "api/timeline")
    at = tl["lines"] // 2
    for query, line in (("", 0), (f"?at={at}", at)):
        with urllib.request.urlopen(url + query, timeout=10) as r:
            html = r.read().decode()
        blob = re.search(r'<script id="first" type="application/json">(.*?)</script>', html, re.S)
        assert blob is not None
        first = json.loads(blob.group(1))
        assert first["timeline"] == tl
        assert first["tree"] == get(url + f"api/tree?at={line}")
        assert first["state"]["tick"] == tl["tick"][line]
        assert first["events"] == get(url + f"api/events?at={line}")


@needs_chromium
def test_the_replay_slider_steps_and_jumps(replay: tuple[str, Path], tmp_path: Path) -> None:
    url, _ = replay
    tl = get(url + "api/timeline")
    with Browser() as b:
        b.open(url)
        b.wait_for(
            "document.getElementById('replaybar').style.display === 'flex' && "
            "document.body.dataset.tick !== undefined"
        )
        assert int(b.js("document.body.dataset.tick")) == tl["tick"][0]
        # Keyboard on the slider, as a person steps tick by tick.
        b.click("#slider")
        start = int(b.js("Number(document.getElementById('slider').value)"))
        b.key("ArrowRight", "ArrowRight", 39)
        b.wait_for(f"Number(document.getElementById('slider').value) === {start + 1}")
        b.wait_for(f"Number(document.body.dataset.tick) === {tl['tick'][start + 1]}")
        b.screenshot(tmp_path / "replay_step.png")
        # The end of the run, then the jump back to the first failure.
        b.js(
            f"(() => {{ const s = document.getElementById('slider'); s.value = {tl['lines'] - 1};"
            " s.dispatchEvent(new Event('input')); })()"
        )
        b.wait_for(f"Number(document.body.dataset.tick) === {tl['tick'][-1]}")
        b.click("#first-failure")
        mark = tl["marks"]["first_failure"]
        b.wait_for(f"Number(document.body.dataset.tick) === {tl['tick'][mark]}")
        failed = b.js(
            "[...document.querySelectorAll('#tree .row.FAILURE .name')].map(e => e.textContent)"
        )
        assert failed, "the first failure shows no failed node"


# ---------------------------------------------------------------------------------- units
def test_addresses() -> None:
    assert parse_address("127.0.0.1:8765") == ("127.0.0.1", 8765)
    assert parse_address("[::1]:0") == ("::1", 0)
    for bad in ("8765", "host:", "host:x", "h:70000"):
        with pytest.raises(UserError):
            parse_address(bad)
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.10")


def test_a_non_loopback_address_warns(capsys: pytest.CaptureFixture[str]) -> None:
    from cell.monitor.server import warn_if_exposed

    warn_if_exposed("127.0.0.1", "--monitor", "sim")
    assert capsys.readouterr().err == ""
    warn_if_exposed("0.0.0.0", "--monitor", "sim")
    assert capsys.readouterr().err.startswith("cell sim: warning: --monitor 0.0.0.0:")


def test_a_bad_address_is_refused_before_the_twin_opens(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "cell.cli", "sim", "--monitor", "localhost"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "cell sim: error: --monitor: expected HOST:PORT (e.g. 127.0.0.1:8765), got 'localhost'"
    ]
    assert not (tmp_path / "out").exists()


def test_any_line_of_a_replay_is_the_fold_of_the_lines_before() -> None:
    header = {
        "tree": [
            {"id": 0, "name": "a", "type": "sequence", "children": [1]},
            {"id": 1, "name": "b", "type": "grasp", "children": []},
        ]
    }
    lines = []
    for i in range(1, 1001):
        s = ("RUNNING", "SUCCESS", "FAILURE")[i % 3]
        line: dict[str, Any] = {
            "tick": i,
            "t": i / 125,
            "changed": {"b": s},
            "tip": "b",
            "feedback": f"step {i}",
            "wrench": [i % 7, 0, 0, 0, 0, 0],
        }
        if i % 97 == 0:
            line["events"] = [{"kind": "picked", "tick": i, "t": i / 125}]
        lines.append(line)
    run = RunModel(header, lines, every=64)
    for index in (0, 63, 64, 65, 500, 999):
        fold = Fold()
        for line in lines[: index + 1]:
            fold.apply(line)
        view = run.view_at(index)
        assert view.status == fold.status and view.feedback == fold.feedback
        assert view.last == fold.last and view.tick == index + 1
        assert view.n_events == len(fold.events)
    assert run.marks()["first_failure"] == 1  # line 2 (tick 2): b FAILURE


def test_a_monitor_bound_to_every_address_links_to_the_machine_s_address() -> None:
    """A browser cannot follow http://0.0.0.0:P/ from another machine, nor may it resolve this
    machine's name: the printed link is an address this machine holds (it can listen there);
    a server bound to one address links to that address."""
    import socket
    import urllib.parse

    from cell.monitor.server import MonitorServer, outward_address

    everywhere = MonitorServer("0.0.0.0", 0).start()
    one = MonitorServer("127.0.0.1", 0)
    try:
        host = urllib.parse.urlsplit(everywhere.url).hostname
        assert host == outward_address() and host not in ("0.0.0.0", "")
        if host != socket.gethostname():  # a network: the link is reachable at that address
            with socket.create_connection((host, everywhere.port), timeout=5):
                pass
        assert one.url == f"http://127.0.0.1:{one.port}/"
    finally:
        everywhere.close()
        one.close()
