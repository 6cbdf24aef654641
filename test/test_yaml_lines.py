"""pearl_pomdp.yaml_lines on libyaml's parser gives what the pure-Python loader gives: the same data,
the same line of every key and item, and the same errors."""
from __future__ import annotations

from pathlib import Path

import pytest

from pearl_pomdp import yaml_lines
from pearl_pomdp.errors import SpecError

REPO = Path(__file__).resolve().parents[1]
FILES = sorted(p for pattern in ("config/**/*.yaml", "test/data/**/*.yaml") for p in REPO.glob(pattern))

pytestmark = pytest.mark.skipif(yaml_lines._FastLoader is None, reason="this PyYAML has no libyaml")


def _pure(text: str, source: str):
    fast, yaml_lines._FastLoader = yaml_lines._FastLoader, None
    try:
        return yaml_lines.parse_yaml(text, source)
    finally:
        yaml_lines._FastLoader = fast


def _same(fast, pure, where="") -> None:
    assert type(fast) is type(pure), where
    if isinstance(fast, (dict, list)):
        assert (fast.line, fast.lines) == (pure.line, pure.lines), where
        pairs = fast.items() if isinstance(fast, dict) else enumerate(fast)
        for key, value in pairs:
            _same(value, pure[key], f"{where}.{key}")
    else:
        assert fast == pure, where


def test_every_shipped_yaml_reads_the_same_with_its_lines():
    assert len(FILES) > 20
    for path in FILES:
        text = path.read_text(encoding="utf-8")
        _same(yaml_lines.parse_yaml(text, str(path)), _pure(text, str(path)), str(path))


def test_yes_no_stay_strings_and_true_is_a_boolean_on_the_fast_path():
    data = yaml_lines.parse_yaml("a: yes\nb: no\nc: on\nd: true\ne: [1, 2.5, null]\n")
    assert data == {"a": "yes", "b": "no", "c": "on", "d": True, "e": [1, 2.5, None]}
    assert data.lines == {"a": 1, "b": 2, "c": 3, "d": 4, "e": 5}


@pytest.mark.parametrize("text", ["a: [1, 2\n", "a: 1\na: 2\n", "a:\n  - b: 1\n  c: 2\n", "? [1]\n: x\n"])
def test_a_bad_file_gives_the_pure_loaders_error_with_its_line(text):
    with pytest.raises(SpecError) as fast:
        yaml_lines.parse_yaml(text, "bad.yaml")
    with pytest.raises(SpecError) as pure:
        _pure(text, "bad.yaml")
    assert str(fast.value) == str(pure.value) and "bad.yaml" in str(fast.value)
