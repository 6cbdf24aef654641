"""A colcon workspace builds this tree as two packages: ``pearl_interfaces`` (ament_cmake) and
``pearl_pomdp`` (ament_python), with the PyPI Jazzy wheels of this venv and no ROS install (issue 39).

colcon is not a dependency of the project: this test is skipped unless the ``colcon`` command is
installed beside this Python (``.venv/bin/pip install colcon-core colcon-ros``, docs/ros-nodes.md,
"Interfaces"). It copies the working tree into ``src/pearl_pomdp`` of a fresh workspace, runs
``colcon build`` (colcon does not look inside a package's folder, so both base paths are named),
and then uses the colcon install alone — its interface package (Python module, generated libraries,
``share/`` definitions) and its ``pearl_pomdp`` executables — in a fresh process.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
COLCON = Path(sys.executable).parent / "colcon"

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not COLCON.is_file(), reason="colcon is not installed beside this Python "
                                                              "(pip install colcon-core colcon-ros)")]

#: Run with the colcon install alone on the paths: the interfaces' module, libraries and definitions.
USE_THE_INSTALL = textwrap.dedent("""
    import sys
    from pathlib import Path
    import pearl_interfaces.msg as msgs
    from rclpy.serialization import deserialize_message, serialize_message
    from pearl_pomdp.launch_xml import package_share_dir
    print(Path(msgs.__file__).resolve())
    action = msgs.Action(name="GuideToPhysio")
    action.stamp.sec = 12
    back = deserialize_message(serialize_message(action), msgs.Action)
    print(back.name, back.stamp.sec)
    print(Path(package_share_dir("pearl_interfaces")).resolve())
    """)


def test_a_colcon_workspace_builds_the_interfaces_and_the_package(tmp_path):
    src = tmp_path / "src" / "pearl_pomdp"
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(".venv", ".git", "__pycache__", "*.egg-info", "build",
                                                            "install", "log", ".pytest_cache", ".hypothesis", "*.so"))
    venv = Path(sys.prefix)
    env = {**os.environ, "AMENT_PREFIX_PATH": str(venv), "CMAKE_PREFIX_PATH": str(venv),
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    build = subprocess.run([str(COLCON), "build", "--base-paths", "src/pearl_pomdp", "src/pearl_pomdp/pearl_interfaces",
                            "--cmake-args", f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF"],
                           cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1200)
    assert build.returncode == 0, build.stdout[-4000:] + build.stderr[-4000:]
    install = tmp_path / "install"
    # Both built, the interfaces first (pearl_pomdp's package.xml exec_depends on them).
    lines = build.stdout.splitlines()
    assert [line.split()[2] for line in lines if line.startswith("Finished <<<")] == ["pearl_interfaces", "pearl_pomdp"]
    for name in ("Action", "Belief", "Decision", "DriveProgress", "RecognisedSpeech"):
        assert (install / "pearl_interfaces" / "share" / "pearl_interfaces" / "msg" / f"{name}.msg").is_file(), name
    sites = [next((install / pkg / "lib").glob("python3*/site-packages")) for pkg in ("pearl_interfaces", "pearl_pomdp")]
    run_env = {**os.environ, "PYTHONPATH": os.pathsep.join(map(str, sites)),
               "LD_LIBRARY_PATH": os.pathsep.join([str(install / "pearl_interfaces" / "lib"),
                                                   os.environ.get("LD_LIBRARY_PATH", "")]),
               "AMENT_PREFIX_PATH": os.pathsep.join([str(install / "pearl_interfaces"), str(install / "pearl_pomdp"),
                                                     str(venv)]),
               "ROS_LOG_DIR": str(tmp_path), "ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"}
    used = subprocess.run([sys.executable, "-c", USE_THE_INSTALL], cwd=tmp_path, env=run_env, capture_output=True,
                          text=True, timeout=120)
    assert used.returncode == 0, used.stderr[-3000:]
    module, round_trip, share = used.stdout.splitlines()
    assert module.startswith(str(install / "pearl_interfaces")), module
    assert round_trip == "GuideToPhysio 12"
    assert share == str((install / "pearl_interfaces" / "share" / "pearl_interfaces").resolve())
    # The installed node starts from the install and says what is wrong in one line.
    tracker = subprocess.run([str(install / "pearl_pomdp" / "lib" / "pearl_pomdp" / "belief_tracker"), "--ros-args",
                              "-p", "domain:=/no/such.yaml"], cwd=tmp_path, env=run_env, capture_output=True, text=True,
                             timeout=120)
    assert tracker.returncode == 2, tracker.stderr[-2000:]
    assert tracker.stderr.strip() == "belief_tracker: error: parameter domain: no such file: /no/such.yaml"
