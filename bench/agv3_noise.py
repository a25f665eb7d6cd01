"""How does the AGV-3 virtual device answer `*IDN?` after line noise?

Feeds seeded random bytes, then "\\r\\n*IDN?\\r\\n", through `fleet-sim emulate`'s `Emulator`
stepped by hand in simulated time (the AGV-3 profile's wire: 9600 8N1, 10 bits a character,
both directions timed), and reports when the reply's last character reaches the host, counted
from the command's last character arriving, and how many error bytes the noise produced. The
0.25 s reply limit is the document's ("Om inget returneras inom 0.25s").

    .venv/bin/python bench/agv3_noise.py [--bytes 25000 100000] [--seed 3]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from agv_model.emulate import Emulator  # noqa: E402
from agv_model.link import device_settings  # noqa: E402
from agv_model.profile import load_profile  # noqa: E402
from agv_model.protocols import get_device  # noqa: E402

COMMAND = b"*IDN?\r\n"
ANSWER = b"AGV-3\r\n"


def run(noise_bytes: int, seed: int) -> tuple[float, int, float]:
    """(seconds from the command's last character arriving to the answer's last character
    reaching the host, bytes the device sent before the answer, wall seconds taken)."""
    profile = load_profile("agv-3")
    link = profile.link
    noise = np.random.default_rng(seed).bytes(noise_bytes) + b"\r\n"
    device = get_device("agv3", **device_settings("agv3", link))
    read_fd, write_fd = os.pipe()
    os.set_blocking(read_fd, False)
    os.set_blocking(write_fd, False)
    sent = 0
    start = time.perf_counter()
    try:
        emu = Emulator(profile, device, write_fd, np.random.default_rng(seed))
        emu.heard(noise + COMMAND, 0.0)
        arrived_s = (len(noise) + len(COMMAND)) * link.char_s
        for step_s in np.arange(1.0, arrived_s + 1.0, 1.0):  # the device has answered by then
            emu.step(float(step_s))
            sent += _drain(read_fd)
        # The answer is the last thing on the wire: its last character is in at `free_s`.
        answer_s = emu.to_host.free_s + link.latency_s - arrived_s
        sent += len(emu.to_host.queue) + emu.dropped_bytes
    finally:
        os.close(read_fd)
        os.close(write_fd)
    return answer_s, sent - len(ANSWER), time.perf_counter() - start


def _drain(fd: int) -> int:
    n = 0
    while True:
        try:
            chunk = os.read(fd, 1 << 16)
        except BlockingIOError:
            return n
        if not chunk:
            return n
        n += len(chunk)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bytes", type=int, nargs="+", default=[25_000, 100_000])
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()
    print(f"{'noise bytes':>11} {'answer s':>10} {'error bytes':>12} {'wall s':>7}")
    for noise_bytes in args.bytes:
        answer_s, error_bytes, wall_s = run(noise_bytes, args.seed)
        print(f"{noise_bytes:11d} {answer_s:10.3f} {error_bytes:12d} {wall_s:7.2f}")


if __name__ == "__main__":
    main()
