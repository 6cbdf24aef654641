"""Ward scenarios: the ward's map, the robot, the person detector, speech noise and the three residents.

A scenario file (``config/scenarios/ward/*.yaml``) names its world (``world: ward``) and describes
one or more episodes; top-level fields are shared and each entry of ``episodes:`` overrides them
(mappings merged key by key; ``residents`` is replaced as a whole)::

    world: ward
    name: ward_study
    seed: 200
    step_timeout: 10.0
    max_steps: 60
    map: {station: [0, 0], room_ann: [8, 6], room_bob: [8, -6], room_cleo: [16, 6], lounge: [16, -6]}
    robot: {speed: 0.7}
    detector: {miss: 0.1}
    speech: {word_error_rate: 0.2}
    residents:
      - {name: Ann, at: room, pills: [60], requests: [{at: 30, need: water}], moves: [{at: 200, to: lounge}]}
      - {name: Bob}
      - {name: Cleo}

The residents are exactly the domain's: ``Ann``, ``Bob`` and ``Cleo``, each once. Every value is
range-checked; an error names the file and the field path
(``study.yaml: episodes[2].residents[0].requests[1].need: 'tea' is not a need (water, help, talk)``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Tuple, Union

from pearl_sim.world_scenario import Checker, PlacesAndTimeout, load_episodes, read_map, read_seed_and_steps

__all__ = ["Resident", "WardScenario", "load_ward_scenarios", "RESIDENTS", "PLACES", "NEEDS", "HOME"]

#: The residents of ``config/ward.domain.yaml`` (feature prefixes), in the domain's order.
RESIDENTS = ("Ann", "Bob", "Cleo")
#: The robot's places (the domain's ``RobotAt`` values).
PLACES = ("station", "room_ann", "room_bob", "room_cleo", "lounge")
#: Where the robot starts and waits: the nurses' station.
HOME = "station"
#: What a resident may ask for (the domain's ``<Name>Need`` values but ``none``).
NEEDS = ("water", "help", "talk")
#: Where a resident may be (the domain's ``<Name>At`` values).
WHERE = ("room", "lounge", "out")


@dataclass
class Resident:
    """One resident of the ward.

    Attributes:
        name: ``Ann``, ``Bob`` or ``Cleo``.
        at: where they are at the start (``room``, ``lounge`` or ``out``).
        pills: seconds at which a medication reminder falls due.
        late_after: seconds after falling due at which the medication counts as overdue.
        requests: ``(time, need)``: at ``time`` they want ``need`` (water, help or talk).
        moves: ``(time, where)``: at ``time`` they go to ``where`` (room, lounge, out).
        speaks_up: per :data:`pearl_sim.ward.world.SPEAK_AGAIN_SECONDS` with the robot at their
            place, the probability they say what they need unasked.
        presses_call: the probability they press the call button in their room when a need arises
            (and again every :data:`pearl_sim.ward.world.CALL_AGAIN_SECONDS` while unserved).
        word_error_rate: their speech's error rate; overrides ``speech.word_error_rate`` when set.
    """

    name: str
    at: str = "room"
    pills: List[float] = field(default_factory=list)
    late_after: float = 180.0
    requests: List[Tuple[float, str]] = field(default_factory=list)
    moves: List[Tuple[float, str]] = field(default_factory=list)
    speaks_up: float = 0.4
    presses_call: float = 0.7
    word_error_rate: Union[float, None] = None

    @property
    def room(self) -> str:
        """The robot's place that is this resident's room."""
        return f"room_{self.name.lower()}"


@dataclass
class WardScenario(PlacesAndTimeout):
    """One episode of the ward world (see the module doc for the file format)."""

    name: str
    seed: int = 0
    description: str = ""
    step_timeout: float = 10.0
    max_steps: int = 60
    map: Dict[str, Tuple[float, float]] = field(default_factory=lambda: {
        "station": (0.0, 0.0), "room_ann": (8.0, 6.0), "room_bob": (8.0, -6.0), "room_cleo": (16.0, 6.0),
        "lounge": (16.0, -6.0)})
    robot_speed: float = 0.7
    detector_miss: float = 0.1
    word_error_rate: float = 0.2
    residents: List[Resident] = field(default_factory=list)
    source: str = ""


_TOP = ("world", "name", "seed", "description", "step_timeout", "max_steps", "map", "robot", "detector", "speech",
        "residents", "episodes")
_RESIDENT = ("name", "at", "pills", "late_after", "requests", "moves", "speaks_up", "presses_call", "word_error_rate")


def _episode(data: dict, source: str, prefix: str) -> WardScenario:
    c = Checker(source)
    data = c.mapping(data, prefix.rstrip("."), _TOP)
    robot = c.mapping(data.get("robot"), f"{prefix}robot", ("speed",))
    detector = c.mapping(data.get("detector"), f"{prefix}detector", ("miss",))
    speech = c.mapping(data.get("speech"), f"{prefix}speech", ("word_error_rate",))
    the_map = read_map(c, data, prefix, PLACES, {p: xy for p, xy in WardScenario("x").map.items()})
    raw = data.get("residents")
    if not isinstance(raw, list):
        raise c.fail(f"{prefix}residents", f"expected a list of the residents {', '.join(RESIDENTS)}")
    residents: Dict[str, Resident] = {}
    for i, r in enumerate(raw):
        where = f"{prefix}residents[{i}]."
        r = c.mapping(r, where.rstrip("."), _RESIDENT)
        name = r.get("name")
        if name not in RESIDENTS or name in residents:
            raise c.fail(f"{where}name", f"{name!r}: each of the domain's residents ({', '.join(RESIDENTS)}) once")
        at = r.get("at", "room")
        if at not in WHERE:
            raise c.fail(f"{where}at", f"{at!r} is not a place a resident is ({', '.join(WHERE)})")
        pills = r.get("pills", []) or []
        if not isinstance(pills, list):
            raise c.fail(f"{where}pills", "expected a list of seconds")
        wer = r.get("word_error_rate")
        residents[name] = Resident(
            name=name, at=at, pills=sorted(c.value(p, f"{where}pills[{k}]", 0.0, 86400.0, "s") for k, p in enumerate(pills)),
            late_after=c.number(r, "late_after", where, 180.0, 1.0, 86400.0, "s"),
            requests=c.timed(r.get("requests"), f"{where}requests", "need", NEEDS),
            moves=c.timed(r.get("moves"), f"{where}moves", "to", WHERE),
            speaks_up=c.number(r, "speaks_up", where, 0.4, 0.0, 1.0),
            presses_call=c.number(r, "presses_call", where, 0.7, 0.0, 1.0),
            word_error_rate=None if wer is None else c.number(r, "word_error_rate", where, 0.0, 0.0, 1.0))
    missing = [n for n in RESIDENTS if n not in residents]
    if missing:
        raise c.fail(f"{prefix}residents", f"{missing[0]} is missing: the domain has residents {', '.join(RESIDENTS)}")
    seed, steps = read_seed_and_steps(c, data, prefix, 60, 100000)
    return WardScenario(
        name=str(data.get("name", Path(source).stem)), seed=seed, description=str(data.get("description", "")),
        step_timeout=c.number(data, "step_timeout", prefix, 10.0, 0.5, 120.0, "s"), max_steps=steps, map=the_map,
        robot_speed=c.number(robot, "speed", f"{prefix}robot.", 0.7, 0.1, 3.0, "m/s"),
        detector_miss=c.number(detector, "miss", f"{prefix}detector.", 0.1, 0.0, 1.0),
        word_error_rate=c.number(speech, "word_error_rate", f"{prefix}speech.", 0.2, 0.0, 1.0),
        residents=[residents[n] for n in RESIDENTS], source=source)


def load_ward_scenarios(path: Union[str, Path]) -> List[WardScenario]:
    """Read a ward scenario file: one :class:`WardScenario` per episode (one if no ``episodes:``).

    Raises:
        SpecError: a field is missing, unknown or out of range (file and field path named).
    """
    return load_episodes(path, "ward", _episode)
