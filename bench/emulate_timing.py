"""How close does `fleet-sim emulate` keep to the link model in real time?

For each bundled vehicle profile with a protocol: the link model's time for one command
(`agv_model.link`, simulated), then the round trip a pyserial host measures against
`fleet-sim emulate` on a pseudo-terminal (median, min and max of --repeats exchanges; the host
waits 20 ms between commands). The measured time should be the model's plus a little scheduling
overhead, never less. TABO's profile has BLE jitter (0-30 ms), so its spread is wide by design.
These machines are noisy: compare figures within one run of this script only.

    .venv/bin/python bench/emulate_timing.py [--repeats 30]
"""

from __future__ import annotations

import argparse
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import serial

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from agv_model.link import Link  # noqa: E402
from agv_model.profile import load_profile  # noqa: E402
from agv_model.protocols import Command, get_codec  # noqa: E402

COMMANDS: dict[str, tuple[str, Command | bytes]] = {
    "carriro-ad-plus": ("battery?", b"battery?\n"),
    "ktm-02": ("RequestStatusCmd", Command("RequestStatusCmd")),
    "tabo": ("GBI", b"GBI\n"),
    "agv-3": ("*IDN?", b"*IDN?\r\n"),
}
PARITY = {"none": serial.PARITY_NONE, "even": serial.PARITY_EVEN, "odd": serial.PARITY_ODD}


def measure(name: str, command: Command | bytes, repeats: int) -> tuple[float, list[float]]:
    profile = load_profile(name)
    assert profile.protocol is not None
    model = Link(profile.protocol, profile.link).exchange(command)
    model_s = model.reply_s - model.jitter_s
    codec = get_codec(profile.protocol)
    proc = subprocess.Popen([sys.executable, "-m", "fleet_sim.cli", "emulate", profile.protocol,
                             "--profile", name], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        path = proc.stdout.readline().strip()
        link = profile.link
        port = serial.Serial(path, link.baud, parity=PARITY[link.parity], timeout=2.0)
        time.sleep(1.5)  # past CarriRo's start-up banner
        port.reset_input_buffer()
        times: list[float] = []
        for _ in range(repeats):
            data = command if isinstance(command, bytes) else codec.encode(command)
            start = time.perf_counter()
            port.write(data)
            reply = port.read(model.rx_bytes)
            times.append(time.perf_counter() - start)
            assert len(reply) == model.rx_bytes, reply
            time.sleep(0.02)
        port.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(10)
    return model_s, times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    print(f"{'profile':16} {'command':18} {'model ms':>9} {'median ms':>10} {'min ms':>8} "
          f"{'max ms':>8} {'median-model':>13}")
    for name, (label, command) in COMMANDS.items():
        model_s, times = measure(name, command, args.repeats)
        median = statistics.median(times)
        print(f"{name:16} {label:18} {model_s * 1e3:9.2f} {median * 1e3:10.2f} "
              f"{min(times) * 1e3:8.2f} {max(times) * 1e3:8.2f} "
              f"{(median - model_s) * 1e3:+13.2f}")


if __name__ == "__main__":
    from machine import machine_line  # bench/machine.py, beside this script

    print(machine_line("at start"), flush=True)
    main()
    print(machine_line("at end"))
