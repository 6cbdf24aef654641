"""The ROS 2 layer: thin rclpy nodes over the ROS-free core (see docs/ros-nodes.md)."""
import os as _os
import signal as _signal
import sys as _sys

#: The console scripts that run a node of this package (setup.py NODES).
_NODE_SCRIPTS = frozenset({"belief_tracker", "hierarchical_policy", "action_executor", "landmark_detector",
                           "guide_pace", "speech_recognizer", "speech_synthesizer", "pearl_bt"})


def _exit_quietly(_signum, _frame):  # pragma: no cover - runs in a node process being stopped
    _os._exit(0)      # as run_node after a stop signal: nothing was started, nothing to clean up


def _quiet_interrupt_while_starting() -> None:
    """A node process stopped while it is still importing (a launch ending during start-up, before
    ``run_node`` installs its handlers) exits with code 0, as ``run_node`` does after a stop
    signal, instead of printing a KeyboardInterrupt traceback.

    Also when SIGINT came *ignored* (a node started as a background job of a non-interactive
    shell, or by a launcher that was: the ignored disposition survives exec): a node treats
    SIGINT as "stop" from here on, as ``run_node`` and rclpy do later, so a stop signal during
    the imports is not lost while the node goes on to start (measured: it then planned and ran
    until the launcher's SIGTERM). Before this point — the interpreter's own start-up — nothing
    of ours runs; ``pearl launch`` starts nodes with SIGINT at its default for that reason.

    Only in a process started to run a node: ``python -m pearl_pomdp.nodes.X`` (``sys.argv[0]``
    is ``-m`` while the module is being located, i.e. while this package is imported) or a
    node's console script. Any other importer (a test, ``pearl demo``) keeps its handler.
    """
    argv0 = _sys.argv[0] if _sys.argv else ""
    starting_a_node = argv0 == "-m" or _os.path.basename(argv0) in _NODE_SCRIPTS
    if starting_a_node and _signal.getsignal(_signal.SIGINT) in (_signal.default_int_handler, _signal.SIG_IGN):
        _signal.signal(_signal.SIGINT, _exit_quietly)


_quiet_interrupt_while_starting()
