"""Show what a bag holds, like `ros2 bag info`: files, size, duration, start/end, and per
topic the type, message count, serialization format and offered QoS.

BAG is a bag directory (metadata.yaml + .mcap) or an .mcap file. A bag whose recorder was
killed (no footer, no metadata.yaml) is read up to the last complete message; the report
then says "Salvaged:" with the file and offset where it was cut.

Examples:
  pearl bag-info bags/table4_clarification
  pearl bag-info run1 --json
"""
from __future__ import annotations

import argparse

COMMAND = "bag-info"
HELP = "summarise a rosbag2 MCAP bag (works on truncated bags: salvages what is complete)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.bags.info import bag_info, format_info
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.cli import print_json

    info = bag_info(BagReader(args.bag, salvage=True))
    if args.json:
        print_json(info)
    else:
        print(format_info(info))
    return 0
