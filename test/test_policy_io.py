"""Policy files: .npz (no pickle) + JSON header, fingerprint checks, clear errors."""
import json
import re

import numpy as np
import pytest

from pearl_pomdp.errors import PolicyError
from pearl_pomdp.policy_io import header_path, load_policy, read_policy_header, save_policy
from pearl_pomdp.solution import AlphaVectorPolicy
from test_belief import three_state, tiger


def tiger_policy():
    # Three vectors: open-right (tiger surely left), listen, open-left (tiger surely right).
    return AlphaVectorPolicy(np.array([[10.0, -100.0], [-1.0, -1.0], [-100.0, 10.0]]), [2, 0, 1])


def test_round_trip_alpha_vectors(tmp_path):
    model = tiger()
    policy = tiger_policy()
    out = save_policy(tmp_path / "tiger.npz", policy, model,
                      {"method": "incprune", "value_at_start": np.float64(19.3713683743952), "upper_bound": None,
                       "seconds": 0.25, "horizon": 15})
    assert out == tmp_path / "tiger.npz"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tiger.json", "tiger.npz"]  # no temp files left
    # Arrays only: numpy reads it without pickle.
    with np.load(out, allow_pickle=False) as npz:
        assert sorted(npz.files) == ["actions", "alphas"]
        np.testing.assert_array_equal(npz["alphas"], policy.alphas)
    header = json.loads((tmp_path / "tiger.json").read_text())
    assert header["model_fingerprint"] == model.fingerprint()
    assert (header["model_name"], header["states"], header["actions"], header["observations"]) == ("tiger.95", 2, 3, 2)
    assert header["action_names"] == ["listen", "open-left", "open-right"]
    assert (header["method"], header["value_at_start"], header["upper_bound"]) == ("incprune", 19.3713683743952, None)
    assert header["solve_seconds"] == 0.25 and header["num_vectors"] == 3 and header["meta"] == {"horizon": 15}
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", header["created"])

    loaded = load_policy(out, model)
    np.testing.assert_array_equal(loaded.alphas, policy.alphas)
    np.testing.assert_array_equal(loaded.actions, policy.actions)
    assert loaded.header["method"] == "incprune"
    for b in ([0.9, 0.1], [0.5, 0.5], [0.02, 0.98]):
        assert loaded.action(np.array(b)) == policy.action(np.array(b))
    assert [loaded.action(np.array(b)) for b in ([0.99, 0.01], [0.5, 0.5], [0.01, 0.99])] == [2, 0, 1]


def test_model_mismatch_names_both_models(tmp_path):
    save_policy(tmp_path / "p.npz", tiger_policy(), tiger(), {"method": "qmdp"})
    other = tiger(accuracy=0.8)
    other.name = "tiger.80"
    with pytest.raises(PolicyError) as err:
        load_policy(tmp_path / "p.npz", other)
    msg = str(err.value)
    fp = tiger().fingerprint()
    assert msg.startswith(f"{tmp_path / 'p.npz'}: policy was solved for model 'tiger.95' (fingerprint {fp[:12]}…")
    assert f"this model is 'tiger.80' ({other.fingerprint()[:12]}…, 2 states" in msg
    with pytest.raises(PolicyError, match=r"'tiger.95' .* 2 states, 3 actions.*'three' .* 3 states, 1 actions"):
        load_policy(tmp_path / "p.npz", three_state())
    # Without a model the file loads.
    assert load_policy(tmp_path / "p.npz").num_vectors == 3


def test_missing_and_corrupt_files(tmp_path):
    p = tmp_path / "p.npz"
    with pytest.raises(PolicyError, match=re.escape(f"{p}: policy file not found")):
        load_policy(p)
    save_policy(p, tiger_policy(), tiger(), {})
    h = header_path(p)
    # Header gone.
    saved = h.read_text()
    h.unlink()
    with pytest.raises(PolicyError, match=re.escape(f"{p}: policy header {h} not found")):
        load_policy(p)
    # Header not JSON.
    h.write_text('{"format": "pearl-policy",\n  oops}')
    with pytest.raises(PolicyError, match=re.escape(f"{h}:2: policy header is not valid JSON")):
        load_policy(p)
    # Header of another kind of file.
    h.write_text('{"format": "something-else"}')
    with pytest.raises(PolicyError, match="not a Pearl policy header"):
        load_policy(p)
    h.write_text(saved)
    # Arrays truncated after saving.
    p.write_bytes(p.read_bytes()[:40])
    with pytest.raises(PolicyError, match=r"the arrays do not match the header .*npz_sha256"):
        load_policy(p)


def _rewrite_npz(p, **arrays):
    """Replace the arrays and fix the header's checksum (a hand-edited policy)."""
    import hashlib

    np.savez(p.with_suffix(".tmp.npz"), **arrays)
    data = p.with_suffix(".tmp.npz").read_bytes()
    p.write_bytes(data)
    h = header_path(p)
    header = json.loads(h.read_text())
    header["npz_sha256"] = hashlib.sha256(data).hexdigest()
    h.write_text(json.dumps(header))


def test_no_pickle_and_bad_arrays(tmp_path):
    p = tmp_path / "p.npz"
    save_policy(p, tiger_policy(), tiger(), {})
    _rewrite_npz(p, alphas=np.array([{"x": 1}], dtype=object), actions=np.array([0]))
    with pytest.raises(PolicyError, match=r"not a readable \.npz policy .*pickle"):
        load_policy(p)
    _rewrite_npz(p, alphas=np.zeros((2, 2)), actions=np.array([0, 5]))
    with pytest.raises(PolicyError, match=r"'actions' has action index 5, outside 0..2"):
        load_policy(p)
    _rewrite_npz(p, alphas=np.zeros((2, 3)), actions=np.array([0, 1]))
    with pytest.raises(PolicyError, match=r"do not fit 2 states"):
        load_policy(p)
    _rewrite_npz(p, values=np.zeros(3))
    with pytest.raises(PolicyError, match=r"array 'alphas' is missing \(has: values\)"):
        load_policy(p)
    p.write_bytes(b"not a zip at all")
    header = json.loads(header_path(p).read_text())
    import hashlib
    header["npz_sha256"] = hashlib.sha256(b"not a zip at all").hexdigest()
    header_path(p).write_text(json.dumps(header))
    with pytest.raises(PolicyError, match=r"not a readable \.npz policy"):
        load_policy(p)


def test_save_rejects_policy_that_does_not_fit(tmp_path):
    with pytest.raises(PolicyError, match=r"model 'three' has 3 states"):
        save_policy(tmp_path / "p.npz", tiger_policy(), three_state(), {})
    with pytest.raises(PolicyError, match="cannot save a dict"):
        save_policy(tmp_path / "p.npz", {}, tiger(), {})
    with pytest.raises(PolicyError, match="meta is not JSON-serialisable"):
        save_policy(tmp_path / "p.npz", tiger_policy(), tiger(), {"when": object()})
    with pytest.raises(PolicyError, match="must not end in .json"):
        save_policy(tmp_path / "p.json", tiger_policy(), tiger(), {})
    assert list(tmp_path.iterdir()) == []  # nothing half-written


def test_header_beside_path_without_npz_suffix(tmp_path):
    p = tmp_path / "tiger.policy"
    save_policy(p, tiger_policy(), tiger(), {"method": "qmdp"})
    assert (tmp_path / "tiger.json").is_file()
    assert read_policy_header(p)["method"] == "qmdp"


def test_most_likely_state_policy_round_trip(tmp_path):
    from pearl_pomdp.policies import MostLikelyStatePolicy
    policy = MostLikelyStatePolicy(np.array([2, 1]))
    save_policy(tmp_path / "mls.npz", policy, tiger(), {"method": "mls"})
    with np.load(tmp_path / "mls.npz", allow_pickle=False) as npz:
        assert npz.files == ["state_actions"]
    loaded = load_policy(tmp_path / "mls.npz", tiger())
    assert isinstance(loaded, MostLikelyStatePolicy)
    np.testing.assert_array_equal(loaded.state_actions, [2, 1])
    assert loaded.action(np.array([0.7, 0.3])) == 2 and loaded.action(np.array([0.2, 0.8])) == 1
