"""Start the ``<node>`` entries of a ROS 2 XML launch file as processes (``ros2 launch`` stand-in).

``pearl launch FILE [name:=value …]`` reads the file with :mod:`pearl_pomdp.launch_xml`,
starts every node in file order as its own process with the same ``--ros-args`` that
``ros2 launch`` would give it (node name, namespace, ``<param>``, ``<param from>``,
``<remap>``), prefixes each output line with ``[node]`` and waits.

Respawn: a node with ``respawn="true"`` that dies (killed by a signal, or an exit code other than
0 — it finished — and 2 — its start-up error, which a restart would repeat) is started again
after its ``respawn_delay``, with one line; a node that dies more than ``--respawn-max-retries``
times within ``--respawn-window`` seconds is left down, with one line, and the others keep
running (never a restart loop; ``ros2 launch`` has no such bound in its XML). The launch then
ends with exit code 1. The lifecycle supervisor (``lifecycle_supervisor``) configures and
activates a respawned managed node again. A ``respawn`` node with ``on_exit="shutdown"`` is started
again only when a signal killed it: any exit of its own ends the launch with its exit code (the
simulator's verdict, such as ``pearl_sim_world``'s timeouts with exit 1, is not a crash to mend).

Shutdown: on SIGINT or SIGTERM, or when a node without respawn exits by itself, every node still running
gets SIGINT; after ``--shutdown-timeout`` seconds the ones left get SIGTERM, then SIGKILL
(Fast DDS can hang at exit, eProsima/Fast-DDS#6502). Exit code 0 when the launch was asked
to stop and every node exited cleanly; otherwise the first failing node's exit code
(or 1), with one line naming it.

Once its nodes have exited, the launcher removes the Fast DDS shared-memory files that belong to
no living process (:mod:`pearl_pomdp.shared_memory`: a node stopped by a signal leaves its
segment), with one line saying how much.

Children get ``FASTRTPS_DEFAULT_PROFILES_FILE`` = the package's ``config/fastdds_profile.xml``
(fast discovery) unless it is already set, and die with the launcher: on Linux each child
has ``PR_SET_PDEATHSIG`` = SIGTERM, so when the launcher is killed (even SIGKILL) every node
gets SIGTERM from the kernel, and the package's nodes exit within their 1.5 s shutdown
deadline (``pearl_pomdp.nodes.common.SHUTDOWN_DEADLINE``). A node's own children (a wrapper
script's grandchildren) are not covered. Elsewhere there is no such signal: stop the
launcher with SIGINT/SIGTERM.
``--print`` shows the commands as JSON instead of running them.

Examples:
  pearl launch launch/pearl.launch.xml --print
  pearl launch launch/pearl.launch.xml policy:=out/policies/pearl     # until Ctrl-C
"""
from __future__ import annotations

import argparse
import ctypes
import importlib.util
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO, List, Optional

from pearl_pomdp.errors import PearlError
from pearl_pomdp.launch_xml import LaunchNode, package_share_dir, parse_cli_arguments, parse_launch_file
from pearl_pomdp.shared_memory import DEFAULT_DIRECTORY, remove_dead_files

COMMAND = "launch"
HELP = "start the nodes of a ROS 2 XML launch file as processes (where `ros2 launch` is absent)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="launch file (ROS 2 XML format), e.g. launch/pearl.launch.xml")
    # REMAINDER so that options may also follow the arguments (``FILE a:=1 --print``); see _split.
    parser.add_argument("arguments", nargs=argparse.REMAINDER, metavar="name:=value", help="launch arguments")
    parser.add_argument("--shutdown-timeout", type=float, default=10.0, metavar="S",
                        help="seconds to wait after SIGINT (then SIGTERM, then SIGKILL); default 10")
    parser.add_argument("--respawn-max-retries", type=int, default=3, metavar="N",
                        help="restarts of a respawn=\"true\" node allowed within --respawn-window; one more "
                             "death and it is left down; default 3")
    parser.add_argument("--respawn-window", type=float, default=60.0, metavar="S",
                        help="seconds over which --respawn-max-retries counts; default 60")
    parser.add_argument("--print", action="store_true", dest="print_only",
                        help="print the node commands as JSON and exit")


def node_command(node: LaunchNode, params_dir: Optional[Path] = None) -> List[str]:
    """The command that runs ``node`` (executable + ``args`` + ``--ros-args …``).

    The executable is found like ``ros2 run`` does (``<prefix>/lib/<pkg>/<exec>`` in
    ``AMENT_PREFIX_PATH``); this package's nodes and Python packages without an ament
    install run as ``python -m <pkg>.<exec>`` or ``<pkg>.nodes.<exec>``; last, ``exec`` on
    the venv's ``bin``/``PATH``.

    Raises:
        PearlError: nothing runs ``exec`` of ``pkg`` (the message names the launch line).
    """
    from pearl_pomdp.cli.run import NODES

    if node.package == "pearl_pomdp" and node.executable in NODES:
        return [sys.executable, "-m", NODES[node.executable], *node.argv(params_dir)]
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        candidate = Path(prefix) / "lib" / node.package / node.executable
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return [str(candidate), *node.argv(params_dir)]
    for module in (f"{node.package}.{node.executable}", f"{node.package}.nodes.{node.executable}"):
        try:
            found = importlib.util.find_spec(module)
        except (ImportError, ValueError):
            found = None
        if found is not None:
            return [sys.executable, "-m", module, *node.argv(params_dir)]
    path = shutil.which(node.executable, path=os.pathsep.join([str(Path(sys.executable).parent),
                                                               os.environ.get("PATH", "")]))
    if path:
        return [path, *node.argv(params_dir)]
    raise PearlError(f"line {node.line}: no executable {node.executable!r} in package {node.package!r} "
                     f"(looked in AMENT_PREFIX_PATH lib/{node.package}/, Python modules, PATH)")


def _libc():
    try:
        return ctypes.CDLL("libc.so.6", use_errno=True)
    except OSError:
        return None


# Loaded in the parent: after fork (reader threads are running) the child must not dlopen.
_LIBC = _libc() if sys.platform.startswith("linux") else None


#: prctl(2) option: the signal this process gets when its parent thread ends.
PR_SET_PDEATHSIG = 1


def _die_with(launcher_pid: int):
    """``preexec_fn`` for a node: default stop signals, and SIGTERM when the launcher dies.

    * SIGINT and SIGTERM start at their default disposition, whatever the launcher inherited
      (a background job of a non-interactive shell has SIGINT ignored, and an ignored signal
      is inherited across exec): the node's own handlers take over once its package is
      imported, and before that a stop signal still ends the process instead of being lost.
    * On Linux, SIGTERM when the launcher dies, however it dies. The launcher starts nodes
      from its main thread, which lives as long as the launcher, so the kernel sends the
      signal when the launcher process ends (SIGKILL included). SIGTERM, not SIGKILL: our
      nodes then stop within ``SHUTDOWN_DEADLINE`` and release their DDS shared memory. If the
      launcher died between fork and ``prctl``, no signal would ever come: the child sees
      another parent and exits before running the node.
    """
    def preexec() -> None:  # pragma: no cover - runs in the child between fork and exec
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        if _LIBC is None:
            return
        _LIBC.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
        if os.getppid() != launcher_pid:
            os._exit(1)

    return preexec


class _Child:
    def __init__(self, node: LaunchNode, cmd: List[str], env: dict, log_dir: Path, deaths: Optional[list] = None):
        self.node, self.label, self.cmd = node, node.label, cmd
        self.log_path = log_dir / f"{node.label}.log"
        self.log = open(self.log_path, "a" if deaths else "w", encoding="utf-8")
        self.last_err = ""
        #: When this node died before (launcher clock), for --respawn-max-retries.
        self.deaths: list = list(deaths or [])
        self.left_down = False
        self.respawn_at: Optional[float] = None
        self.proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     stdin=subprocess.DEVNULL, start_new_session=True,
                                     preexec_fn=_die_with(os.getpid()))
        screen = node.output in ("screen", "both")
        self.threads = [threading.Thread(target=self._pump, args=(self.proc.stdout, sys.stdout if screen else None,
                                                                  False), daemon=True),
                        threading.Thread(target=self._pump, args=(self.proc.stderr, sys.stderr if screen else None,
                                                                  True), daemon=True)]
        for t in self.threads:
            t.start()

    def _pump(self, stream: IO[bytes], out: Optional[IO[str]], is_err: bool) -> None:
        for raw in iter(stream.readline, b""):
            line = raw.decode("utf-8", errors="replace").rstrip("\n")
            if is_err and line.strip():
                self.last_err = line.strip()
            self.log.write(line + "\n")
            self.log.flush()
            if out is not None:
                out.write(f"[{self.label}] {line}\n")
                out.flush()
        stream.close()

    def finish(self) -> None:
        for t in self.threads:
            t.join(timeout=2.0)
        self.log.close()


def _log_dir() -> Path:
    base = Path(os.environ.get("ROS_LOG_DIR") or Path.home() / ".ros" / "log")
    path = base / f"pearl_launch_{time.strftime('%Y-%m-%d-%H-%M-%S')}_{os.getpid()}"
    path.mkdir(parents=True, exist_ok=True)
    return path


def _say(text: str) -> None:
    print(f"[launch] {text}", file=sys.stderr, flush=True)


#: The options with a value that may stand anywhere among the launch arguments: option → (attribute, type, what).
_VALUED = {"--shutdown-timeout": ("shutdown_timeout", float, "seconds"),
           "--respawn-max-retries": ("respawn_max_retries", int, "a whole number"),
           "--respawn-window": ("respawn_window", float, "seconds")}


def _split(args: argparse.Namespace) -> None:
    """Take ``--print`` and the valued options (:data:`_VALUED`) out of the launch arguments,
    wherever they are."""
    rest, items = [], list(args.arguments)
    while items:
        item = items.pop(0)
        option = item.partition("=")[0]
        if item == "--print":
            args.print_only = True
        elif option in _VALUED:
            attribute, kind, what = _VALUED[option]
            value = item.partition("=")[2] or (items.pop(0) if items else "")
            try:
                setattr(args, attribute, kind(value))
            except ValueError:
                raise PearlError(f"{option} needs {what}, got {value!r}") from None
        else:
            rest.append(item)
    args.arguments = rest
    if args.respawn_max_retries < 0 or not args.respawn_window > 0:
        raise PearlError(f"--respawn-max-retries must be >= 0 and --respawn-window > 0 s, got "
                         f"{args.respawn_max_retries} and {args.respawn_window}")


def run(args: argparse.Namespace) -> int:
    _split(args)
    description = parse_launch_file(args.file, parse_cli_arguments(args.arguments))
    log_dir = _log_dir()
    commands = [node_command(node, log_dir / "params") for node in description.nodes]
    if args.print_only:
        from pearl_pomdp.cli import print_json

        print_json({"file": str(description.source), "arguments": description.values,
                    "nodes": [{"name": n.label, "package": n.package, "executable": n.executable,
                               "namespace": n.namespace, "command": cmd}
                              for n, cmd in zip(description.nodes, commands)]})
        return 0
    if not commands:
        raise PearlError(f"{description.source}: no <node> to start")
    env = dict(os.environ)
    share = package_share_dir("pearl_pomdp")
    profile = share / "config" / "fastdds_profile.xml" if share else None
    if "FASTRTPS_DEFAULT_PROFILES_FILE" not in env and profile is not None and profile.is_file():
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(profile)
    env.setdefault("PYTHONUNBUFFERED", "1")

    stop = threading.Event()
    requested: List[int] = []

    def on_signal(signum, _frame):
        requested.append(signum)
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    children: List[_Child] = []
    try:
        for node, cmd in zip(description.nodes, commands):
            if stop.is_set():
                break
            children.append(_Child(node, cmd, env, log_dir))
            _say(f"started {node.label} (pid {children[-1].proc.pid})")
        _say(f"{len(children)} node(s) running; logs in {log_dir}")
        failed: Optional[_Child] = None
        while not stop.wait(0.1):
            failed = _watch(children, args, env, log_dir)
            if failed is not None:
                code = failed.proc.returncode
                why = f": {failed.last_err}" if failed.last_err else ""
                _say(f"{failed.label} exited with code {code}{why}; stopping the others")
                break
            if all(c.left_down for c in children):
                _say("every node is left down; stopping")
                break
        codes = _stop_all(children, args.shutdown_timeout)
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
    for child in children:
        child.finish()
    _remove_dead_shared_memory()
    bad = [(c.label, code) for c, code in zip(children, codes) if code != 0]
    if failed is not None and failed.proc.returncode != 0:
        code = failed.proc.returncode
        return code if code > 0 else 1
    if bad:
        _say("not clean: " + ", ".join(f"{label} exited with {code}" for label, code in bad))
        return 1
    return 0


def _watch(children: List[_Child], args: argparse.Namespace, env: dict, log_dir: Path) -> Optional[_Child]:
    """One look at the children: respawn the dead ``respawn`` nodes (bounded, see the module doc),
    leave down the ones that died too often; the first other child that exited, or ``None``."""
    now = time.monotonic()
    for i, child in enumerate(children):
        code = child.proc.poll()
        if code is None or child.left_down:
            continue
        if child.respawn_at is not None:
            if now >= child.respawn_at:
                child.finish()
                children[i] = _Child(child.node, child.cmd, env, log_dir, deaths=child.deaths)
                _say(f"respawned {child.label} (pid {children[i].proc.pid})")
            continue
        if not child.node.respawn or code in (0, 2) or (child.node.shutdown_on_exit and code > 0):
            return child
        why = f" ({child.last_err})" if child.last_err and code > 0 else ""
        child.deaths = [t for t in child.deaths if now - t <= args.respawn_window] + [now]
        if len(child.deaths) > args.respawn_max_retries:
            child.left_down = True
            _say(f"{child.label} exited with code {code}{why}: death {len(child.deaths)} within "
                 f"{args.respawn_window:g} s (--respawn-max-retries {args.respawn_max_retries}): left down, "
                 "not respawned again")
            continue
        child.respawn_at = now + child.node.respawn_delay
        _say(f"{child.label} exited with code {code}{why}; respawning in {child.node.respawn_delay:g} s "
             f"(restart {len(child.deaths)} of at most {args.respawn_max_retries} within {args.respawn_window:g} s)")
    return None


def _remove_dead_shared_memory() -> None:
    """Remove the Fast DDS shared memory that stopped nodes left (a node stopped by a signal leaves its
    participant's segment: :mod:`pearl_pomdp.shared_memory`), and say how much."""
    cleanup = remove_dead_files()
    if cleanup.removed:
        _say(f"removed {len(cleanup.removed)} shared-memory file(s) of stopped participants "
             f"({cleanup.removed_bytes / 2 ** 20:.1f} MB in {DEFAULT_DIRECTORY})")


def _stop_all(children: List[_Child], timeout: float) -> List[int]:
    """SIGINT every running child; SIGTERM after ``timeout``; SIGKILL after ``timeout`` more."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        running = [c for c in children if c.proc.poll() is None]
        if not running:
            break
        for c in running:
            try:
                c.proc.send_signal(sig)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and any(c.proc.poll() is None for c in running):
            time.sleep(0.05)
        if sig == signal.SIGINT and any(c.proc.poll() is None for c in running):
            _say("still running after SIGINT: " + ", ".join(c.label for c in running if c.proc.poll() is None)
                 + "; sending SIGTERM")
    for c in children:
        if c.proc.poll() is None:
            _say(f"{c.label} did not stop; SIGKILL")
            c.proc.kill()
            c.proc.wait()
    return [c.proc.returncode for c in children]
