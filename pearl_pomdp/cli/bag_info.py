"""Show what a bag holds, like `ros2 bag info`: files, size, duration, start/end, and per
topic the type, message count, serialization format and offered QoS.

BAG is a bag directory (metadata.yaml + .mcap) or an .mcap file. A bag whose recorder was
killed (no footer, no metadata.yaml) is read up to the last complete message; the report
then says "Salvaged:" with the file and offset where it was cut.

--repair rewrites such a bag in place into a complete one (as `ros2 bag reindex` would),
so that every reader (rosbags, ros2 bag play, Foxglove) opens it.

Examples:
  pearl bag-info bags/table4_clarification
  pearl bag-info run1 --json
  pearl bag-info killed_run --repair
"""
from __future__ import annotations

import argparse

COMMAND = "bag-info"
HELP = "summarise a rosbag2 MCAP bag (works on truncated bags: salvages what is complete)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    parser.add_argument("--repair", action="store_true",
                        help="rewrite a salvaged bag directory into a complete one (footer, index, metadata.yaml); "
                             "the damaged file is kept as *.mcap.broken")


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.bags.info import bag_info, format_info
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.cli import print_json

    if args.repair:
        from pearl_pomdp.bags.info import repair_bag

        repaired = repair_bag(args.bag)
        print(f"pearl bag-info: repaired {repaired['bag']}: {repaired['messages']} messages; kept "
              f"{', '.join(repaired['kept'])}", file=__import__("sys").stderr)
    info = bag_info(BagReader(args.bag, salvage=True))
    if args.json:
        print_json(info)
    else:
        print(format_info(info))
    return 0
