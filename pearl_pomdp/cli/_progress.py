"""When a command shows a progress bar: on a terminal only, unless asked.

Progress bars (tqdm, on stderr) help a person watching a terminal and only clutter a CI log
or a file that stderr is redirected to (a tiger solve writes ~500 updates). So a command
shows progress when stderr is a terminal and it is not printing ``--json``; ``--progress``
forces it (e.g. to watch a redirected log with ``tail -f``), ``--quiet`` turns it off.
"""
from __future__ import annotations

import argparse
import sys
from typing import IO, Optional


def add_progress_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the mutually exclusive ``--progress`` / ``--quiet`` flags read by :func:`show_progress`."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--progress", action="store_true",
                       help="show progress on stderr even when it is not a terminal (default: on a terminal only)")
    group.add_argument("--quiet", action="store_true", help="never show progress")


def show_progress(args: argparse.Namespace, stream: Optional[IO] = None) -> bool:
    """True when the command should draw progress on ``stream`` (default stderr); see the module doc."""
    if getattr(args, "quiet", False):
        return False
    if getattr(args, "progress", False):
        return True
    if getattr(args, "json", False):
        return False
    stream = sys.stderr if stream is None else stream
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # closed or not a real file
        return False
