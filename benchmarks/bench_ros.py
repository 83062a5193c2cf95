"""The ROS 2 nodes' speed.

`--map MAP`: the localization node's overhead, the image-to-pose round trip through `vlocbench ros
localize` (its own process, loopback DDS) against the same localization in process (SIFT, 800x600).
The node localizes the latest image on its timer; at `--rate` Hz the wait for the next tick is at
most 1/rate, part of the overhead measured. Medians over `--repeats` images after a warm-up.

`--sim TOWN`: the simulator node as fast as it goes (20 Hz steps, one 800x600 camera at 2 Hz,
driving on cmd_vel): simulated seconds per wall second, median of `--repeats` 10 s stretches.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from collections.abc import Iterable
from pathlib import Path

from vlocbench.ros.environment import local_only


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--map", type=Path, help="a SIFT map of 800x600 images")
    ap.add_argument("--sim", help="a town for the simulator node instead")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--rate", type=float, default=100.0, help="the node's localization_frequence")
    args = ap.parse_args()
    env = local_only(os.environ)
    env.setdefault("ROS_DOMAIN_ID", "91")
    if args.sim:
        sim_speed(args.sim, args.repeats)
        return
    if args.map is None:
        ap.error("give --map or --sim")

    import rclpy
    from builtin_interfaces.msg import Time
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from vlocbench.loc.gallery import Gallery
    from vlocbench.loc.localizer import MapLocalizer
    from vlocbench.ros.messages import msg_from_image

    gallery = Gallery.load(json.loads((args.map / "map.json").read_text())["gallery"])
    camera = next(iter(gallery.cameras.values()))
    images = [gallery.load_image(gallery.names[k]) for k in range(5, 5 + 7 * args.repeats, 7)]
    localizer = MapLocalizer(args.map)
    localizer.localize(images[0], camera)  # warm-up
    node_proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "vlocbench.cli",
            "ros",
            "localize",
            "--map",
            str(args.map),
            "--ros-args",
            "-p",
            f"localization_frequence:={args.rate}",
        ],
        env=env,
    )
    rclpy.init()
    probe = Node("bench_ros")
    got: list[float] = []
    probe.create_subscription(
        PoseWithCovarianceStamped,
        "visual_pose_estimate",
        lambda m: got.append(time.perf_counter()),
        10,
    )
    status: list[dict[str, float]] = []  # the node's own times (s), from its diagnostics

    def on_status(msg: DiagnosticArray) -> None:
        values = {v.key: v.value for v in msg.status[0].values}
        if "computation_time_s" in values:
            status.append({k: float(v) for k, v in values.items() if k.endswith("_s")})

    probe.create_subscription(DiagnosticArray, "diagnostics", on_status, 10)
    pub = probe.create_publisher(Image, "image", 10)
    while pub.get_subscription_count() == 0:
        rclpy.spin_once(probe, timeout_sec=0.1)
    # per image, in process and then through the node: the pair sees the same machine state
    here: list[dict[str, float]] = []  # stage -> s, "total" -> s
    there: list[dict[str, float]] = []  # the node's stage times, "round_trip" -> s
    for k, image in enumerate([images[0], *images]):  # the first is a warm-up
        t = time.perf_counter()
        seconds = localizer.localize(image, camera).seconds
        here.append({**seconds, "total": time.perf_counter() - t})
        got.clear()
        status.clear()
        t = time.perf_counter()
        pub.publish(msg_from_image(image, Time(sec=k + 1), "camera"))
        while not (got and status) and time.perf_counter() - t < 30:
            rclpy.spin_once(probe, timeout_sec=0.005)
        if not got:
            sys.exit(f"image {k}: no pose from the node within 30 s")
        there.append({**status[0], "round_trip": got[0] - t})
    node_proc.send_signal(signal.SIGINT)
    node_proc.wait(timeout=30)
    probe.destroy_node()
    rclpy.shutdown()
    here, there = here[1:], there[1:]

    def ms(values: Iterable[float]) -> str:
        return f"{1000 * statistics.median(values):.0f} ms"

    print(f"SIFT, 800x600, node at {args.rate:g} Hz, medians of {len(here)} images:")
    print(
        f"  in process {ms(h['total'] for h in here)}; image to pose through the node "
        f"{ms(t['round_trip'] for t in there)}, of which localizing "
        f"{ms(t['computation_time_s'] for t in there)}"
    )
    print(
        f"  overhead, per image: {ms(t['round_trip'] - h['total'] for h, t in zip(here, there))}"
        f"; transport and the timer's wait alone: "
        f"{ms(t['round_trip'] - t['computation_time_s'] for t in there)}"
    )
    for stage in [s for s in here[0] if s != "total"]:
        print(
            f"  {stage}: {ms(h[stage] for h in here)} in process, "
            f"{ms(t[f'{stage}_s'] for t in there)} in the node"
        )


def sim_speed(town: str, repeats: int) -> None:
    import rclpy
    from geometry_msgs.msg import Twist
    from rclpy.parameter import Parameter

    from vlocbench.ros.sim_node import SimulatorNode

    rclpy.init()
    node = SimulatorNode(town, parameter_overrides=[Parameter("real_time_factor", value=0.0)])
    command = Twist()
    command.linear.x = 4.0
    node.command = command
    factors = []
    for k in range(repeats + 1):  # the first is a warm-up
        t0, wall0 = node.sim.state.time_s, time.perf_counter()
        while node.sim.state.time_s - t0 < 10.0:
            rclpy.spin_once(node, timeout_sec=0.0)
        if k:
            factors.append((node.sim.state.time_s - t0) / (time.perf_counter() - wall0))
    node.destroy_node()
    rclpy.shutdown()
    print(
        f"simulator node, {town}: {statistics.median(factors):.1f}x real time "
        f"(20 Hz, one 800x600 camera at 2 Hz; median of {repeats} 10 s stretches)"
    )


if __name__ == "__main__":
    main()
