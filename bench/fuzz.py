"""Longer fuzzing of every input reader than the suite's bounded budget (issue 7).

Mutates the shipped/benchmark files (truncation, line deletion/duplication, token swaps,
token replacement by hostile values, bit flips, insertions) and damages bags and policy
files; every input must load or raise the project's own error naming the file. Anything else
is a crash. Prints ONE JSON object: per target inputs, loaded, rejected (own error), crashes
(with the first few examples), slowest input (s).

    .venv/bin/python bench/fuzz.py [--n 2000] [--seed 0]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
import traceback
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "test"))
sys.path.insert(0, str(REPO))

from test_fuzz_inputs import BENCH, CONFIG, INSERTS, MUTATIONS, POMDP_FILES, _write_bag, mutate  # noqa: E402

from pearl_pomdp.errors import PearlError  # noqa: E402


def _targets(tmp: Path):
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.hierarchy.spec import parse_hierarchy
    from pearl_pomdp.model.domain_yaml import load_domain, parse_domain
    from pearl_pomdp.model.pomdp_format import parse_pomdp
    from pearl_pomdp.model.pomdpx import format_pomdpx, parse_pomdpx
    from pearl_pomdp.policy_io import load_policy, save_policy
    from pearl_pomdp.solution import AlphaVectorPolicy
    from pearl_sim.nursing_home.scenario import parse_scenarios

    domain = load_domain(CONFIG / "pearl.domain.yaml")
    features = {f.name: list(f.values) for f in domain.features}
    texts = {}
    for name in POMDP_FILES:
        texts[f"pomdp:{name}"] = ((BENCH / name).read_text(), lambda t, n=name: parse_pomdp(t, source=n))
    tiger = parse_pomdp((BENCH / "tiger.95.POMDP").read_text(), source="tiger")
    texts["pomdpx:tiger"] = (format_pomdpx(tiger), lambda t: parse_pomdpx(t, source="tiger.pomdpx"))
    for name in ("pearl.domain.yaml", "table4.domain.yaml"):
        texts[f"domain:{name}"] = ((CONFIG / name).read_text(), lambda t, n=name: parse_domain(t, source=n))
    texts["hierarchy:pearl"] = ((CONFIG / "pearl.hierarchy.yaml").read_text(),
                                lambda t: parse_hierarchy(t, domain.actions, features, source="h.yaml"))
    for p in sorted((CONFIG / "scenarios").glob("*.yaml")):
        texts[f"scenario:{p.name}"] = (p.read_text(), lambda t, n=p.name: parse_scenarios(t, source=n))

    # Binary targets: bytes -> load from a file.
    bags = {}
    for kind, kw in (("plain", {}), ("chunked", {"chunk_size": 300, "compression": "zstd"})):
        _write_bag(tmp / kind, **kw)
        bags[f"bag:{kind}"] = next((tmp / kind).glob("*.mcap")).read_bytes()
    pol_dir = tmp / "policy"
    pol_dir.mkdir()
    save_policy(pol_dir / "t.npz", AlphaVectorPolicy(np.array([[1.0, -2.0], [-2.0, 1.0]]), np.array([1, 2])), tiger, {})
    binaries = {"bag": bags, "policy:npz": (pol_dir / "t.npz").read_bytes(), "policy:json": (pol_dir / "t.json").read_bytes()}

    def load_bag(data: bytes, f: Path):
        f.write_bytes(data)
        return BagReader(f)

    def load_pol(data: bytes, which: str, f: Path):
        d = f.parent
        shutil.copy(pol_dir / "t.npz", d / "t.npz")
        shutil.copy(pol_dir / "t.json", d / "t.json")
        (d / which).write_bytes(data)
        return load_policy(d / "t.npz", tiger)

    return texts, binaries, load_bag, load_pol


def run(n: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    out = {"seed": seed, "per_target": {}, "inputs": 0, "crashes": 0, "crash_examples": []}
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        texts, binaries, load_bag, load_pol = _targets(tmp)
        jobs = []
        for name, (text, parse) in texts.items():
            jobs.append((name, lambda m, text=text, parse=parse: parse(mutate(text, *m))))
        for name, data in binaries["bag"].items():
            jobs.append((name, lambda m, data=data: load_bag(_damage(data, m), tmp / "f_0.mcap")))
        for which in ("npz", "json"):
            data = binaries[f"policy:{which}"]
            jobs.append((f"policy:{which}", lambda m, data=data, which=which:
                         load_pol(_damage(data, m), f"t.{which}", tmp / "p" / "x")))
        (tmp / "p").mkdir()
        per = max(1, n // len(jobs))
        for name, job in jobs:
            stats = {"inputs": 0, "loaded": 0, "rejected": 0, "crashes": 0, "slowest_s": 0.0}
            for _ in range(per):
                m = (MUTATIONS[int(rng.integers(len(MUTATIONS)))], int(rng.integers(10**7)), int(rng.integers(10**7)),
                     int(rng.integers(len(INSERTS) * 8)))
                t0 = time.perf_counter()
                try:
                    job(m)
                    stats["loaded"] += 1
                except PearlError:
                    stats["rejected"] += 1
                except Exception as err:  # a crash: not the project's own error
                    stats["crashes"] += 1
                    if len(out["crash_examples"]) < 10:
                        out["crash_examples"].append({"target": name, "mutation": list(m), "error": repr(err)[:300],
                                                      "where": traceback.format_exc().splitlines()[-3][:200]})
                stats["slowest_s"] = max(stats["slowest_s"], round(time.perf_counter() - t0, 4))
                stats["inputs"] += 1
            out["per_target"][name] = stats
            out["inputs"] += stats["inputs"]
            out["crashes"] += stats["crashes"]
    return out


def _damage(data: bytes, m) -> bytes:
    kind, i, j, pick = m
    b = bytearray(data)
    k = i % len(b)
    if kind == "truncate":
        return bytes(b[:k])
    if kind in ("flip_byte", "replace_token"):
        b[k] ^= 1 << (pick % 8)
        return bytes(b)
    if kind == "delete_line":
        return bytes(b[:k] + b[k + 1 + j % 16:])
    if kind == "duplicate_line":
        return bytes(b[:k] + b[k:k + 1 + j % 64] + b[k:])
    if kind == "swap_tokens":
        b[k:k + 4] = bytes([pick % 256, 255, 255, 255])[: len(b[k:k + 4])]
        return bytes(b)
    return bytes(b[:k]) + np.random.default_rng(j).integers(0, 256, 1 + pick, dtype=np.uint8).tobytes()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000, help="total inputs (split over the targets)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    t0 = time.perf_counter()
    res = run(args.n, args.seed)
    res["seconds"] = round(time.perf_counter() - t0, 1)
    res["load_average"] = os.getloadavg()[0]
    print(json.dumps(res))
    return 1 if res["crashes"] else 0


if __name__ == "__main__":
    sys.exit(main())
