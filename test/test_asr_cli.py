"""`pearl listen` and `pearl calibrate-speech` as a user runs them."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import pocketsphinx  # noqa: F401  (a missing install fails, it is not skipped)
import espeakng_loader  # noqa: F401  (a missing install fails, it is not skipped)

from ros_helpers import DOMAIN, REPO  # noqa: E402

PEARL = str(Path(sys.executable).parent / "pearl")


def pearl(*args, env=None):
    return subprocess.run([PEARL, *args], capture_output=True, text=True, cwd=REPO, timeout=120, env=env)


def test_listen_to_a_wav_file_prints_text_confidence_symbol(tmp_path):
    from pearl_pomdp.asr.audio import mix_at_snr, write_wav
    from pearl_pomdp.asr.synthesizer import synthesize

    write_wav(tmp_path / "ask.wav", mix_at_snr(synthesize("what time is it", "clear"), 30, np.random.default_rng(0)))
    out = pearl("listen", str(tmp_path / "ask.wav"), "--domain", str(DOMAIN), "--json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["symbol"] == "time" and "time" in result["text"].split() and 0 < result["confidence"] <= 1
    human = pearl("listen", str(tmp_path / "ask.wav"), "--domain", str(DOMAIN))
    assert "symbol:     time" in human.stdout


def test_listen_errors_are_one_line(tmp_path):
    (tmp_path / "bad.wav").write_bytes(b"not a wav")
    for args, problem in [(["listen", str(tmp_path / "bad.wav")], "bad.wav: not a PCM WAV file"),
                          (["listen", "--say", "yes", "--voice", "robot"], "unknown voice 'robot'"),
                          (["listen"], "give exactly one of")]:
        out = pearl(*args, "--domain", str(DOMAIN))
        assert out.returncode == 2 and problem in out.stderr and len(out.stderr.strip().splitlines()) == 1, out.stderr


def test_calibrate_speech_writes_the_channel(tmp_path):
    utts = tmp_path / "u.yaml"
    utts.write_text("time: [what time is it]\nunknown: [hello pearl]\n")
    env = {**__import__("os").environ, "PEARL_CACHE_DIR": str(tmp_path / "cache")}
    out = pearl("calibrate-speech", str(DOMAIN), "--snr", "30", "--voices", "clear", "--utterances", str(utts),
                "--out", str(tmp_path / "ch.json"), "--write-observation-table", str(tmp_path / "fitted.yaml"),
                "--json", env=env)
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    assert summary["trials"] == 2 and summary["accuracy"]["30"] == 1.0
    table = json.loads((tmp_path / "ch.json").read_text())
    assert table["cells"]["30"]["time"]["counts"] == {"time": 1}
    from pearl_pomdp.model.domain_yaml import load_domain

    assert summary["observation_table"]["snr_db"] == 30.0
    assert load_domain(tmp_path / "fitted.yaml").compile().num_observations == 20   # 18 + navFailed, userLost
    bad = pearl("calibrate-speech", str(DOMAIN), "--snr", "loud", env=env)
    assert bad.returncode == 2 and "--snr" in bad.stderr
