"""Helpers for tests that run real ROS 2 nodes (what launch_testing would do, in pytest).

* :func:`allocate_domain_id` — a ``ROS_DOMAIN_ID`` in 1..101 (above 101 DDS ports reach Linux's
  ephemeral range) that no other test process on this machine holds: each id is a lease, an
  ``flock`` on a file of :data:`LEASE_DIR`, so the pytest-xdist workers of a run and other runs
  (another checkout's suite) never share one. :func:`domain_leases` gives a scope's leases back
  (conftest wraps every test and module in it); the kernel drops them when the process ends.
* :func:`ros_env` — the environment for a node process: the domain, discovery on localhost only,
  the fast-discovery Fast DDS profile (``config/fastdds_profile.xml``), logs and node journals
  (``ROS_HOME``) in a temporary dir.
* :class:`Proc` — a started process, stopped with SIGINT, then SIGTERM, then SIGKILL after
  timeouts (Fast DDS can hang at exit: eProsima/Fast-DDS#6502), its output kept in files.
* :class:`Probe` — a node in the test process that publishes inputs and records outputs;
  :func:`wait_for` spins until a condition holds. No fixed sleeps anywhere: wait for matching.
* :func:`call_service` / :func:`answer_within` — a service call that survives a lost answer.
* fixture ``ros_context`` — an rclpy ``Context`` on its own domain (yields ``(context, domain_id)``).
"""
from __future__ import annotations

import contextlib
import fcntl
import itertools
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, Dict, Iterator, List, Optional, Tuple

import pytest

REPO = Path(__file__).resolve().parents[1]
PROFILE = REPO / "config" / "fastdds_profile.xml"
PYTHON = sys.executable

#: Discovery between processes: allow this long (2-core machine under load).
DISCOVERY_TIMEOUT = 20.0

#: The ROS domain ids the tests use: 1..101 (DDS ports of higher ids reach the ephemeral range).
DOMAIN_IDS = 101
#: Where the leases on domain ids live: one lock file per id, per user (any checkout, any run).
LEASE_DIR = Path(tempfile.gettempdir()) / f"pearl_pomdp-ros-domains-{os.getuid()}"

#: This process's leases, oldest first: (domain id, the open file whose flock is the lease).
_leases: List[Tuple[int, int]] = []
_counter = itertools.count()


def _worker() -> Tuple[int, int]:
    """(index, count) of this pytest-xdist worker; (0, 1) outside xdist."""
    name = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    count = os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")
    return (int(name[2:]) if name[2:].isdigit() else 0), (int(count) if count.isdigit() else 1)


def _lease(domain_id: int) -> bool:
    """Take the lease on ``domain_id`` if no process holds it (never blocks)."""
    try:
        LEASE_DIR.mkdir(mode=0o700, exist_ok=True)
        fd = os.open(LEASE_DIR / f"{domain_id}.lock", os.O_RDWR | os.O_CREAT, 0o600)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        return False
    _leases.append((domain_id, fd))
    return True


def allocate_domain_id() -> int:
    """A ROS domain id in 1..:data:`DOMAIN_IDS` that no other process holds, leased until the
    scope that asked for it ends (:func:`domain_leases`; the test, or the module for a module
    fixture). Each worker starts its search in its own share of the range, so the workers of a
    run rarely even look at the same ids. If all ids are held (> 100 tests at once on one
    machine), the least recently leased of this process is handed out again."""
    index, count = _worker()
    share = DOMAIN_IDS // max(count, 1)
    start = index * share + (os.getpid() + next(_counter)) % max(share, 1)
    mine = {domain_id for domain_id, _ in _leases}
    for step in range(DOMAIN_IDS):
        domain_id = 1 + (start + step) % DOMAIN_IDS
        if domain_id not in mine and _lease(domain_id):
            return domain_id
    return _leases[0][0] if _leases else 1 + start % DOMAIN_IDS


@contextlib.contextmanager
def domain_leases() -> Iterator[None]:
    """Give back, on leaving, the domain ids leased inside (see :func:`allocate_domain_id`)."""
    mark = len(_leases)
    try:
        yield
    finally:
        while len(_leases) > mark:
            _, fd = _leases.pop()
            os.close(fd)            # (closing drops the flock)


def configure_test_process(log_dir: Path) -> None:
    """Set the DDS/log variables in this (pytest) process before its first participant exists."""
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(PROFILE))
    os.environ.setdefault("ROS_LOG_DIR", str(log_dir))
    # Node journals (auto: under $ROS_HOME) stay with the test: no test resumes another's.
    os.environ["ROS_HOME"] = str(log_dir)
    os.environ.pop("ROS_LOCALHOST_ONLY", None)


def ros_env(domain_id: int, log_dir: Path) -> Dict[str, str]:
    """Environment for a node process on ``domain_id`` (see the module doc)."""
    env = dict(os.environ)
    env.pop("ROS_LOCALHOST_ONLY", None)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               FASTRTPS_DEFAULT_PROFILES_FILE=str(PROFILE), ROS_LOG_DIR=str(log_dir), ROS_HOME=str(log_dir),
               PYTHONUNBUFFERED="1", RCUTILS_COLORIZED_OUTPUT="0")
    return env


class Proc:
    """A process started for a test; output goes to ``<log_dir>/<name>.out|.err``."""

    def __init__(self, cmd: List[str], env: Dict[str, str], log_dir: Path, name: str, cwd: Optional[Path] = None):
        log_dir.mkdir(parents=True, exist_ok=True)
        self.name = name
        self.out_path = log_dir / f"{name}.out"
        self.err_path = log_dir / f"{name}.err"
        self._out = open(self.out_path, "wb")
        self._err = open(self.err_path, "wb")
        self.popen = subprocess.Popen(cmd, env=env, cwd=str(cwd or REPO), stdout=self._out, stderr=self._err,
                                      stdin=subprocess.DEVNULL)

    @property
    def returncode(self) -> Optional[int]:
        return self.popen.poll()

    def wait(self, timeout: float) -> Optional[int]:
        """Exit code, or ``None`` if still running after ``timeout`` s."""
        try:
            return self.popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            return None

    def stop(self, timeout: float = 10.0) -> int:
        """SIGINT; after ``timeout`` s SIGTERM; after ``timeout`` s more SIGKILL. Returns the exit code."""
        for sig in (signal.SIGINT, signal.SIGTERM):
            if self.popen.poll() is not None:
                break
            self.popen.send_signal(sig)
            if self.wait(timeout) is not None:
                break
        if self.popen.poll() is None:
            self.popen.kill()
            self.popen.wait(timeout=10)
        self._out.close()
        self._err.close()
        return self.popen.returncode

    def stdout(self) -> str:
        if not self._out.closed:
            self._out.flush()
        return self.out_path.read_text(errors="replace")

    def stderr(self) -> str:
        if not self._err.closed:
            self._err.flush()
        return self.err_path.read_text(errors="replace")


def wait_for(predicate: Callable[[], bool], timeout: float, executor=None, poll: float = 0.02) -> bool:
    """Spin ``executor`` (if given) until ``predicate()`` holds or ``timeout`` s passed; returns it."""
    deadline = time.monotonic() + timeout
    while True:
        if predicate():
            return True
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return False
        if executor is not None:
            executor.spin_once(timeout_sec=min(poll, remaining))
        else:
            time.sleep(min(poll, remaining))


#: How long a service request waits for its answer before the caller looks again (see :func:`call_service`).
ANSWER_WAIT = 2.0


def answer_within(client, request, wait: float, executor=None):
    """Send ``request`` on ``client``; its answer, or ``None`` if none came within ``wait`` s
    (the pending request is then forgotten, so a late answer cannot complete it)."""
    future = client.call_async(request)
    if wait_for(future.done, wait, executor):
        return future.result()
    client.remove_pending_request(future)
    return None


def call_service(client, request, executor=None, timeout: float = DISCOVERY_TIMEOUT):
    """The answer to ``request``, a request that can safely be made twice; fails after ``timeout`` s.

    Why not one ``call_async`` and a wait: ``client.service_is_ready()`` says the client's request
    writer has matched the server's reader, not that the server's response writer has matched the
    client's reader. A Fast DDS server waits for that match only for its writer's
    ``max_blocking_time`` (100 ms) and then drops the answer ("client will not receive response",
    rmw_fastrtps' ``__rmw_send_response``); rclpy only warns. On a loaded machine a new client's
    first answer can be lost that way while its request arrived, and the future would never complete
    (a CI run here: ``/action_executor/get_state did not answer`` in 20 s). So the request is sent
    again every :data:`ANSWER_WAIT` s until one is answered. For a request that must not be repeated
    (a lifecycle transition), use :func:`answer_within` and find out what happened another way.
    """
    assert wait_for(client.service_is_ready, timeout, executor), f"{client.srv_name} never came up"
    deadline = time.monotonic() + timeout
    while (remaining := deadline - time.monotonic()) > 0:
        answer = answer_within(client, request, min(ANSWER_WAIT, remaining), executor)
        if answer is not None:
            return answer
    raise AssertionError(f"{client.srv_name} did not answer in {timeout} s")


class Probe:
    """A test-side node: publishers for inputs, recorders for outputs.

    Args:
        node: an rclpy node (created by the test in its context).
    """

    def __init__(self, node):
        self.node = node
        self.received: Dict[str, list] = {}
        self.arrival: Dict[str, List[float]] = {}
        self.publishers: Dict[str, object] = {}
        self.subscriptions: Dict[str, object] = {}

    def listen(self, topic: str, msg_type, qos) -> list:
        """Record every message on ``topic`` (the list fills while the executor spins)."""
        store = self.received.setdefault(topic, [])
        stamps = self.arrival.setdefault(topic, [])

        def callback(msg):
            stamps.append(time.perf_counter())
            store.append(msg)

        self.subscriptions[topic] = self.node.create_subscription(msg_type, topic, callback, qos)
        return store

    def unmatched(self, peers=()) -> List[str]:
        """Topics whose DDS match is not yet complete on *both* ends, ``[]`` when all are.

        Discovery is asymmetric: a publisher can see its subscriber before the subscriber
        sees the publisher, and a message sent then may be lost or arrive late. A probe
        subscription counts as matched when it sees a publisher; a probe publisher when it
        sees a subscriber and every subscription on that topic in the ``peers`` nodes (the
        nodes under test, same process) sees a publisher.
        """
        missing = [t for t, sub in self.subscriptions.items() if sub.get_publisher_count() == 0]
        for topic, pub in self.publishers.items():
            theirs = [s for node in peers for s in node.subscriptions if s.topic_name == topic]
            if pub.get_subscription_count() == 0 or any(s.get_publisher_count() == 0 for s in theirs):
                missing.append(topic)
        return missing

    def publisher(self, topic: str, msg_type, qos):
        pub = self.node.create_publisher(msg_type, topic, qos)
        self.publishers[topic] = pub
        return pub


@pytest.fixture
def ros_context(tmp_path):
    """An initialised rclpy ``Context`` on a fresh domain: yields ``(context, domain_id)``."""
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    configure_test_process(tmp_path)
    domain_id = allocate_domain_id()
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    try:
        yield context, domain_id
    finally:
        rclpy.try_shutdown(context=context)


# ------------------------------------------------------------------ the Pearl policy
DOMAIN = REPO / "config" / "pearl.domain.yaml"
HIERARCHY = REPO / "config" / "pearl.hierarchy.yaml"
#: Where a committed, planned Pearl policy may live (first match that fits the domain wins).
POLICY_CANDIDATES = (REPO / "config" / "pearl.policy", REPO / "plans" / "pearl", REPO / "policies" / "pearl")


def _policy_fits(directory: Path, domain) -> bool:
    from pearl_pomdp.errors import PolicyError
    from pearl_pomdp.hierarchy import load_hierarchical_policy

    try:
        load_hierarchical_policy(directory, domain)
        return True
    except (PolicyError, OSError, KeyError, ValueError):
        return False


@pytest.fixture(scope="session")
def pearl_policy(request, tmp_path_factory) -> Path:
    """A planned Pearl policy directory that matches ``config/pearl.domain.yaml``.

    ``$PEARL_POLICY_DIR``, then a committed one (:data:`POLICY_CANDIDATES`), else planned once
    and kept in pytest's cache under a key of the domain, hierarchy and planner sources (so
    only the first run after a change pays for PLAN).
    """
    env_dir = os.environ.get("PEARL_POLICY_DIR")
    return _planned_policy(request, tmp_path_factory, DOMAIN, ([Path(env_dir)] if env_dir else [])
                           + list(POLICY_CANDIDATES))


@pytest.fixture(scope="session")
def day_policy(request, tmp_path_factory) -> Path:
    """A planned policy of the working day's domain (``config/pearl_day.domain.yaml``):
    ``$PEARL_DAY_POLICY_DIR`` or the shipped ``config/plans/pearl_day`` when it fits, else planned
    once and cached as :func:`pearl_policy` is."""
    env_dir = os.environ.get("PEARL_DAY_POLICY_DIR")
    return _planned_policy(request, tmp_path_factory, REPO / "config" / "pearl_day.domain.yaml",
                           ([Path(env_dir)] if env_dir else []) + [REPO / "config" / "plans" / "pearl_day"])


def _planned_policy(request, tmp_path_factory, domain_path: Path, candidates) -> Path:
    import hashlib

    from pearl_pomdp.model.domain_yaml import load_domain

    domain = load_domain(domain_path)
    for candidate in candidates:
        if (candidate / "hierarchy.json").is_file() and _policy_fits(candidate, domain):
            return candidate
    h = hashlib.sha256()
    sources = [domain_path, HIERARCHY] + sorted((REPO / "pearl_pomdp" / "hierarchy").glob("*.py")) \
        + sorted((REPO / "pearl_pomdp" / "solvers").glob("*.py"))
    for path in sources:
        h.update(path.name.encode() + path.read_bytes())
    cache_provider = getattr(request.config, "cache", None)  # absent under -p no:cacheprovider
    root = Path(cache_provider.mkdir("pearl_policy")) if cache_provider else tmp_path_factory.mktemp("pearl_policy")
    cache = root / h.hexdigest()[:16]
    with open(root / f"{cache.name}.lock", "w") as lock:
        # One worker plans (Pearl: ~6 s), the others wait for its policy instead of planning it again.
        fcntl.flock(lock, fcntl.LOCK_EX)
        _plan_into(cache, domain)
    return cache


def _plan_into(cache: Path, domain) -> None:
    """Plan ``domain``'s policy into ``cache`` unless a usable one is there (the caller holds the lock).
    The plan is saved into a private folder and renamed into place: a run killed mid-save leaves no
    half-written policy."""
    import shutil

    if (cache / "hierarchy.json").is_file() and _policy_fits(cache, domain):
        return
    from pearl_pomdp.hierarchy import load_hierarchy, plan

    tmp = cache.parent / f"{cache.name}.tmp{os.getpid()}"
    try:
        plan(domain, load_hierarchy(HIERARCHY, domain)).save(tmp)
        shutil.rmtree(cache, ignore_errors=True)  # an unusable leftover
        os.rename(tmp, cache)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


#: A reader that imports nothing of this project (nor rclpy): every /pearl/* message of the MCAP
#: files it is given, decoded by mcap-ros2-support from the bag's own schemas; one JSON object.
MCAP_ROS2_ALONE = r"""
import collections, json, sys
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

def plain(value, depth=0):
    # The decoded message as JSON: fields by name (mcap_ros2 builds plain classes with __slots__).
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    if isinstance(value, (list, tuple)):
        return [plain(v, depth + 1) for v in value[:50]]
    if isinstance(value, (bytes, bytearray)):
        return list(value[:50])
    names = getattr(value, "__slots__", None) or list(vars(value))
    return {n: plain(getattr(value, n), depth + 1) for n in names}

topics = {}
for path in sys.argv[1:]:
    with open(path, "rb") as fh:
        for schema, channel, message, decoded in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            if not channel.topic.startswith("/pearl/"):
                continue
            entry = topics.setdefault(channel.topic, {"type": schema.name, "count": 0, "first": plain(decoded)})
            entry["count"] += 1
print(json.dumps({"topics": topics,
                  "project_modules": sorted(m for m in sys.modules if m.split(".")[0] in ("pearl_pomdp", "pearl_sim",
                                                                                          "pearl_interfaces", "rclpy"))}))
"""


def decode_with_mcap_ros2_alone(bag_dir: Path) -> Dict[str, dict]:
    """``{topic: {"type", "count", "first"}}`` of every ``/pearl/*`` message of the bag in ``bag_dir``, decoded
    in a fresh process by ``mcap-ros2-support`` alone (it asserts that process imported nothing of this
    project); ``first`` is the topic's first message as plain JSON."""
    import json

    files = sorted(str(p) for p in Path(bag_dir).glob("*.mcap"))
    assert files, f"no .mcap in {bag_dir}"
    out = subprocess.run([sys.executable, "-c", MCAP_ROS2_ALONE, *files], capture_output=True, text=True, timeout=120,
                         cwd=tempfile.gettempdir())
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout)
    assert result["project_modules"] == [], result["project_modules"]
    return result["topics"]
