"""`binpick emulate cell` as its own process, against the real drivers and `binpick pick`: ports
reopened, the camera over its socket equal to the in-process renderer, a replayed scan equal to
the live one, three picks removing three parts according to world.json, the example cell file
(`binpick pick --example`) picking the last with only its ports and camera edited, a clean SIGTERM.

One twin serves the whole module (spawned once, always stopped in teardown); the tests run in
file order because the last ones change the twin (picks, then SIGTERM)."""

from __future__ import annotations

import difflib
import json
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import binpick
from binpick.cell import FolderReplay, ReplayMismatchError, ScanRecorder, cell_from_file, load_cell_file
from binpick.cell import camera_socket as wire
from binpick.cell.cell_file import GRIPPER_SHAPE_KEYS
from binpick.devices.emulators.clock import PhysicalClock
from binpick.errors import CalibrationError, DeviceTimeout, PortClosedError, ProtocolError, TruncatedReplyError
from binpick.scan import load_scan
from binpick.sim import Cell as Layout
from binpick.sim import SimCamera
from binpick.vision import extract_line, reconstruct

SEED = 0
COUNT = 4
FRAMES = 40
ROOT = Path(__file__).resolve().parents[2]


def _child_env() -> dict:
    """The environment of a spawned binpick: the package these tests import (an installed wheel
    or a source tree with its built core), and a plain PATH."""
    return {"PYTHONPATH": str(Path(binpick.__file__).resolve().parents[1]), "PATH": "/usr/bin:/bin"}


class _Twin:
    """The spawned twin: its folder, its process and the lines it printed."""

    def __init__(self, out: Path) -> None:
        self.out = out
        env = _child_env()
        argv = [sys.executable, "-m", "binpick", "emulate", "cell", "--out", str(out)]
        argv += ["--count", str(COUNT), "--frames", str(FRAMES), "--seed", str(SEED), "--speed-scale", "10"]
        self.t0 = time.perf_counter()
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
        self.lines: list[str] = []
        self.picked = 0  # parts the tests picked out of the twin's bin so far
        self.ready = threading.Event()
        threading.Thread(target=self._drain, daemon=True).start()
        if not self.ready.wait(60.0):
            self.stop()
            raise AssertionError("the twin printed no ready line within 60 s:\n" + "".join(self.lines))
        self.startup_s = time.perf_counter() - self.t0

    def _drain(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line)
            if " ready " in line:
                self.ready.set()

    def world(self) -> dict:
        return json.loads((self.out / "world.json").read_text())

    def world_after(self, frames_served: int, timeout_s: float = 5.0) -> dict:
        """world.json once it shows at least ``frames_served`` frames (the twin rewrites it on
        its tick, every 0.1 s), so it describes the state the last frame was rendered in."""
        deadline = time.monotonic() + timeout_s
        while True:
            world = self.world()
            if world["frames_served"] >= frames_served or time.monotonic() > deadline:
                return world
            time.sleep(0.02)

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                return self.proc.wait(15.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5.0)
        return self.proc.returncode


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    t = _Twin(tmp_path_factory.mktemp("twin"))
    try:
        shutil.copy(t.out / "true_calibration.toml", t.out / "calibration.toml")
        yield t
    finally:
        t.stop()


@pytest.fixture(scope="module")
def cell(twin):
    """The cell of the twin's cell.toml (real drivers on the twin's ptys, TwinCamera), open."""
    c = cell_from_file(load_cell_file(twin.out / "cell.toml"))
    with c:
        yield c


def test_the_twin_writes_a_cell_file_pick_can_load_and_its_true_calibration(twin):
    assert {"cell.toml", "true_calibration.toml", "world.json", "camera.sock"} <= {p.name for p in twin.out.iterdir()}
    assert twin.startup_s < 30.0
    world = twin.world()
    assert world["version"] == 1 and len(world["in_bin"]) == COUNT and world["removed"] == []
    assert world["held"] is None and world["collisions"] == []
    true = binpick.calibration.CellCalibration.load(twin.out / "true_calibration.toml")
    assert true == Layout().calibration()
    # The board the capture aims at is the twin's own.
    board, cell_file = Layout().board, load_cell_file(twin.out / "cell.toml")
    assert cell_file.numbers("calibration_board", "pattern", 2).tolist() == list(board.pattern)
    assert cell_file.number("calibration_board", "square_mm") == board.square
    np.testing.assert_allclose(cell_file.numbers("calibration_board", "center_mm", 3), board.center, atol=1e-6)
    # The gripper a cell reads from the file is the twin's, shape and TCP.
    mine, true = binpick.cell.config_from_file(cell_file).gripper, binpick.sim.sim_gripper(Layout())
    for key in GRIPPER_SHAPE_KEYS:
        assert getattr(mine, key) == pytest.approx(getattr(true, key)), key
    assert true.finger_length_mm == 90.0  # the paper's 80 mm deep bin, 10 mm tip reach
    np.testing.assert_allclose(mine.T_flange_gripper, true.T_flange_gripper, atol=1e-6)


def test_the_ports_reopen_again_and_again_with_the_real_drivers(twin):
    cell_file = load_cell_file(twin.out / "cell.toml")
    for _ in range(3):
        c = cell_from_file(cell_file)
        with c:  # opens the robot session, enables the motor, activates and opens the gripper
            assert np.isfinite(c.robot.read_pose()).all()
            assert abs(c.motor.move_to(0.05, wait=True) - 0.05) < 0.01
            assert c.gripper.status().activated
            assert c.camera.grab().shape == (778, 1032, 3)


class _Snapshot:
    """What SimCamera renders from, as world.json and a frame's header tell it (the twin at rest)."""

    def __init__(self, world: dict, frame: wire.Frame) -> None:
        self.layout = Layout()
        self.num_threads = 0
        poses = np.array([p["T_base_object"] for p in world["in_bin"]])
        ids = [p["id"] for p in world["in_bin"]]
        self.pile = SimpleNamespace(bin=self.layout.bin, model=binpick.parts.tee(), ids=ids, poses=poses)
        self.robot_emulator = SimpleNamespace(pose=lambda: frame.T_base_flange)
        self._angle = frame.angle
        self.clock = PhysicalClock()

    def settle_pending(self) -> None:
        pass

    def laser_angle(self) -> float:
        return self._angle


def test_a_twin_frame_is_the_in_process_render_of_the_actual_pose_and_angle(twin, cell):
    cell.robot.move_to(cell.config.scan_poses[0])  # the arm at the scan pose (from above the approach height)
    cell.motor.move_to(0.02, wait=True)
    image = cell.camera.grab()
    frame = cell.camera.last
    np.testing.assert_allclose(frame.T_base_flange, cell.robot.read_pose(), atol=0.05)
    assert abs(frame.angle - cell.motor.present_angle()) < 1e-6
    world = twin.world_after(frame.counter + 1)
    assert world["frames_served"] >= frame.counter + 1, "world.json caught up with the frame within 5 s"
    np.testing.assert_allclose(world["T_base_flange"], frame.T_base_flange, atol=1e-9)
    here = SimCamera(_Snapshot(world, frame), seed=SEED + frame.counter)
    here.begin(frame.T_base_flange)
    expected = here.grab()
    assert image.shape == expected.shape
    assert len(extract_line(image)) > 300, "the laser line is in the frame"
    np.testing.assert_array_equal(image, expected)


def test_a_replayed_scan_gives_the_live_cloud(twin, cell, tmp_path):
    twin_camera = cell.camera
    cell.camera = ScanRecorder(twin_camera, cell.config.calibration, tmp_path)
    try:
        live = cell.scan()
        folder = cell.camera.flush()
    finally:
        cell.camera = twin_camera
        cell.close()  # the replay below opens the twin's ports again, from a cell file
    assert len(live.points) > 5000
    rebuilt = reconstruct(load_scan(folder), volume=cell.config.scan_volume)
    np.testing.assert_array_equal(np.asarray(rebuilt.points), np.asarray(live.points))
    text = (twin.out / "cell.toml").read_text()
    twin_camera_table = 'source = "twin"\nsocket = "camera.sock"'
    assert twin_camera_table in text
    replay_file = twin.out / "replay.toml"
    replay_file.write_text(text.replace(twin_camera_table, f'source = "replay"\nfolder = "{folder}"'))
    with cell_from_file(load_cell_file(replay_file)) as replaying:
        assert isinstance(replaying.camera, FolderReplay)
        replayed = replaying.scan()
        assert replaying.camera.remaining == 0
    np.testing.assert_array_equal(np.asarray(replayed.points), np.asarray(live.points))
    replay = FolderReplay(folder)
    moved = live.T_base_flanges[0].copy()
    moved[0, 3] += 5.0
    with pytest.raises(ReplayMismatchError, match=r"recorded with the flange at .*5\.00 mm"):
        replay.begin(moved)
    replay.begin(live.T_base_flanges[0])
    with pytest.raises(ReplayMismatchError, match="recorded with the laser at"):
        replay.laser_at(live.angles[0] + 0.01)


def test_pick_names_the_missing_calibration(twin, tmp_path):
    (tmp_path / "cell.toml").write_text((twin.out / "cell.toml").read_text())
    with pytest.raises(CalibrationError, match=r"calibration.toml does not exist; solve the cell's calibration"):
        cell_from_file(load_cell_file(tmp_path / "cell.toml"))


def test_the_twin_answers_a_bad_request_with_an_error_text(twin):
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(10.0)
        s.connect(str(twin.out / "camera.sock"))
        s.sendall(b"GET / HTTP")
        with pytest.raises(ProtocolError, match="the twin refused: camera request: magic is b'GET "):
            wire.read_reply(s)


def _serve_once(path: Path, reply: bytes, *, hold_s: float = 0.0) -> threading.Thread:
    """A peer that reads one request, sends ``reply`` and hangs up (after ``hold_s``)."""
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    srv.bind(str(path))
    srv.listen(1)

    def run() -> None:
        conn, _ = srv.accept()
        conn.recv(wire.REQUEST_SIZE)
        conn.sendall(reply)
        time.sleep(hold_s)
        conn.close()
        srv.close()

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


_IMAGE = np.zeros((10, 12, 3), np.uint8)
_GOOD = wire.encode_frame(_IMAGE, 7, 0.1, np.eye(4))


def _header(**change) -> bytes:
    fields = list(wire._HEADER.unpack(_GOOD[: wire.HEADER_SIZE]))
    names = ["magic", "version", "status", "dtype", "channels", "height", "width", "counter", "angle"]
    for k, v in change.items():
        fields[names.index(k) if k != "length" else len(fields) - 1] = v
    return wire._HEADER.pack(*fields)


@pytest.mark.parametrize(
    ("reply", "error", "match"),
    [
        (_GOOD[:-100], TruncatedReplyError, r"hung up after 260 of 360 bytes"),
        (_GOOD[:50], TruncatedReplyError, r"reply header: the twin hung up after 50 of 168"),
        (b"", PortClosedError, "closed the connection"),
        (_header(magic=b"HTTP") + _GOOD[wire.HEADER_SIZE :], ProtocolError, "not b'BPCR'"),
        (_header(version=9), ProtocolError, "protocol version 9"),
        (_header(length=5) + b"12345", ProtocolError, r"declares 5 payload bytes for a 12×10×3 frame \(360"),
        (_header(height=1 << 20, width=1 << 20), ProtocolError, "outside what binpick reads"),
        (_header(channels=4), ProtocolError, "expected uint8 BGR"),
        (_header(status=7), ProtocolError, "unknown reply status 7"),
        (wire.encode_error("the arm is gone"), ProtocolError, "the twin refused: the arm is gone"),
        (_header(status=1, length=1 << 30), ProtocolError, "error reply declares"),
    ],
    ids=[
        "truncated-frame",
        "truncated-header",
        "hung-up",
        "magic",
        "version",
        "length",
        "huge",
        "channels",
        "status",
        "error-text",
        "huge-error",
    ],
)
def test_bad_replies_raise_device_errors_naming_the_fault(tmp_path, reply, error, match):
    from binpick.cell import TwinCamera

    path = tmp_path / "bad.sock"
    peer = _serve_once(path, reply)
    cam = TwinCamera(path, timeout_s=5.0)
    try:
        with pytest.raises(error, match=match):
            cam.grab()
    finally:
        cam.close()
        peer.join(5.0)


def test_a_silent_twin_times_out_and_an_absent_one_is_named(tmp_path):
    from binpick.cell import TwinCamera

    path = tmp_path / "quiet.sock"
    peer = _serve_once(path, b"", hold_s=1.0)
    cam = TwinCamera(path, timeout_s=0.2)
    with pytest.raises(DeviceTimeout, match="no answer within 0.2 s"):
        cam.grab()
    cam.close()
    peer.join(5.0)
    with pytest.raises(PortClosedError, match="start `binpick emulate cell"):
        TwinCamera(tmp_path / "nobody.sock")


def test_binpick_pick_removes_three_parts_in_three_attempts(twin, tmp_path):
    before = twin.world()
    out = tmp_path / "pick"
    env = _child_env()
    t0 = time.perf_counter()
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "binpick",
            "pick",
            str(twin.out / "cell.toml"),
            "--picks",
            "3",
            "--out",
            str(out),
            "--save-scans",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=240,
    )
    pick_s = time.perf_counter() - t0
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    picks = json.loads((out / "picks.json").read_text())["picks"]
    assert [p["success"] for p in picks] == [True, True, True], done.stdout[-4000:]
    time.sleep(0.5)  # the twin's world tick
    after = twin.world()
    removed = set(after["removed"]) - set(before["removed"])
    assert len(removed) == 3 and removed <= {p["id"] for p in before["in_bin"]}
    assert len(after["in_bin"]) == len(before["in_bin"]) - 3
    assert after["held"] is None
    sweeps = sorted((out / "scans").iterdir())
    assert [p.name for p in sweeps] == ["sweep_000", "sweep_001", "sweep_002"], done.stdout[-6000:]
    assert all(len(load_scan(p)) == FRAMES for p in sweeps)
    assert [c for c in after["collisions"] if c["with"] == "bin" or c["with"].startswith("robot")] == []
    # The rehearsal's physical time, on the twin's hardware clock: each pick's stages, and the rate.
    for p in picks:
        stages = p["stage_s"]
        assert p["cycle_time_s"] == pytest.approx(sum(stages.values()))
        assert stages["scan.sweep"] >= FRAMES / 15.0 and stages["motion"] > 0.5  # (the arm may start at the scan pose)
    assert re.search(
        r"cycle time \(the cell's hardware clock, and binpick's compute\): mean [\d.]+ s .*picks per hour", done.stdout
    )
    assert after["clock_s"] >= sum(p["cycle_time_s"] - p["stage_s"]["compute"] for p in picks)
    twin.picked += 3
    print(f"twin start-up {twin.startup_s:.1f} s, binpick pick --picks 3 {pick_s:.1f} s")


def _table_lines(text: str, table: str) -> list[str]:
    """The lines of ``[table]`` in a cell file: its header to the line before the next table."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"[{table}]"))
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[")), len(lines))
    while not lines[end - 1].strip():
        end -= 1
    return lines[start:end]


def test_the_printed_example_picks_from_the_twin_with_only_its_ports_and_camera_edited(twin, tmp_path):
    env = _child_env()
    printed = subprocess.run(
        [sys.executable, "-m", "binpick", "pick", "--example"], capture_output=True, text=True, env=env, timeout=60
    )
    assert printed.returncode == 0, printed.stderr
    example, twin_file = printed.stdout, load_cell_file(twin.out / "cell.toml")
    # What an integrator edits: the three ports, and the [camera] table replaced by the twin's.
    lines = example.splitlines()
    for table in ("robot", "motor", "gripper"):
        head = lines.index(f"[{table}]")
        at = next(i for i in range(head, len(lines)) if lines[i].startswith("port = "))
        lines[at] = re.sub(r'"[^"]*"', json.dumps(twin_file.text(table, "port")), lines[at], count=1)
    mine = _table_lines("\n".join(lines), "camera")
    at = lines.index(mine[0])
    lines[at : at + len(mine)] = _table_lines((twin.out / "cell.toml").read_text(), "camera")
    edited = "\n".join(lines) + "\n"
    changed = [d for d in difflib.ndiff(example.splitlines(), lines) if d[:1] in "+-"]
    assert all(re.match(r"[+-] (port = |\[camera\]|source = |socket = |device = |\s+#)", d) for d in changed), changed
    path = twin.out / "example.toml"  # beside the twin's calibration.toml, which the example names
    path.write_text(edited)
    before = twin.world()
    out = tmp_path / "pick"
    done = subprocess.run(
        [sys.executable, "-m", "binpick", "pick", str(path), "--picks", "1", "--out", str(out)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    picks = json.loads((out / "picks.json").read_text())
    assert [p["success"] for p in picks["picks"]] == [True] and picks["lifted"] == [1]
    time.sleep(0.5)  # the twin's world tick
    after = twin.world()
    removed = set(after["removed"]) - set(before["removed"])
    assert len(removed) == 1 and removed <= {p["id"] for p in before["in_bin"]}, (before, after)
    # The twin's ground truth (its camera socket's WORLD) names the part the pick removed.
    (pid,) = removed
    assert f"removed 1 part ({pid}); failures: none" in done.stdout, done.stdout[-2000:]
    assert picks["picks"][0]["picked_instance"] == pid and picks["picks"][0]["truth"]["instance"] == pid
    assert after["held"] is None
    twin.picked += 1


def test_sigterm_ends_the_twin_cleanly_with_its_files_in_place(twin):
    assert twin.stop() == 0
    names = {p.name for p in twin.out.iterdir()}
    assert {"cell.toml", "true_calibration.toml", "world.json"} <= names and "camera.sock" not in names
    assert len(twin.world()["removed"]) == twin.picked > 0
    assert any(" stopped " in line for line in twin.lines)
