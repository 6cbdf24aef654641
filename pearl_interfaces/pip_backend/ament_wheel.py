"""A PEP 517 build backend that builds an ament_cmake interface package into a wheel.

``pip`` installs the ROS 2 wheels named in ``pyproject.toml`` into its isolated build
environment, then calls :func:`build_wheel`: cmake configures the package against that
environment's ament prefix, builds the interfaces and installs them into a staging prefix,
which becomes the wheel (the Python package at the wheel's root, ``lib/``, ``share/`` and
``include/`` as data installed under the target environment's prefix).

Standard library only (it runs before anything else is importable).
"""
from __future__ import annotations

import base64
import csv
import hashlib
import io
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Tuple

SOURCE = Path(__file__).resolve().parents[1]

#: What the built messages need at run time: the message runtime and the packages they use.
REQUIRES = ["ros-jazzy-rclpy", "ros-jazzy-rosidl-default-runtime", "numpy>=1.24"]


def _package_xml() -> Tuple[str, str, str]:
    text = (SOURCE / "package.xml").read_text(encoding="utf-8")
    name, version, summary = (re.search(rf"<{tag}>([^<]+)</{tag}>", text) for tag in ("name", "version", "description"))
    if not (name and version and summary):
        raise RuntimeError(f"{SOURCE / 'package.xml'}: needs <name>, <version> and <description>")
    return name.group(1).strip(), version.group(1).strip(), " ".join(summary.group(1).split())


def _ament_prefixes() -> List[str]:
    """Every prefix on ``sys.path`` (``<prefix>/lib/pythonX.Y/site-packages``) that holds an ament index."""
    out: List[str] = []
    for entry in sys.path:  # (pip's isolated build: its build environment only, not the target venv)
        path = Path(entry)
        if path.name != "site-packages" or len(path.parents) < 3:
            continue
        prefix = path.parents[2]
        if (prefix / "share" / "ament_index").is_dir() and str(prefix) not in out:
            out.append(str(prefix))
    return out


def _run(cmd: List[str], env: Dict[str, str], log: Path) -> None:
    with log.open("a", encoding="utf-8") as fh:
        fh.write("$ " + " ".join(cmd) + "\n")
        fh.flush()
        done = subprocess.run(cmd, env=env, stdout=fh, stderr=subprocess.STDOUT)
    if done.returncode != 0:
        tail = log.read_text(encoding="utf-8", errors="replace").splitlines()[-60:]
        raise RuntimeError(f"{SOURCE.name}: {' '.join(cmd[:2])} failed (exit {done.returncode}); "
                           "the log's end:\n" + "\n".join(tail))


def _cmake_install(stage: Path, work: Path) -> None:
    cmake = shutil.which("cmake")
    if cmake is None:
        raise RuntimeError(f"{SOURCE.name}: building the ROS 2 interfaces needs cmake (and a C/C++ compiler) "
                           "on PATH: install them (Debian: apt-get install cmake g++)")
    prefixes = _ament_prefixes()
    if not prefixes:
        raise RuntimeError(f"{SOURCE.name}: no ament prefix found on sys.path (is ros-jazzy-ament-cmake installed?)")
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(prefixes)
    env["CMAKE_PREFIX_PATH"] = os.pathsep.join(prefixes + [p for p in env.get("CMAKE_PREFIX_PATH", "").split(os.pathsep) if p])
    env["PATH"] = os.pathsep.join([str(Path(p) / "bin") for p in prefixes] + [env.get("PATH", "")])
    log = work / "cmake.log"
    build = work / "build"
    _run([cmake, "-S", str(SOURCE), "-B", str(build), f"-DCMAKE_INSTALL_PREFIX={stage}",
          f"-DPython3_EXECUTABLE={sys.executable}", f"-DPYTHON_EXECUTABLE={sys.executable}",
          "-DBUILD_TESTING=OFF", "-DCMAKE_BUILD_TYPE=Release"], env, log)
    _run([cmake, "--build", str(build), "--parallel", str(os.cpu_count() or 1)], env, log)
    _run([cmake, "--install", str(build)], env, log)


def _tag() -> str:
    impl = f"cp{sys.version_info.major}{sys.version_info.minor}"
    return f"{impl}-{impl}-" + re.sub(r"[-.]", "_", sysconfig.get_platform())


def _wheel_files(stage: Path, name: str, data: str) -> Iterator[Tuple[str, Path]]:
    """(path in the wheel, file) for everything the staging prefix holds."""
    site = next(stage.glob("lib/python*/site-packages"), None)
    if site is None or not (site / name).is_dir():
        raise RuntimeError(f"{SOURCE.name}: cmake installed no Python package {name} under {stage}/lib/python*/site-packages")
    for path in sorted(stage.rglob("*")):
        if path.is_dir() or "__pycache__" in path.parts:
            continue
        rel = path.relative_to(stage)
        if site in path.parents:
            inner = path.relative_to(site)
            if inner.parts[0] == name:  # the message modules; the egg-info cmake writes is not needed
                yield inner.as_posix(), path
        else:
            yield f"{data}/data/{rel.as_posix()}", path


def _record_hash(blob: bytes) -> str:
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(blob).digest()).rstrip(b"=").decode()


def _metadata(dist: str, version: str, summary: str) -> str:
    lines = ["Metadata-Version: 2.1", f"Name: {dist}", f"Version: {version}", f"Summary: {summary}",
             "License: Apache-2.0"] + [f"Requires-Dist: {r}" for r in REQUIRES]
    return "\n".join(lines) + "\n"


def build_wheel(wheel_directory: str, config_settings: Optional[dict] = None,
                metadata_directory: Optional[str] = None) -> str:
    name, version, summary = _package_xml()
    dist = name.replace("-", "_")
    wheel_name = f"{dist}-{version}-{_tag()}.whl"
    info, data = f"{dist}-{version}.dist-info", f"{dist}-{version}.data"
    with tempfile.TemporaryDirectory(prefix=f"{name}-build-") as tmp:
        work = Path(tmp)
        stage = work / "stage"
        _cmake_install(stage, work)
        records: List[List[str]] = []
        with zipfile.ZipFile(Path(wheel_directory) / wheel_name, "w", zipfile.ZIP_DEFLATED) as whl:
            def add(arcname: str, blob: bytes, mode: int = 0o644) -> None:
                entry = zipfile.ZipInfo(arcname, date_time=(2020, 1, 1, 0, 0, 0))
                entry.external_attr = (0o100000 | mode) << 16
                entry.compress_type = zipfile.ZIP_DEFLATED
                whl.writestr(entry, blob)
                records.append([arcname, _record_hash(blob), str(len(blob))])

            for arcname, path in _wheel_files(stage, name, data):
                add(arcname, path.read_bytes(), 0o755 if os.access(path, os.X_OK) else 0o644)
            add(f"{info}/METADATA", _metadata(dist, version, summary).encode())
            add(f"{info}/WHEEL", (f"Wheel-Version: 1.0\nGenerator: {name} ament_wheel\nRoot-Is-Purelib: false\n"
                                  f"Tag: {_tag()}\n").encode())
            out = io.StringIO()
            writer = csv.writer(out, lineterminator="\n")
            writer.writerows(records + [[f"{info}/RECORD", "", ""]])
            whl.writestr(f"{info}/RECORD", out.getvalue())
    return wheel_name
