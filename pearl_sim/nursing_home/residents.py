"""The study's residents, specified before any policy is run (``docs/simulation.md``, *Residents*).

Two populations:

* :func:`paper_residents` — the paper's six residents A–F of ``config/scenarios/study.yaml``
  (walking speeds 5 cm/s to 1 m/s, rests for the slow walkers), exactly as that file
  gives them; what the paper does not report (hearing, memory, …) is left at the world's
  defaults (hears and answers everything, never forgets).
* :func:`generate_residents` — a seeded generator of profiles over every parameter the
  world models. Each range has its source or reason in ``docs/simulation.md``.

A resident's *articulation* is not a world parameter of its own: it adds recogniser errors
on top of the noise level of the study (:func:`effective_word_error_rate`), so the study's
noise axis stays the environment's and a resident with slurred speech is harder at every level.

Every profile is checked with the scenario loader's own range checks
(:func:`resident_scenarios`), so a generated value out of range is the same error as a
typo in a scenario file.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Dict, List, Sequence

import numpy as np

from pearl_pomdp.errors import SpecError

if TYPE_CHECKING:  # pragma: no cover - typing only
    from pearl_sim.nursing_home.scenario import Scenario

__all__ = ["Profile", "paper_residents", "generate_residents", "effective_word_error_rate", "resident_scenarios",
           "parse_population", "study_template", "StudyCase", "TASKS", "RANGES", "MAX_GENERATED"]

#: The generator's ranges (low, high) — each with its reason in docs/simulation.md.
RANGES: Dict[str, tuple] = {
    "walking_speed": (0.05, 1.0),      # m/s, drawn log-uniform (walking aid … brisk)
    "rest_seconds": (5.0, 20.0),       # s per rest
    "hearing": (0.7, 1.0),             # P(she hears a sentence)
    "articulation_wer": (0.0, 0.15),   # extra word errors from her speech
    "responsiveness": (0.8, 1.0),      # P(she answers what she heard)
    "forgets": (0.0, 0.02),            # per action, an unanswered question is forgotten
    "changes_mind": (0.0, 0.02),       # per action, a walk not yet started is given up
    "willingness": (0.7, 1.0),         # P(she accepts the walk after the reminder)
    "answers_door": (0.8, 1.0),        # P(she comes to the door per ring)
    "touchscreen": (0.0, 0.5),         # fraction of answers on the screen
}
#: Most generated residents one study takes (a guard against a typo such as generated:10000).
MAX_GENERATED = 200


@dataclass
class Profile:
    """One resident: the scenario's ``resident:`` fields plus her articulation."""

    name: str
    fields: Dict[str, object] = field(default_factory=dict)
    articulation_wer: float = 0.0


def paper_residents(study_path) -> List[Profile]:
    """The six residents of ``study.yaml`` (one profile per distinct resident name, file order)."""
    from pearl_sim.nursing_home.scenario import load_scenarios

    seen: Dict[str, Profile] = {}
    for sc in load_scenarios(study_path):
        r = sc.resident
        if r.name in seen:
            continue
        seen[r.name] = Profile(r.name, {
            "name": r.name, "walking_speed": r.walking_speed, "rest_probability": r.rest_probability,
            "rest_seconds": r.rest_seconds, "willingness": r.willingness, "answers_door": r.answers_door,
            "touchscreen": r.touchscreen, "lose_distance": r.lose_distance,
        })
    return list(seen.values())


def generate_residents(count: int, seed: int = 0) -> List[Profile]:
    """``count`` residents drawn from :data:`RANGES` with a generator seeded by ``seed``.

    Rests depend on speed: a walker slower than 0.4 m/s (walking aid, frail) stops to
    catch her breath about once a minute or two (0.005–0.03 per second), a faster one rarely
    (0–0.005).
    """
    if not 1 <= int(count) <= MAX_GENERATED:
        raise SpecError("<command line>", "--residents", f"generated:{count}: the count must be in [1, {MAX_GENERATED}]")
    rng = np.random.default_rng(int(seed))
    out = []

    def uniform(key):
        lo, hi = RANGES[key]
        return float(rng.uniform(lo, hi))

    for i in range(int(count)):
        lo, hi = RANGES["walking_speed"]
        speed = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
        rest = float(rng.uniform(0.005, 0.03) if speed < 0.4 else rng.uniform(0.0, 0.005))
        name = f"G{i + 1:02d}"
        fields = {"name": name, "walking_speed": round(speed, 3), "rest_probability": round(rest, 4),
                  "rest_seconds": round(uniform("rest_seconds"), 1)}
        for key in ("hearing", "responsiveness", "willingness", "answers_door", "touchscreen"):
            fields[key] = round(uniform(key), 3)
        for key in ("forgets", "changes_mind"):
            fields[key] = round(uniform(key), 4)
        out.append(Profile(name, fields, articulation_wer=round(uniform("articulation_wer"), 3)))
    return out


def effective_word_error_rate(noise: float, articulation_wer: float) -> float:
    """Errors from the environment and from her speech, independent per word:
    ``1 − (1 − noise)(1 − articulation)``."""
    return 1.0 - (1.0 - float(noise)) * (1.0 - float(articulation_wer))


#: The tasks every resident is given (the paper's study: a guidance, half of them followed by
#: a question; here every resident gets all three, so residents and tasks are crossed).
TASKS: List[dict] = [
    {"label": "walk"},
    {"label": "walk+weather", "questions": [{"ask": "weather", "when": "at_physio"}]},
    {"label": "walk+time", "questions": [{"ask": "time", "at": 30}]},
]


@dataclass
class StudyCase:
    """One resident on one task: the scenario and what the study needs besides it."""

    scenario: "Scenario"
    resident: str
    task: str
    articulation_wer: float


def study_template(study_path) -> dict:
    """The study file's shared fields (map, robot, timeout, appointment …) without its episodes."""
    from pearl_pomdp.yaml_lines import parse_yaml
    from pathlib import Path

    data = parse_yaml(Path(study_path).read_text(encoding="utf-8"), str(study_path))
    return {k: v for k, v in data.items() if k not in ("episodes", "resident", "questions", "description")}


def resident_scenarios(template: dict, profiles: Sequence[Profile], tasks: Sequence[dict] = TASKS,
                       source: str = "<residents>") -> List[StudyCase]:
    """Every profile × every task as a :class:`StudyCase`.

    ``template`` is a scenario mapping (:func:`study_template`); each task's fields override
    it and each profile's fields are its ``resident:``. Values go through the scenario
    loader's range checks (an error names the resident and the field).
    """
    from pearl_sim.nursing_home.scenario import _build, _merge

    out = []
    for p_index, profile in enumerate(profiles):
        for t_index, task in enumerate(tasks):
            task = dict(task)
            label = str(task.pop("label", t_index + 1))
            data = _merge(copy.deepcopy(template), copy.deepcopy(task))
            data["resident"] = dict(profile.fields)
            data["name"] = f"{profile.name}-{label}"
            data["seed"] = int(template.get("seed", 0)) + 100 * p_index + t_index
            if not 0.0 <= profile.articulation_wer <= 1.0:
                raise SpecError(source, f"{profile.name}.articulation_wer", f"{profile.articulation_wer} is outside [0, 1]")
            out.append(StudyCase(_build(data, source, f"{profile.name}."), profile.name, label,
                                 profile.articulation_wer))
    return out


def parse_population(spec: str, study_path, seed: int = 0) -> List[Profile]:
    """``paper``, ``generated:N`` or both comma-separated (``paper,generated:6``)."""
    profiles: List[Profile] = []
    for part in [p.strip() for p in str(spec).split(",") if p.strip()]:
        if part == "paper":
            profiles += paper_residents(study_path)
        elif part.startswith("generated:"):
            try:
                n = int(part.split(":", 1)[1])
            except ValueError:
                raise SpecError("<command line>", "--residents", f"{part!r}: expected generated:N with N an integer") from None
            profiles += generate_residents(n, seed=seed)
        else:
            raise SpecError("<command line>", "--residents", f"{part!r} is not 'paper' or 'generated:N'")
    if not profiles:
        raise SpecError("<command line>", "--residents", "no residents: use paper, generated:N or both")
    return profiles
