"""Scenarios: who lives where, when appointments fall due, how noisy speech is.

A scenario file (YAML, ``config/scenarios/*.yaml``) describes one or more
*episodes*. Fields shared by all episodes go at the top level; each entry of
``episodes:`` overrides them (nested mappings are merged key by key)::

    name: figure4
    seed: 4
    step_timeout: 8.0            # s of silence that close a step (→ Speech `unknown`)
    max_steps: 80
    map: {home: [0, 0], room: [15, 0], physio: [15, 30]}   # metres
    robot: {speed: 0.6, pace_adaptation: true, battery_seconds: 7200}
    speech: {word_error_rate: 0.2}
    resident: {name: Mrs B, walking_speed: 0.15, willingness: 0.9, ...}
    appointments: [{at: 20, kind: physio}]
    questions: [{when: at_physio, ask: weather}]
    blocked: [{between: [home, room], from: 0, until: 300}]   # a corridor no drive gets through

``blocked`` (optional) lists corridors that are impassable from ``from`` (default 0) until
``until`` seconds (default: never cleared): a drive between the two places (either way)
that starts then never arrives — the robot stops at the obstacle and no landmark is
reported, so only the manager's drive deadline closes the step (``navFailed``).

Every value is range-checked; an error names the file and the field path, e.g.
``config/scenarios/study.yaml: episodes[3].resident.walking_speed: 0.01 m/s is
below the slowest walker modelled (0.05 m/s)``.
"""
from __future__ import annotations

import copy
import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple, Union



from pearl_pomdp.errors import SpecError

LOCATIONS = ("home", "room", "physio")
REMINDER_KINDS = ("physio", "vitamin", "checklist")
QUESTION_KINDS = ("time", "weather")
QUESTION_WHEN = ("at_time", "at_physio")


@dataclass
class Resident:
    """The simulated resident (an elderly person with mild impairments).

    Attributes:
        walking_speed: m/s while walking; 0.05 (walking aid, very frail) to 1.0.
        rest_probability: chance per second of walking that she stops to rest.
        rest_seconds: how long a rest lasts.
        willingness: probability she accepts guidance after a physio reminder.
        answers_door: probability she comes to the door when the bell rings.
        touchscreen: fraction of her answers given on the touchscreen (the rest by voice).
        lose_distance: metres behind the robot at which she loses it and gives up following.
        word_error_rate: her speech's error rate; overrides ``speech.word_error_rate`` when set.
        voice: her espeak-ng voice on the real speech channel (a preset of
            :data:`pearl_pomdp.asr.synthesizer.VOICES`: clear, slow, quiet, slurred).
        hearing: probability she hears a sentence the robot says to her (else it is as if
            she were not listening: a reminder is not delivered, a question not answered).
        responsiveness: probability she answers a question or prompt she heard.
        forgets: chance per robot action that she forgets an unanswered question (memory).
        changes_mind: chance per robot action that a wish to be walked over, not yet
            started, is given up.
    """

    name: str = "resident"
    walking_speed: float = 0.5
    rest_probability: float = 0.0
    rest_seconds: float = 10.0
    willingness: float = 0.9
    answers_door: float = 0.9
    touchscreen: float = 0.2
    lose_distance: float = 15.0
    word_error_rate: Optional[float] = None
    voice: str = "clear"
    hearing: float = 1.0
    responsiveness: float = 1.0
    forgets: float = 0.0
    changes_mind: float = 0.0


@dataclass
class Appointment:
    """A reminder the scheduler raises at ``at`` seconds: physio, vitamin or checklist."""

    at: float
    kind: str


@dataclass
class Question:
    """An information request: ``ask`` (time/weather) at time ``at`` or on arrival at physio."""

    ask: str
    when: str = "at_time"
    at: float = 0.0


@dataclass
class Blockage:
    """A corridor no drive gets through: between places ``a`` and ``b`` (either way), from
    ``start`` until ``end`` seconds (``None``: never cleared)."""

    a: str
    b: str
    start: float = 0.0
    end: Optional[float] = None

    def blocks(self, origin: str, goal: str, t: float) -> bool:
        """Whether a drive from ``origin`` to ``goal`` started at ``t`` is stopped by this blockage."""
        return ({origin, goal} == {self.a, self.b} and t >= self.start
                and (self.end is None or t < self.end))


@dataclass
class Scenario:
    """One simulated episode (see the module docstring for the file format)."""

    name: str
    seed: int = 0
    description: str = ""
    step_timeout: float = 8.0
    max_steps: int = 80
    map: Dict[str, Tuple[float, float]] = field(
        default_factory=lambda: {"home": (0.0, 0.0), "room": (15.0, 0.0), "physio": (15.0, 30.0)}
    )
    robot_speed: float = 0.6
    pace_adaptation: bool = True
    battery_seconds: float = 7200.0
    word_error_rate: float = 0.2
    #: The ``speech:`` mapping for :func:`pearl_sim.speech_channel.make_speech_channel`
    #: (channel recogniser | measured | word_error, snr_db, noise, measured).
    speech: Dict[str, object] = field(default_factory=dict)
    resident: Resident = field(default_factory=Resident)
    appointments: List[Appointment] = field(default_factory=list)
    questions: List[Question] = field(default_factory=list)
    #: Corridors the navigation cannot pass (:class:`Blockage`).
    blocked: List[Blockage] = field(default_factory=list)
    source: str = "<scenario>"

    def is_blocked(self, origin: str, goal: str, t: float) -> bool:
        """Whether a drive from ``origin`` to ``goal`` started at ``t`` never arrives."""
        return origin != goal and any(b.blocks(origin, goal, t) for b in self.blocked)

    def tracker_parameters(self) -> Dict[str, Any]:
        """The belief tracker's parameters for this scenario: its step timeout and its map's
        places (drive deadlines are computed from the distances the simulated robot drives)."""
        params: Dict[str, Any] = {"step_timeout": float(self.step_timeout), "location_names": list(self.map)}
        for name, (x, y) in self.map.items():
            params[f"locations.{name}"] = [float(x), float(y), 0.0]
        return params

    def distance(self, a: str, b: str) -> float:
        """Straight-line distance in metres between two named places."""
        (xa, ya), (xb, yb) = self.map[a], self.map[b]
        return float(((xa - xb) ** 2 + (ya - yb) ** 2) ** 0.5)


# --------------------------------------------------------------------------- loading
@functools.lru_cache(maxsize=1)
def default_domain():
    """The shipped Pearl domain (``config/pearl.domain.yaml``), loaded once per process."""
    from pearl_pomdp.launch_xml import package_share_dir
    from pearl_pomdp.model.domain_yaml import load_domain

    share = package_share_dir("pearl_pomdp")
    if share is None:
        raise FileNotFoundError("config/pearl.domain.yaml: the pearl_pomdp share directory was not found")
    return load_domain(share / "config" / "pearl.domain.yaml")


def load_scenarios(path: Union[str, Path]) -> List[Scenario]:
    """Read a scenario file: one :class:`Scenario` per episode (one if no ``episodes:``).

    Raises:
        SpecError: naming the file and field, for any invalid or out-of-range value.
        FileNotFoundError: no such file.
    """
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    return parse_scenarios(text, source=str(path))


def parse_scenarios(text: str, source: str = "<string>") -> List[Scenario]:
    """Like :func:`load_scenarios`, from YAML text."""
    from pearl_pomdp.yaml_lines import line_table, parse_yaml

    data = parse_yaml(text, source)
    lines = line_table(data)
    try:
        return _parse(data, source)
    except SpecError as err:
        # Field errors name a path; the one loader knows its line (an episode override's
        # field is looked up as written, e.g. episodes[3].resident.walking_speed).
        if err.line is None and err.where:
            line = lines.get(err.where)
            probe = err.where
            while line is None and ("." in probe or "[" in probe):
                probe = probe.rsplit(".", 1)[0] if "." in probe else probe.rsplit("[", 1)[0]
                line = lines.get(probe)
            if line is not None:
                raise SpecError(err.source, err.where, err.problem, line=line) from None
        raise


def _parse(data, source: str) -> List[Scenario]:
    if not isinstance(data, dict):
        raise SpecError(source, "", "a scenario file must be a mapping with at least `name`")
    episodes = data.pop("episodes", None)
    if episodes is None:
        return [_build(data, source, "")]
    if not isinstance(episodes, list) or not episodes:
        raise SpecError(source, "episodes", "must be a non-empty list of episode overrides")
    out = []
    for i, override in enumerate(episodes):
        if not isinstance(override, dict):
            raise SpecError(source, f"episodes[{i}]", "must be a mapping of fields to override")
        merged = _merge(copy.deepcopy(data), override)
        merged.setdefault("name", data.get("name", "scenario"))
        if "name" not in override:
            merged["name"] = f"{merged['name']}#{i + 1}"
        if "seed" not in override:
            merged["seed"] = int(data.get("seed", 0)) + i
        out.append(_build(merged, source, f"episodes[{i}]."))
    return out


def _merge(base: dict, override: dict) -> dict:
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            base[key] = _merge(base[key], value)
        else:
            base[key] = value
    return base


class _Fields:
    """Reads typed, range-checked values from a mapping, naming the field on error."""

    def __init__(self, data: dict, source: str, prefix: str, known: Tuple[str, ...]):
        self.data, self.source, self.prefix = data, source, prefix
        if not isinstance(data, dict):
            raise SpecError(source, prefix.rstrip(".") or "<top>", f"must be a mapping, got {type(data).__name__}")
        unknown = sorted(set(map(str, data)) - set(known))
        if unknown:
            raise SpecError(source, f"{prefix}{unknown[0]}", f"unknown field; known fields: {', '.join(known)}")

    def where(self, key: str) -> str:
        return f"{self.prefix}{key}"

    def number(self, key: str, default: float, lo: float, hi: float, unit: str = "", why: str = "") -> float:
        value = self.data.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SpecError(self.source, self.where(key), f"must be a number, got {value!r}")
        if not lo <= value <= hi:
            bound = f"[{lo}, {hi}]{' ' + unit if unit else ''}"
            raise SpecError(self.source, self.where(key), f"{value}{' ' + unit if unit else ''} is outside {bound}{'; ' + why if why else ''}")
        return float(value)

    def integer(self, key: str, default: int, lo: int, hi: int) -> int:
        value = self.data.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise SpecError(self.source, self.where(key), f"must be an integer, got {value!r}")
        if not lo <= value <= hi:
            raise SpecError(self.source, self.where(key), f"{value} is outside [{lo}, {hi}]")
        return int(value)

    def boolean(self, key: str, default: bool) -> bool:
        value = self.data.get(key, default)
        if not isinstance(value, bool):
            raise SpecError(self.source, self.where(key), f"must be true or false, got {value!r}")
        return value

    def choice(self, key: str, default: Optional[str], options: Tuple[str, ...]) -> str:
        value = self.data.get(key, default)
        if value not in options:
            raise SpecError(self.source, self.where(key), f"{value!r} is not one of {', '.join(options)}")
        return str(value)

    def text(self, key: str, default: str) -> str:
        value = self.data.get(key, default)
        if not isinstance(value, (str, int, float)):
            raise SpecError(self.source, self.where(key), f"must be text, got {value!r}")
        return str(value)


def _voice_presets() -> Tuple[str, ...]:
    from pearl_pomdp.asr.synthesizer import VOICES

    return tuple(VOICES)


def _build(data: dict, source: str, prefix: str) -> Scenario:
    top = _Fields(data, source, prefix, ("name", "seed", "description", "step_timeout", "max_steps", "map", "robot",
                                          "speech", "resident", "appointments", "questions", "blocked"))
    if "name" not in data:
        raise SpecError(source, f"{prefix}name", "missing: every scenario has a name")
    scenario = Scenario(
        name=top.text("name", "scenario"),
        seed=top.integer("seed", 0, 0, 2**31 - 1),
        description=top.text("description", ""),
        step_timeout=top.number("step_timeout", 8.0, 0.5, 120.0, "s"),
        max_steps=top.integer("max_steps", 80, 1, 100_000),
        source=source,
    )
    if "map" in data:
        m = data["map"]
        if not isinstance(m, dict):
            raise SpecError(source, f"{prefix}map", "must map home/room/physio to [x, y] in metres")
        places = {}
        for loc in LOCATIONS:
            xy = m.get(loc)
            if (not isinstance(xy, (list, tuple)) or len(xy) != 2
                    or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xy)):
                raise SpecError(source, f"{prefix}map.{loc}", f"must be [x, y] in metres, got {xy!r}")
            places[loc] = (float(xy[0]), float(xy[1]))
        extra = sorted(set(m) - set(LOCATIONS))
        if extra:
            raise SpecError(source, f"{prefix}map.{extra[0]}", f"unknown place; the domain knows {', '.join(LOCATIONS)}")
        scenario.map = places
    robot = _Fields(data.get("robot", {}), source, f"{prefix}robot.", ("speed", "pace_adaptation", "battery_seconds"))
    scenario.robot_speed = robot.number("speed", 0.6, 0.05, 2.0, "m/s", "Pearl drives at walking pace")
    scenario.pace_adaptation = robot.boolean("pace_adaptation", True)
    scenario.battery_seconds = robot.number("battery_seconds", 7200.0, 60.0, 86400.0, "s")
    speech = _Fields(data.get("speech", {}), source, f"{prefix}speech.",
                     ("word_error_rate", "channel", "snr_db", "noise", "measured"))
    scenario.word_error_rate = speech.number("word_error_rate", 0.2, 0.0, 1.0)
    channel = speech.choice("channel", "word_error", ("recogniser", "measured", "word_error"))
    scenario.speech = {"channel": channel, "word_error_rate": scenario.word_error_rate}
    if channel != "word_error":
        scenario.speech["snr_db"] = speech.number("snr_db", 20.0, -20.0, 60.0, "dB")
        scenario.speech["noise"] = speech.choice("noise", "white", ("white", "babble"))
        if channel == "measured":
            measured = speech.text("measured", "")
            if not measured:
                raise SpecError(source, f"{prefix}speech.measured",
                                "channel: measured needs the file of `pearl calibrate-speech --out`")
            scenario.speech["measured"] = measured
    res = _Fields(data.get("resident", {}), source, f"{prefix}resident.",
                  ("name", "walking_speed", "rest_probability", "rest_seconds", "willingness", "answers_door",
                   "touchscreen", "lose_distance", "word_error_rate", "voice", "hearing", "responsiveness",
                   "forgets", "changes_mind"))
    scenario.resident = Resident(
        name=res.text("name", "resident"),
        walking_speed=res.number("walking_speed", 0.5, 0.05, 1.0, "m/s",
                                 "the slowest walker modelled goes 0.05 m/s, the fastest 1 m/s"),
        rest_probability=res.number("rest_probability", 0.0, 0.0, 0.5, "per s"),
        rest_seconds=res.number("rest_seconds", 10.0, 0.0, 600.0, "s"),
        willingness=res.number("willingness", 0.9, 0.0, 1.0),
        answers_door=res.number("answers_door", 0.9, 0.0, 1.0),
        touchscreen=res.number("touchscreen", 0.2, 0.0, 1.0),
        lose_distance=res.number("lose_distance", 15.0, 1.0, 100.0, "m"),
        word_error_rate=(res.number("word_error_rate", 0.0, 0.0, 1.0)
                         if data.get("resident", {}).get("word_error_rate") is not None else None),
        voice=res.choice("voice", "clear", _voice_presets()),
        hearing=res.number("hearing", 1.0, 0.0, 1.0),
        responsiveness=res.number("responsiveness", 1.0, 0.0, 1.0),
        forgets=res.number("forgets", 0.0, 0.0, 1.0, "per action"),
        changes_mind=res.number("changes_mind", 0.0, 0.0, 1.0, "per action"),
    )
    appts = data.get("appointments", [])
    if not isinstance(appts, list):
        raise SpecError(source, f"{prefix}appointments", "must be a list of {at, kind}")
    for i, item in enumerate(appts):
        f = _Fields(item, source, f"{prefix}appointments[{i}].", ("at", "kind"))
        scenario.appointments.append(Appointment(at=f.number("at", 0.0, 0.0, 1e6, "s"),
                                                 kind=f.choice("kind", None, REMINDER_KINDS)))
    questions = data.get("questions", [])
    if not isinstance(questions, list):
        raise SpecError(source, f"{prefix}questions", "must be a list of {ask, when, at}")
    for i, item in enumerate(questions):
        f = _Fields(item, source, f"{prefix}questions[{i}].", ("ask", "when", "at"))
        scenario.questions.append(Question(ask=f.choice("ask", None, QUESTION_KINDS),
                                           when=f.choice("when", "at_time", QUESTION_WHEN),
                                           at=f.number("at", 0.0, 0.0, 1e6, "s")))
    blocked = data.get("blocked", [])
    if not isinstance(blocked, list):
        raise SpecError(source, f"{prefix}blocked", "must be a list of {between: [place, place], from, until}")
    for i, item in enumerate(blocked):
        f = _Fields(item, source, f"{prefix}blocked[{i}].", ("between", "from", "until"))
        pair = item.get("between")
        if (not isinstance(pair, list) or len(pair) != 2 or any(p not in LOCATIONS for p in pair)
                or pair[0] == pair[1]):
            raise SpecError(source, f"{prefix}blocked[{i}].between",
                            f"must be two different places of {', '.join(LOCATIONS)}, got {pair!r}")
        start = f.number("from", 0.0, 0.0, 1e6, "s")
        end = f.number("until", 1e6, 0.0, 1e6, "s") if "until" in item else None
        if end is not None and end <= start:
            raise SpecError(source, f"{prefix}blocked[{i}].until", f"{end} s is not after from ({start} s)")
        scenario.blocked.append(Blockage(str(pair[0]), str(pair[1]), start, end))
    return scenario
