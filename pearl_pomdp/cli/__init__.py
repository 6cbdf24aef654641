"""The ``pearl`` command.

Each subcommand lives in its own module of this package and exposes::

    COMMAND = "solve"                       # the subcommand name
    HELP = "one line for `pearl --help`"
    def add_arguments(parser: argparse.ArgumentParser) -> None: ...
    def run(args: argparse.Namespace) -> int: ...   # exit code

Modules are discovered automatically, so adding a command never edits this file;
other packages add commands through the ``pearl.commands`` entry-point group (pearl_sim's
``demo`` and ``experiment``).
User errors (:class:`~pearl_pomdp.errors.PearlError`, missing files) print one
line ``pearl <command>: error: …`` on stderr and exit 2, without a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import pkgutil
import sys
from typing import List, Optional

from pearl_pomdp.errors import PearlError
from pearl_pomdp.jsonable import numpy_to_json


#: Entry-point group through which other packages (pearl_sim) add subcommands.
COMMAND_GROUP = "pearl.commands"


def _command_modules():
    modules = []
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if not info.name.startswith("_"):
            modules.append(importlib.import_module(f"{__name__}.{info.name}"))
    from importlib.metadata import entry_points

    for ep in sorted(entry_points(group=COMMAND_GROUP), key=lambda e: e.name):
        try:
            modules.append(importlib.import_module(ep.value))
        except ImportError as err:  # a plug-in whose dependencies are missing: say so, keep the rest
            print(f"pearl: subcommand {ep.name!r} ({ep.value}) is unavailable: {err}", file=sys.stderr)
    for module in sorted(modules, key=lambda m: getattr(m, "COMMAND", "")):
        if hasattr(module, "COMMAND") and hasattr(module, "run"):
            yield module


def _builtin_command(name: str):
    """The built-in command module whose ``COMMAND`` is ``name`` (module ``bag_info`` for
    ``bag-info``), or None: so that ``pearl solve …`` imports one command module and reads
    no installed package's entry points (together ~40 ms of start-up)."""
    if name.startswith("_") or name.startswith("-"):
        return None
    mod_name = name.replace("-", "_")
    if not any(info.name == mod_name for info in pkgutil.iter_modules(__path__)):
        return None
    module = importlib.import_module(f"{__name__}.{mod_name}")
    if getattr(module, "COMMAND", None) == name and hasattr(module, "run"):
        return module
    return None


class _LazyVersion(argparse.Action):
    """``--version``: reads the installed version (importlib.metadata, ~20 ms) only when asked."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0,
                         help=help or "show program's version number and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        from pearl_pomdp import __version__

        parser.exit(message=f"pearl {__version__}\n")


def build_parser(only=None) -> argparse.ArgumentParser:
    """The full argument parser, with every discovered subcommand (``only``: that one module alone)."""
    parser = argparse.ArgumentParser(
        prog="pearl",
        description="Pearl POMDP: hierarchical POMDP behaviour manager for ROS 2 service robots.",
    )
    parser.add_argument("--version", action=_LazyVersion)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in ([only] if only is not None else _command_modules()):
        # argparse %-formats the one-line help (a literal "95%" would break `pearl --help`),
        # but prints a description as it is: escaping it too would show "95%%".
        p = sub.add_parser(module.COMMAND, help=module.HELP.replace("%", "%%"),
                           description=getattr(module, "__doc__", None) or "",
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def print_json(obj) -> None:
    """Print one JSON object on stdout (the ``--json`` contract of every command)."""
    json.dump(obj, sys.stdout, indent=None, sort_keys=False, default=numpy_to_json)
    sys.stdout.write("\n")
    sys.stdout.flush()


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``pearl`` console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    only = _builtin_command(argv[0]) if argv else None
    parser = build_parser(only)
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except BrokenPipeError:
        # `pearl plan --json | head`: the reader left; say nothing more (Python would print a
        # traceback, then fail again flushing stdout at exit). 141 = 128 + SIGPIPE, as a shell reports.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except PearlError as err:
        print(f"pearl {args.command}: error: {err}", file=sys.stderr)
        return 2
    except (FileNotFoundError, IsADirectoryError, PermissionError) as err:
        name = getattr(err, "filename", None) or ""
        print(f"pearl {args.command}: error: {name}: {err.strerror or err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"pearl {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
