"""Shared fixtures: bundled files, small scenario builders, golden files and a virtual device
on a real pseudo-terminal."""

from __future__ import annotations

import os
import select
import tty
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import serial
import yaml

from agv_model.protocols import Device
from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.config.scenario import Scenario, load_layout_for, load_scenario, parse_scenario

ROOT = Path(__file__).resolve().parent.parent
LAYOUTS = ROOT / "layouts"
DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="session")
def tiny_layout() -> Layout:
    return load_layout(LAYOUTS / "tiny_loop.yaml")


@pytest.fixture(scope="session")
def warehouse_layout() -> Layout:
    return load_layout(LAYOUTS / "warehouse.yaml")


def make_scenario(layout_file: str = "tiny_loop.yaml", base_dir: Path = LAYOUTS,
                  **fields: Any) -> Scenario:
    """A scenario from keyword fields, as if read from a file in `base_dir`."""
    return parse_scenario({"layout": layout_file, **fields}, "<test scenario>", base_dir)


def write_yaml(path: Path, data: Any) -> Path:
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


ACCEL_MPS2 = 0.5  # P_002 / P_003: 500 mm/s2, both ways
TURN_MPS = 0.3  # Req.Nav.005: a turn is driven at 0.3 m/s


def trapezoid_s(length_m: float, v0: float, v1: float, vmax: float = 1.0) -> float:
    """By hand: accelerate from v0 to vmax, cruise, brake to v1 (long enough to cruise)."""
    d_acc = (vmax**2 - v0**2) / (2 * ACCEL_MPS2)
    d_dec = (vmax**2 - v1**2) / (2 * ACCEL_MPS2)
    assert d_acc + d_dec <= length_m
    return (vmax - v0) / ACCEL_MPS2 + (vmax - v1) / ACCEL_MPS2 + (length_m - d_acc - d_dec) / vmax


# The tiny loop has tags every 4 m and a 90-degree left turn at each corner. A turn is driven at
# 0.3 m/s (Req.Nav.005) over the first 1.0 m after the corner (layout turn_length_m), so an AGV
# slows to 0.3 m/s before each corner and speeds up again 1 m after it.
TURN = TURN_MPS
INTO_CORNER = trapezoid_s(4, 1.0, TURN)  # 1.0 m/s -> 0.3 m/s at the corner
OUT_OF_CORNER = 1.0 / TURN + trapezoid_s(3, TURN, 1.0)  # curve, then back up to 1.0 m/s
START = trapezoid_s(4, 0.0, 1.0)
STOP = trapezoid_s(4, 1.0, 0.0)
# P -> D: start, into SE, out of SE, into NE, out of NE, stop at D. D -> P is the mirror image.
HALF_LOOP_S = START + INTO_CORNER + OUT_OF_CORNER + INTO_CORNER + OUT_OF_CORNER + STOP
# K -> P after leaving parking: K->SW (start, slow for the corner), out of SW, stop at P.
K_TO_P_S = trapezoid_s(4, 0.0, TURN) + OUT_OF_CORNER + STOP
# L_Approach 1.5 s + L_Handshake 1.0 s + L_Transfer (the station's handling) + L_Verify 0.5 s
SUB_STATES_S = 1.5 + 1.0 + 0.5
PICK_S, DROP_S = 20.0 + SUB_STATES_S, 30.0 + SUB_STATES_S


GOLDEN = Path(__file__).parent / "golden"


def golden_hex(protocol: str, name: str) -> bytes:
    """Bytes of a `.hex` golden file: hex byte tokens, `#` comments, `30*246` repeats."""
    out = bytearray()
    for line in (GOLDEN / protocol / f"{name}.hex").read_text(encoding="utf-8").splitlines():
        for token in line.split("#", 1)[0].split():
            byte, _, count = token.partition("*")
            out += bytes([int(byte, 16)]) * int(count or "1")
    return bytes(out)


def golden_bytes(protocol: str, name: str) -> bytes:
    """Exact bytes of a raw golden file."""
    return (GOLDEN / protocol / name).read_bytes()


class PtyLink:
    """A virtual device behind the master side of a pseudo-terminal; the host talks to the
    slave path through pyserial. The device runs in simulated time, `step_s` per loop turn."""

    def __init__(self, device: Device) -> None:
        self.device = device
        self.master_fd, self.slave_fd = os.openpty()
        tty.setraw(self.slave_fd)
        self.port = serial.Serial(os.ttyname(self.slave_fd), baudrate=19200, timeout=0)
        self.now_s = 0.0

    def exchange(self, request: bytes, done: Callable[[bytes], bool], *, step_s: float = 0.01,
                 max_steps: int = 2000) -> bytes:
        """Write `request` from the host, drive the device until `done(received)`; return what
        the host read."""
        self.port.write(request)
        self.port.flush()
        received = b""
        for _ in range(max_steps):
            ready, _, _ = select.select([self.master_fd], [], [], 0.005)
            if ready:
                self.device.receive(os.read(self.master_fd, 4096), self.now_s)
            self.now_s += step_s
            for _, data in self.device.poll(self.now_s):
                os.write(self.master_fd, data)
            received += self.port.read(4096)
            if done(received):
                return received
        raise AssertionError(f"no complete answer after {max_steps} steps; got {received!r}")

    def close(self) -> None:
        self.port.close()
        os.close(self.master_fd)
        os.close(self.slave_fd)


@pytest.fixture
def pty_link() -> Iterator[Callable[[Device], PtyLink]]:
    links: list[PtyLink] = []

    def make(device: Device) -> PtyLink:
        links.append(PtyLink(device))
        return links[-1]

    yield make
    for link in links:
        link.close()


def in_browser(html: str, tmp_path: Path, check: str) -> tuple[dict[str, Any], str]:
    """The page opened in headless Chromium with the script `check` added before </body>
    (it writes JSON into <pre id="img-check"> once the page has loaded): that JSON, and the
    DOM. Skipped without Chromium, except in CI (.ci/run installs it)."""
    import html as html_lib
    import json
    import re
    import shutil
    import subprocess

    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        if os.environ.get("CI"):
            pytest.fail("chromium is missing (.ci/run installs it)")
        pytest.skip("chromium is not installed (apt-get install chromium)")
    page = tmp_path / "report.html"
    page.write_text(html.replace("</body>", check), encoding="utf-8")
    result = subprocess.run(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=10000",
         "--dump-dom", page.as_uri()],
        capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr[-2000:]
    dom = result.stdout
    found = re.search(r'<pre id="img-check">(.*?)</pre>', dom, re.S)
    assert found, dom[-2000:]
    return json.loads(html_lib.unescape(found.group(1))), dom


def scenario_for(layout: str, agvs: int, hours: float, rate: float, policy: str,
                 base: str = "warehouse_shift.yaml", **extra: Any) -> Any:
    """A scenario of experiments/`base` on a bundled layout, seed 11, flat demand, and its
    layout: (scenario, layout)."""
    path = ROOT / "experiments" / base
    scenario = load_scenario(path, {
        "layout": f"../layouts/{layout}.yaml", "fleet.size": agvs, "duration_h": hours,
        "warmup_h": min(0.5, hours / 4), "demand.rate_per_hour": rate, "demand.profile": [],
        "seed": 11, "traffic.policy": policy, **extra})
    return scenario, load_layout_for(scenario, str(path))
