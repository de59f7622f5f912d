"""The vision server's own latency (issue 40: ≤ 5 ms per pick on top of the scan and the pose).

The digital twin runs as its own process (``binpick emulate cell``, a pile of 12 tees); binpick's
:class:`~binpick.server.VisionServer` runs in this process on 127.0.0.1 with the twin's laser
motor and camera; the client of ``examples/robots/twin_program.py`` plays the robot program.
After one SCAN at the scan pose, each round is NEXT (the pick is planned) and RESULT -1 (declined,
so that the next NEXT plans another part of the same scan), until no part is left to offer; then
STATUS 1,000 times. Measured at the client, one request at a time:

- NEXT: request-to-reply time minus the server's own locating and planning time
  (``VisionService.compute_ms``) — what the server adds to the pose: parsing, checking the plan's
  conversion to the brand's convention, encoding, the socket both ways;
- RESULT and STATUS: the whole round trip (nothing is computed for them).

    PYTHONPATH=python python benches/server_latency.py [--brand ur] [--out DIR]

Writes ``OUT/server_latency.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples" / "robots"))

from twin_program import VisionClient, pose_numbers  # noqa: E402

from binpick.cell.cell_file import cell_from_file, config_from_file, load_cell_file, robot_from_file  # noqa: E402
from binpick.server import ProgramGripper, ProgramRobot, VisionServer, VisionService, convention  # noqa: E402


def _stats(ms: list) -> dict:
    a = np.asarray(ms)
    return {
        "n": len(a),
        "median_ms": float(np.median(a)),
        "p99_ms": float(np.percentile(a, 99)),
        "max_ms": float(a.max()),
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--brand", default="ur")
    p.add_argument("--out", default="bench-out")
    args = p.parse_args()
    work = Path(tempfile.mkdtemp(prefix="binpick-serve-bench-"))
    twin = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "binpick",
            "emulate",
            "cell",
            "--out",
            str(work),
            "--count",
            "12",
            "--speed-scale",
            "10",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        while not (work / "camera.sock").exists():
            if twin.poll() is not None:
                raise SystemExit("the twin did not start")
            time.sleep(0.2)
        shutil.copy(work / "true_calibration.toml", work / "calibration.toml")
        f = load_cell_file(work / "cell.toml")
        config = config_from_file(f)
        arm = robot_from_file(f)
        arm.open_session()
        arm.move_to(config.scan_poses[0])
        T_scan = arm.read_pose()
        robot = ProgramRobot(limits=None)
        cell = cell_from_file(f, robot=robot, gripper=ProgramGripper(True), num_threads=1)
        robot.limits = cell.config.limits
        cell.motor.enable()
        service = VisionService(cell, convention(args.brand))
        with VisionServer(service, port=0) as server:
            c = VisionClient(*server.address, args.brand)
            c.call("HELLO 1")
            t0 = time.perf_counter()
            scan = c.call("SCAN " + ",".join(f"{x:.6f}" for x in pose_numbers(args.brand, T_scan)))
            scan_ms = (time.perf_counter() - t0) * 1e3
            next_overhead, next_compute, result_rtt = [], [], []
            while True:
                t0 = time.perf_counter()
                r = c.call("NEXT")
                rtt = (time.perf_counter() - t0) * 1e3
                if r.code != 0:
                    break
                next_overhead.append(rtt - service.compute_ms)
                next_compute.append(service.compute_ms)
                t0 = time.perf_counter()
                c.call(f"RESULT {r.numbers[0]:.0f} -1")
                result_rtt.append((time.perf_counter() - t0) * 1e3)
                print(
                    f"pick {r.numbers[0]:.0f}: planned in {next_compute[-1]:.1f} ms, "
                    f"server overhead {next_overhead[-1]:.2f} ms",
                    flush=True,
                )
            status_rtt = []
            for _ in range(1000):
                t0 = time.perf_counter()
                c.call("STATUS")
                status_rtt.append((time.perf_counter() - t0) * 1e3)
            c.call("BYE")
            c.close()
        cell.close()
        arm.close_session()
        arm.close()
    finally:
        os.killpg(twin.pid, signal.SIGTERM)
        twin.wait(timeout=30)
        shutil.rmtree(work, ignore_errors=True)
    report = {
        "brand": args.brand,
        "scan": {"points": scan.numbers[1], "request_to_reply_ms": scan_ms},
        "next_server_overhead": _stats(next_overhead),
        "next_locate_and_plan": _stats(next_compute),
        "result_round_trip": _stats(result_rtt),
        "status_round_trip": _stats(status_rtt),
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "server_latency.json").write_text(json.dumps(report, indent=2))
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
