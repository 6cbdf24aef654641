"""The ament layout colcon produces: executables in ``P/lib/pearl_pomdp``, the
launch file and configuration in ``P/share/pearl_pomdp``, the ament index marker — what
``ros2 run pearl_pomdp belief_tracker`` and ``ros2 launch pearl_pomdp pearl.launch.xml`` look for."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_colcon_style_install_layout(tmp_path):
    build, prefix = tmp_path / "build", tmp_path / "install"
    build.mkdir()
    out = subprocess.run([sys.executable, "setup.py", "-q", "egg_info", "--egg-base", str(build), "build",
                          "--build-base", str(build / "build"), "install", "--prefix", str(prefix),
                          "--single-version-externally-managed", "--record", str(build / "install.log")],
                         cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    for name in ("belief_tracker", "hierarchical_policy", "action_executor", "landmark_detector", "guide_pace"):
        exe = prefix / "lib" / "pearl_pomdp" / name
        assert exe.is_file() and os.access(exe, os.X_OK), name
        assert f"'console_scripts', '{name}'" in exe.read_text()
    share = prefix / "share" / "pearl_pomdp"
    for rel in ("package.xml", "launch/pearl.launch.xml", "config/pearl_nodes.yaml", "config/fastdds_profile.xml",
                "config/pearl.domain.yaml", "config/foxglove/pearl.layout.json"):
        assert (share / rel).is_file(), rel
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "pearl_pomdp").is_file()
    # $(find-pkg-share pearl_pomdp) resolves through the ament index, as ros2 launch does.
    check = subprocess.run([sys.executable, "-c", "from pearl_pomdp.launch_xml import package_share_dir as p; "
                            "print(p('pearl_pomdp'))"], capture_output=True, text=True, timeout=60,
                           env={**os.environ, "AMENT_PREFIX_PATH": str(prefix)})
    assert check.stdout.strip() == str(share), check.stderr
    # The installed executable runs from the installed package (one-line error, exit 2).
    site = next((prefix / "lib").glob("python3*/site-packages"))
    # setup.py build compiled the exact solver's pruning kernel into the install
    assert list((site / "pearl_pomdp" / "solvers").glob("_prune*.so")), "no compiled _prune in the install"
    run = subprocess.run([str(prefix / "lib" / "pearl_pomdp" / "belief_tracker"), "--ros-args", "-p",
                          "domain:=/no/such.yaml"], capture_output=True, text=True, timeout=60, cwd=tmp_path,
                         env={**os.environ, "PYTHONPATH": str(site), "ROS_LOG_DIR": str(tmp_path),
                              "ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"})
    assert run.returncode == 2
    assert run.stderr.strip() == "belief_tracker: error: parameter domain: no such file: /no/such.yaml"
