"""The ROS-free boundary, checked (issue 10): the core imports without rclpy, never imports the
simulator, and the ROS layer holds no Pearl domain facts."""
from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: The ROS layer: only these may import rclpy or ROS message packages.
ROS_LAYER = ("pearl_pomdp/nodes/", "pearl_sim/nodes.py", "pearl_sim/nursing_home/bt_node.py", "pearl_sim/world_hardware.py")
ROS_PACKAGES = ("rclpy", "rcl_interfaces", "std_msgs", "rosgraph_msgs", "geometry_msgs", "builtin_interfaces",
                "diagnostic_msgs", "nav_msgs", "lifecycle_msgs", "std_srvs", "sensor_msgs", "pearl_interfaces")


def modules_outside_ros_layer():
    out = []
    for package in ("pearl_pomdp", "pearl_sim"):
        for path in sorted((REPO / package).rglob("*.py")):
            rel = path.relative_to(REPO).as_posix()
            if any(rel.startswith(p) for p in ROS_LAYER):
                continue
            name = rel[:-3].replace("/", ".").removesuffix(".__init__")
            out.append(name)
    return out


def test_every_core_module_imports_with_ros_unimportable():
    blocker = f"""
import importlib, importlib.abc, sys
BLOCKED = {ROS_PACKAGES!r}
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in BLOCKED:
            raise ImportError(f'{{name}} is blocked: the core must not import ROS')
sys.meta_path.insert(0, Block())
failed = []
for name in {modules_outside_ros_layer()!r}:
    try:
        importlib.import_module(name)
    except ImportError as err:
        failed.append(f'{{name}}: {{err}}')
print('\\n'.join(failed))
sys.exit(1 if failed else 0)
"""
    proc = subprocess.run([sys.executable, "-c", blocker], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"modules that need ROS outside the ROS layer:\n{proc.stdout}{proc.stderr[-2000:]}"
    assert len(modules_outside_ros_layer()) > 40   # the walk really found the package


def test_the_core_never_imports_the_simulator():
    offenders = []
    for path in sorted((REPO / "pearl_pomdp").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            offenders += [f"{path.relative_to(REPO)}:{node.lineno}" for n in names if n.split(".")[0] == "pearl_sim"]
    assert not offenders, f"pearl_pomdp imports pearl_sim at {offenders}"


def test_no_pearl_action_name_in_the_ros_layer():
    """Which actions drive, speak or clarify comes from the domain and the params file, not from node code."""
    from pearl_pomdp.model.domain_yaml import load_domain

    actions = load_domain(REPO / "config" / "pearl.domain.yaml").actions
    hits = []
    for path in sorted((REPO / "pearl_pomdp" / "nodes").glob("*.py")):
        text = path.read_text(encoding="utf-8")
        hits += [f"{path.name}: {a}" for a in actions if re.search(rf"\b{a}\b", text)]
    assert not hits, f"Pearl action names in pearl_pomdp/nodes/: {hits}"
