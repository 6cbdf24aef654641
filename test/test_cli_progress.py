"""Progress bars only on a terminal unless asked.

`pearl solve tiger` used to write ~500 tqdm updates (38 KB) into a CI log. Now stderr that is
not a terminal gets no progress bytes at all; a terminal (a pty here) gets the bar, and
--progress forces it into a pipe; --quiet and --json turn it off.
"""
import argparse
import fcntl
import os
import pty
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

from pearl_pomdp.cli._progress import show_progress

PEARL = [sys.executable, "-c", "import sys; from pearl_pomdp.cli import main; sys.exit(main())"]


def _solve(benchmarks_dir: Path, *extra: str, stderr_tty: bool = False) -> tuple:
    cmd = PEARL + ["solve", str(benchmarks_dir / "tiger.95.POMDP"), "--horizon", "15", *extra]
    if not stderr_tty:
        done = subprocess.run(cmd, capture_output=True, timeout=120)
        return done.returncode, done.stdout, done.stderr
    master, slave = pty.openpty()
    # a fresh pty is 0×0 characters, where tqdm draws nothing: make it a normal 80×24 terminal
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    try:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=slave)
        os.close(slave)
        chunks = []
        while True:
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: the child closed the pty
                break
            if not data:
                break
            chunks.append(data)
        out = proc.stdout.read()
        return proc.wait(timeout=120), out, b"".join(chunks)
    finally:
        os.close(master)


def test_no_progress_bytes_when_stderr_is_not_a_terminal(benchmarks_dir):
    rc, out, err = _solve(benchmarks_dir)
    assert rc == 0 and b"47 \xce\xb1-vectors" in out
    assert err == b""


def test_no_progress_with_json_or_quiet_even_on_a_terminal(benchmarks_dir):
    for flag in ("--json", "--quiet"):
        rc, out, err = _solve(benchmarks_dir, flag, stderr_tty=True)
        assert rc == 0
        assert b"incprune" not in err, flag


def test_progress_on_a_terminal_and_when_forced(benchmarks_dir):
    rc, _, err = _solve(benchmarks_dir, stderr_tty=True)
    assert rc == 0 and b"incprune tiger" in err
    rc, _, err = _solve(benchmarks_dir, "--progress")
    assert rc == 0 and b"incprune tiger" in err


class _Stream:
    def __init__(self, tty):
        self.tty = tty

    def isatty(self):
        return self.tty


@pytest.mark.parametrize("flags, tty, expected", [
    ({}, True, True), ({}, False, False),
    ({"json": True}, True, False), ({"quiet": True}, True, False),
    ({"progress": True}, False, True), ({"progress": True, "json": True}, False, True),
])
def test_show_progress_rules(flags, tty, expected):
    assert show_progress(argparse.Namespace(**flags), _Stream(tty)) is expected


@pytest.mark.parametrize("command", ["solve", "simulate", "plan", "hierarchy", "experiment", "replay"])
def test_every_long_command_offers_progress_and_quiet(command, capsys):
    from pearl_pomdp.cli import main

    with pytest.raises(SystemExit):
        main([command, "--help"])
    out = capsys.readouterr().out
    assert "--progress" in out and "--quiet" in out
