"""Record ROS 2 topics into a rosbag2 'ros2'-profile MCAP bag (like `ros2 bag record -s mcap`).

OUT is a new directory: OUT/OUT_0.mcap plus OUT/metadata.yaml, written when recording
stops (Ctrl-C / SIGINT, SIGTERM, or --duration). Messages are recorded as raw bytes, never
re-serialised. Each message is handed to the OS as it arrives, so even a recorder killed
with SIGKILL leaves a bag that `pearl bag-info` reads (it salvages the messages).

Progress lines go to stderr ("subscribed /topic [type]" for each topic as it is found).

Examples:
  pearl record run1                                 # every topic, until Ctrl-C
  pearl record run1 --topics /pearl/speech /pearl/action --duration 3
  pearl record run1 --use-sim-time                  # log times follow /clock
"""
from __future__ import annotations

import argparse
import signal
import time
from typing import Dict, Optional

COMMAND = "record"
HELP = "record topics into a rosbag2 MCAP bag (raw bytes; SIGINT/SIGTERM close it cleanly)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out", metavar="OUT", help="bag directory to create")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="topics to record (default: all non-hidden)")
    parser.add_argument("--exclude", nargs="+", metavar="TOPIC", default=[], help="topics never recorded")
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds (wall clock)")
    parser.add_argument("--use-sim-time", action="store_true", help="stamp messages with /clock time")
    parser.add_argument("--chunk-size", type=int, metavar="BYTES",
                        help="write MCAP chunks of this size (default: unchunked, every message on disk at once)")
    parser.add_argument("--custom-data", nargs="+", metavar="KEY=VALUE", default=[],
                        help="store KEY=VALUE pairs in metadata.yaml custom_data (as ros2 bag record does)")
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout at the end")


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.errors import PearlError

    if args.duration is not None and args.duration <= 0:
        raise PearlError(f"--duration: must be > 0, got {args.duration}")
    custom = {}
    for item in args.custom_data:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise PearlError(f"--custom-data: {item!r} is not KEY=VALUE")
        custom[key] = value
    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    from pearl_pomdp.nodes.bag_recorder import Recorder, log
    from pearl_pomdp.bags.writer import BagWriter
    from pearl_pomdp.cli import print_json

    writer = BagWriter(args.out, chunk_size=args.chunk_size, custom_data=custom)
    stop: Dict[str, Optional[str]] = {"why": None}

    def on_signal(signum, _frame):
        stop["why"] = signal.Signals(signum).name

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    rclpy.init(args=["--ros-args", "--disable-external-lib-logs"],
               signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = rclpy.create_node(
            "pearl_recorder",
            parameter_overrides=[Parameter("use_sim_time", Parameter.Type.BOOL, bool(args.use_sim_time))])
        recorder = Recorder(node, writer, args.topics, exclude=args.exclude,
                            on_subscribe=lambda t, ty: log(f"pearl record: subscribed {t} [{ty}]"))
        log(f"pearl record: recording into {writer.path} "
            f"({'topics ' + ' '.join(args.topics) if args.topics else 'all topics'})")
        deadline = None if args.duration is None else time.monotonic() + args.duration
        from rclpy.executors import SingleThreadedExecutor

        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while stop["why"] is None:
            if deadline is not None and time.monotonic() >= deadline:
                stop["why"] = "duration"
                break
            executor.spin_once(timeout_sec=0.05)
        recorder.stop()
    finally:
        writer.close()
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
        for s, h in old.items():
            signal.signal(s, h)
    counts = dict(recorder.counts)
    log(f"pearl record: stopped ({stop['why']}); {writer.message_count} messages in {writer.path}")
    if args.json:
        print_json({"bag": str(writer.path), "stopped_by": stop["why"], "messages": writer.message_count,
                    "topics": counts})
    return 0
