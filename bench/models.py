"""Where the bench scripts find the benchmark models: ``test/data/pomdp`` in this repository.

The files and their provenance are listed in ``test/data/pomdp/README.md``. The one kept
compressed (``RockSample_7_8.pomdp.xz``) is decompressed once into ``out/bench-models/``
(git-ignored, next to the other outputs). Peer-solver results (pomdp-solve, SARSOP) are not
part of the repository: scripts that compare with them take ``--peer-results FILE`` and
leave the peer columns empty, saying so, without it.
"""
from __future__ import annotations

import lzma
import shutil
import sys
from pathlib import Path
from typing import List, Optional

REPO = Path(__file__).resolve().parents[1]
#: The models as stored in the repository.
MODELS = REPO / "test" / "data" / "pomdp"
#: Where compressed models are unpacked for the bench scripts.
UNPACKED = REPO / "out" / "bench-models"


def model_dir() -> Path:
    """A folder with every benchmark model as a plain ``.pomdp`` file (unpacking what is compressed)."""
    UNPACKED.mkdir(parents=True, exist_ok=True)
    for path in sorted(MODELS.iterdir()):
        if path.suffix == ".xz":
            out = UNPACKED / path.stem
            if not out.is_file() or out.stat().st_mtime < path.stat().st_mtime:
                tmp = out.with_name("." + out.name + ".tmp")
                with lzma.open(path) as src, open(tmp, "wb") as dst:
                    shutil.copyfileobj(src, dst)
                tmp.replace(out)
        elif path.suffix.lower() == ".pomdp":
            link = UNPACKED / path.name
            if not link.exists():
                link.symlink_to(path)
    return UNPACKED


def model_files() -> List[Path]:
    """Every benchmark model, smallest first."""
    folder = model_dir()
    return sorted((p for p in folder.iterdir() if p.suffix.lower() == ".pomdp"), key=lambda p: p.stat().st_size)


def model_path(name: str) -> Path:
    """``name`` as given when it is a file, else the benchmark model of that name.

    Raises:
        SystemExit: neither exists (the message names both places looked in).
    """
    given = Path(name)
    if given.is_file():
        return given
    path = model_dir() / name
    if path.is_file():
        return path
    raise SystemExit(f"{Path(sys.argv[0]).name}: no such model file: {name} (looked in . and {MODELS})")


def peer_results(path: Optional[str]) -> Optional[Path]:
    """The peer-results file given with ``--peer-results``, or ``None`` (said once on stderr).

    Raises:
        SystemExit: a path was given and does not exist.
    """
    if not path:
        print(f"{Path(sys.argv[0]).name}: no --peer-results FILE given: the peer-solver columns stay empty "
              "(the peers are built and run outside this repository; docs/solvers.md)", file=sys.stderr)
        return None
    p = Path(path)
    if not p.is_file():
        raise SystemExit(f"{Path(sys.argv[0]).name}: --peer-results: no such file: {p}")
    return p
