"""``pearl launch`` process handling, with stand-in node executables (no ROS): output prefixing,
SIGINT forwarding, the SIGINT → SIGTERM → SIGKILL escalation for a node that will not stop, and the
shared memory a node stopped by a signal leaves, removed once the nodes have exited."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

PEARL = str(Path(sys.executable).parent / "pearl")

POLITE = """#!{python} -S
import signal, sys, time
def stop(signum, frame):
    print("stopping on", signal.Signals(signum).name, flush=True)
    sys.exit(0)
signal.signal(signal.SIGINT, stop)
print("args", sys.argv[1:], flush=True)
while True:
    time.sleep(0.05)
"""

STUBBORN = """#!{python} -S
import signal, time
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, signal.SIG_IGN)
print("ignoring signals", flush=True)
while True:
    time.sleep(0.05)
"""

#: Makes a Fast DDS-like segment in /dev/shm (the file and its ``_el`` lock, held) and, stopped by
#: SIGINT, ends without removing it: what a package node's participant leaves (run_node's os._exit).
LEAKY = """#!{python} -S
import fcntl, os, secrets, signal, sys, time
name = "/dev/shm/fastrtps_" + secrets.token_hex(8)
open(name, "wb").write(bytes(4096))
lock = os.open(name + "_el", os.O_CREAT | os.O_RDONLY, 0o644)
fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
past = time.time() - 60         # as if started a minute ago (the clean-up leaves lock files under 1 s old)
os.utime(name + "_el", (past, past))
signal.signal(signal.SIGINT, lambda *_: os._exit(0))
print("args segment", name, flush=True)
while True:
    time.sleep(0.05)
"""

LAUNCH = """<launch>
  <node pkg="fake" exec="polite_node" name="polite" output="screen"><param name="rate" value="2.0"/></node>
  <node pkg="fake" exec="{second}" name="second" output="screen"/>
</launch>"""


def _setup(tmp_path, second):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for name, body in (("polite_node", POLITE), ("stubborn_node", STUBBORN), ("leaky_node", LEAKY)):
        path = bin_dir / name
        path.write_text(body.format(python=sys.executable))
        path.chmod(0o755)
    launch = tmp_path / "fake.launch.xml"
    launch.write_text(LAUNCH.format(second=second))
    env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}", ROS_LOG_DIR=str(tmp_path))
    return launch, env


def _start_and_wait(launch, env, *extra):
    proc = subprocess.Popen([PEARL, "launch", str(launch), *extra], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    # Wait until both stand-ins printed their first line (the launch prefixes it with [name]).
    seen = []
    while time.monotonic() < deadline and len(seen) < 2:
        line = proc.stdout.readline()
        if line.startswith("[polite] args") or line.startswith("[second] "):
            seen.append(line)
    return proc, seen


def test_sigint_is_forwarded_and_the_exit_is_clean(tmp_path):
    launch, env = _setup(tmp_path, "polite_node")
    proc, seen = _start_and_wait(launch, env)
    assert len(seen) == 2, seen
    assert any("'--ros-args', '-r', '__node:=polite', '--params-file'" in line for line in seen)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "[polite] stopping on SIGINT" in out and "[second] stopping on SIGINT" in out


def test_a_node_that_ignores_signals_is_killed(tmp_path):
    launch, env = _setup(tmp_path, "stubborn_node")
    proc, seen = _start_and_wait(launch, env, "--shutdown-timeout", "0.5")
    assert len(seen) == 2, seen
    start = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert time.monotonic() - start < 10
    assert proc.returncode == 1
    assert "[launch] still running after SIGINT: second; sending SIGTERM" in err
    assert "[launch] second did not stop; SIGKILL" in err
    assert "[launch] not clean: second exited with -9" in err
    assert "[polite] stopping on SIGINT" in out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "\nState:\tZ" not in state  # a zombie has exited


def test_nodes_die_with_a_killed_launcher(tmp_path):
    launch, env = _setup(tmp_path, "polite_node")
    proc = subprocess.Popen([PEARL, "launch", str(launch)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    pids = []
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and len(pids) < 2:
        line = proc.stderr.readline()
        if line.startswith("[launch] started"):
            pids.append(int(line.rsplit("pid ", 1)[1].rstrip(")\n")))
    assert len(pids) == 2
    proc.kill()
    proc.wait(10)
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and any(_alive(p) for p in pids):
        time.sleep(0.05)
    assert not any(_alive(p) for p in pids)


@pytest.mark.skipif(not Path("/dev/shm").is_dir(), reason="no /dev/shm here")
def test_the_launch_removes_the_shared_memory_its_stopped_nodes_left(tmp_path):
    launch, env = _setup(tmp_path, "leaky_node")
    proc, seen = _start_and_wait(launch, env)
    assert len(seen) == 2, seen
    segment = Path([line for line in seen if line.startswith("[second] ")][0].split("segment ", 1)[1].strip())
    assert segment.exists() and Path(f"{segment}_el").exists()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert not segment.exists() and not Path(f"{segment}_el").exists()
    assert "shared-memory file(s) of stopped participants" in err


#: Dies with exit code 1 at once, every time (a node that crashes at start); counts its starts.
#: CRASH_CODE: that exit code instead; "SIGKILL": killed by that signal.
CRASHING = """#!{python} -S
import os, signal, sys
with open(os.environ["CRASH_COUNT"], "a") as f:
    f.write("start\\n")
print("crashing", flush=True)
code = os.environ.get("CRASH_CODE", "1")
if code == "SIGKILL":
    os.kill(os.getpid(), signal.SIGKILL)
sys.exit(int(code))
"""

RESPAWN_LAUNCH = """<launch>
  <node pkg="fake" exec="polite_node" name="polite" output="screen"/>
  <node pkg="fake" exec="crashing_node" name="crasher" output="screen" respawn="true" respawn_delay="0.1"/>
</launch>"""


def _respawn_setup(tmp_path, code: str = "1", on_exit: str = ""):
    launch, env = _setup(tmp_path, "polite_node")
    crasher = tmp_path / "bin" / "crashing_node"
    crasher.write_text(CRASHING.format(python=sys.executable))
    crasher.chmod(0o755)
    launch.write_text(RESPAWN_LAUNCH.replace('respawn="true"', f'respawn="true"{on_exit}'))
    env.update(CRASH_COUNT=str(tmp_path / "starts"), CRASH_CODE=code)
    return launch, env


def _launch_until_left_down(launch, env, retries: int):
    """``pearl launch`` started; returns once the crasher was left down (or after 30 s): ``(proc, stderr lines)``."""
    proc = subprocess.Popen([PEARL, "launch", str(launch), "--respawn-max-retries", str(retries)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines = []
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and not any("left down" in line for line in lines):
        lines.append(proc.stderr.readline())
    return proc, lines


def test_a_node_that_keeps_dying_is_respawned_a_bounded_number_of_times_then_left_down(tmp_path):
    launch, env = _respawn_setup(tmp_path)
    proc, lines = _launch_until_left_down(launch, env, 2)
    # The others keep running: polite is still there when the crasher is left down.
    time.sleep(0.5)
    assert proc.poll() is None, "".join(lines)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    text = "".join(lines) + err
    assert proc.returncode == 1, text
    assert (tmp_path / "starts").read_text().count("start") == 3      # the first start and 2 respawns
    assert text.count("[launch] crasher exited with code 1; respawning in 0.1 s") == 2
    assert "(restart 2 of at most 2 within 60 s)" in text
    assert ("[launch] crasher exited with code 1: death 3 within 60 s (--respawn-max-retries 2): "
            "left down, not respawned again") in text
    assert "[polite] stopping on SIGINT" in out


def test_a_start_up_error_is_not_respawned_and_stops_the_launch(tmp_path):
    """Exit code 2 (a node's start-up error: a bad parameter) would only repeat: the launch stops."""
    launch, env = _respawn_setup(tmp_path, code="2")
    done = subprocess.run([PEARL, "launch", str(launch)], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done.stderr
    assert (tmp_path / "starts").read_text().count("start") == 1
    assert "[launch] crasher exited with code 2; stopping the others" in done.stderr


def test_a_node_whose_exit_shuts_the_launch_down_ends_it_with_its_code_instead_of_a_respawn(tmp_path):
    """on_exit="shutdown" with respawn (the simulator): its own exit (exit 1, its verdict) ends the launch."""
    launch, env = _respawn_setup(tmp_path, code="1", on_exit=' on_exit="shutdown"')
    done = subprocess.run([PEARL, "launch", str(launch)], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 1, done.stderr
    assert (tmp_path / "starts").read_text().count("start") == 1
    assert "[launch] crasher exited with code 1; stopping the others" in done.stderr
    assert "respawning" not in done.stderr


def test_a_node_whose_exit_shuts_the_launch_down_is_still_respawned_when_a_signal_killed_it(tmp_path):
    launch, env = _respawn_setup(tmp_path, code="SIGKILL", on_exit=' on_exit="shutdown"')
    proc, lines = _launch_until_left_down(launch, env, 1)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    text = "".join(lines) + err
    assert (tmp_path / "starts").read_text().count("start") == 2      # the first start and its respawn
    assert text.count("[launch] crasher exited with code -9; respawning in 0.1 s") == 1
    assert "[launch] crasher exited with code -9: death 2 within 60 s" in text
