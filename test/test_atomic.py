"""Files written for users get the mode of a plain write, and `pearl bag-info` names the
QoS history (issue 16 item 8)."""
import os
import stat
from contextlib import contextmanager
from pathlib import Path

import pytest

from pearl_pomdp.atomic import atomic_write
from pearl_pomdp.cli import main

REPO = Path(__file__).resolve().parents[1]


@contextmanager
def umask(mask: int):
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


def mode(path: Path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("mask, expected", [(0o022, 0o644), (0o027, 0o640), (0o002, 0o664)])
def test_atomic_write_gives_a_new_file_0666_less_the_umask(tmp_path, mask, expected):
    with umask(mask):
        atomic_write(tmp_path / "new.txt", "hello")
    assert mode(tmp_path / "new.txt") == expected
    assert (tmp_path / "new.txt").read_text() == "hello"


def test_atomic_write_keeps_the_mode_of_the_file_it_replaces(tmp_path):
    target = tmp_path / "private.json"
    target.write_text("old")
    os.chmod(target, 0o600)
    with umask(0o022):
        atomic_write(target, "new")
    assert mode(target) == 0o600 and target.read_text() == "new"


def test_export_and_solve_out_write_shareable_files(tmp_path, benchmarks_dir, capsys):
    with umask(0o022):
        assert main(["export", str(REPO / "config" / "table4.domain.yaml"), "--out", str(tmp_path / "t4.pomdp")]) == 0
        assert main(["export", str(REPO / "config" / "table4.domain.yaml"), "--out", str(tmp_path / "t4.pomdpx")]) == 0
        assert main(["solve", str(benchmarks_dir / "tiger.95.POMDP"), "--horizon", "3", "--quiet",
                     "--out", str(tmp_path / "tiger.npz")]) == 0
    capsys.readouterr()
    written = sorted(p.name for p in tmp_path.iterdir())
    assert written == ["t4.pomdp", "t4.pomdpx", "tiger.json", "tiger.npz"]
    assert {p.name: oct(mode(p)) for p in tmp_path.iterdir()} == {name: "0o644" for name in written}


def test_bag_metadata_yaml_is_0644_like_rosbag2(tmp_path):
    from pearl_pomdp.bags.metadata import QosProfile
    from pearl_pomdp.bags.writer import BagWriter

    with umask(0o022):
        with BagWriter(tmp_path / "bag") as w:
            w.add_topic("/pearl/action", "std_msgs/msg/String", qos=[QosProfile()])
    assert mode(tmp_path / "bag" / "metadata.yaml") == 0o644
    assert mode(tmp_path / "bag" / "bag_0.mcap") == 0o644


def test_bag_info_says_which_qos_policy_is_unknown(capsys):
    assert main(["bag-info", str(REPO / "bags" / "table4_clarification")]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if "Topic: /pearl/display " in x)
    assert line.endswith("QoS: reliable/volatile, history unknown")
    assert " unknown" not in line.replace("history unknown", "")
