"""Simulator benchmarks: settling a pile of 20 tees, renderer frames per second, a 90-frame scan
at 1032 × 778, and one frame of each depth camera 30° off vertical — on one core (num_threads=1 /
RAYON_NUM_THREADS=1)."""

import os
import time

os.environ.setdefault("RAYON_NUM_THREADS", "1")

import binpick  # noqa: E402
from binpick import sim  # noqa: E402


def main() -> None:
    tee = binpick.parts.tee()
    t0 = time.perf_counter()
    pile = sim.Pile(tee, 20, seed=3)
    t1 = time.perf_counter()
    print(
        f"pile of 20 tees ({len(tee.faces)} faces): settled={pile.last_settle.settled} in {t1 - t0:.2f} s "
        f"(sim time {pile.last_settle.simulated_time:.2f} s), interpenetration {pile.max_interpenetration():.3f} mm"
    )
    cell = sim.Cell()
    world = sim.World.of_pile(sim.Pile(tee, 12, seed=3))
    t0 = time.perf_counter()
    view = world.view(cell, num_threads=1)
    t1 = time.perf_counter()
    angles = cell.sweep(90)
    frames = view.frames(angles, seed=3, num_threads=1)
    t2 = time.perf_counter()
    print(
        f"view (ray cast {cell.camera.width}x{cell.camera.height}): {t1 - t0:.2f} s; "
        f"90 frames: {t2 - t1:.2f} s ({90 / (t2 - t1):.1f} fps); scan total {t2 - t0:.2f} s; {frames.shape}"
    )

    for name in ("kinect", "tof", "structured_light"):
        camera = getattr(sim.DepthCamera, name)().looking_at((400.0, 0.0, 40.0), distance=900.0, tilt_deg=30.0)
        sim.render_depth(world, camera, num_threads=1)  # the camera's ray table, built once
        t0 = time.perf_counter()
        frame = sim.render_depth(world, camera, seed=1, num_threads=1)
        print(
            f"depth frame {name} ({camera.intrinsics.width}x{camera.intrinsics.height}): "
            f"{time.perf_counter() - t0:.2f} s, {len(frame.cloud)} points"
        )


if __name__ == "__main__":
    main()
