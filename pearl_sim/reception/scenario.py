"""Reception scenarios: the building, the robot, the person detector, speech noise and the visitors.

A scenario file (``config/scenarios/reception/*.yaml``) names the world it runs in
(``world: reception``) and describes one or more episodes; fields shared by all go at the top
level and each entry of ``episodes:`` overrides them (mappings merged key by key)::

    world: reception
    name: one_visitor
    seed: 11
    step_timeout: 8.0
    max_steps: 40
    map: {desk: [0, 0], gallery: [30, 10], office: [12, -20]}       # metres
    robot: {speed: 0.7, battery: 1.0, idle_hours: 6, drive_hours: 1.5, charge_minutes: 10}
    detector: {miss: 0.1, passers_per_minute: 0.3}
    speech: {word_error_rate: 0.2}
    visitors:
      - {name: Ms Ito, arrive: 10, wish: gallery, walking_speed: 1.0}

Every value is range-checked; an error names the file and the field path
(``visitors.yaml: episodes[1].visitors[0].wish: 'cafe' is not a place visitors go to (gallery, office)``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Tuple, Union

from pearl_sim.world_scenario import Checker, PlacesAndTimeout, load_episodes, read_map, read_seed_and_steps

__all__ = ["Visitor", "ReceptionScenario", "load_reception_scenarios", "DESTINATIONS", "HOME"]

#: Where the robot waits and charges.
HOME = "desk"
#: The places visitors ask for (the domain's Wish values).
DESTINATIONS = ("gallery", "office")


@dataclass
class Visitor:
    """One visitor.

    Attributes:
        arrive: seconds after the start at which they walk up to the desk.
        wish: where they want to go (``gallery`` or ``office``).
        walking_speed: m/s; the robot escorts at this pace when it is slower than its own.
        says_hello: probability they greet the robot first when they arrive (and again every
            :data:`pearl_sim.reception.world.HELLO_AGAIN_SECONDS` while left waiting).
        touchscreen: fraction of their destination answers given on the touchscreen.
        volunteers: probability, per robot wait once greeted, that they say where they want to go unasked.
        patience: seconds they wait ungreeted at the desk before they leave.
        word_error_rate: their speech's error rate; overrides ``speech.word_error_rate`` when set.
    """

    name: str = "visitor"
    arrive: float = 0.0
    wish: str = "gallery"
    walking_speed: float = 1.0
    says_hello: float = 0.5
    touchscreen: float = 0.3
    volunteers: float = 0.2
    patience: float = 240.0
    word_error_rate: Union[float, None] = None


@dataclass
class ReceptionScenario(PlacesAndTimeout):
    """One episode of the reception world (see the module doc for the file format)."""

    name: str
    seed: int = 0
    description: str = ""
    step_timeout: float = 8.0
    max_steps: int = 40
    map: Dict[str, Tuple[float, float]] = field(default_factory=lambda: {"desk": (0.0, 0.0), "gallery": (30.0, 10.0),
                                                                         "office": (12.0, -20.0)})
    robot_speed: float = 0.7
    battery: float = 1.0
    idle_hours: float = 6.0
    drive_hours: float = 1.5
    charge_minutes: float = 10.0
    detector_miss: float = 0.1
    passers_per_minute: float = 0.3
    word_error_rate: float = 0.2
    visitors: List[Visitor] = field(default_factory=list)
    source: str = ""


_TOP = ("world", "name", "seed", "description", "step_timeout", "max_steps", "map", "robot", "detector", "speech",
        "visitors", "episodes")
_VISITOR = ("name", "arrive", "wish", "walking_speed", "says_hello", "touchscreen", "volunteers", "patience",
            "word_error_rate")


def _episode(data: dict, source: str, prefix: str) -> ReceptionScenario:
    c = Checker(source)
    data = c.mapping(data, prefix.rstrip("."), _TOP)
    robot = c.mapping(data.get("robot"), f"{prefix}robot", ("speed", "battery", "idle_hours", "drive_hours",
                                                             "charge_minutes"))
    detector = c.mapping(data.get("detector"), f"{prefix}detector", ("miss", "passers_per_minute"))
    speech = c.mapping(data.get("speech"), f"{prefix}speech", ("word_error_rate",))
    the_map = read_map(c, data, prefix, (HOME, *DESTINATIONS),
                       {"desk": [0, 0], "gallery": [30, 10], "office": [12, -20]})
    visitors = []
    raw = data.get("visitors", []) or []
    if not isinstance(raw, list):
        raise c.fail(f"{prefix}visitors", "expected a list of visitors")
    for i, v in enumerate(raw):
        where = f"{prefix}visitors[{i}]."
        v = c.mapping(v, where.rstrip("."), _VISITOR)
        wish = v.get("wish", "gallery")
        if wish not in DESTINATIONS:
            raise c.fail(f"{where}wish", f"{wish!r} is not a place visitors go to ({', '.join(DESTINATIONS)})")
        wer = v.get("word_error_rate")
        visitors.append(Visitor(
            name=str(v.get("name", f"visitor {i + 1}")), arrive=c.number(v, "arrive", where, 0.0, 0.0, 86400.0, "s"),
            wish=wish, walking_speed=c.number(v, "walking_speed", where, 1.0, 0.2, 2.0, "m/s"),
            says_hello=c.number(v, "says_hello", where, 0.5, 0.0, 1.0),
            touchscreen=c.number(v, "touchscreen", where, 0.3, 0.0, 1.0),
            volunteers=c.number(v, "volunteers", where, 0.2, 0.0, 1.0),
            patience=c.number(v, "patience", where, 240.0, 10.0, 86400.0, "s"),
            word_error_rate=None if wer is None else c.number(v, "word_error_rate", where, 0.0, 0.0, 1.0)))
    seed, steps = read_seed_and_steps(c, data, prefix, 40, 10000)
    return ReceptionScenario(
        name=str(data.get("name", Path(source).stem)), seed=seed, description=str(data.get("description", "")),
        step_timeout=c.number(data, "step_timeout", prefix, 8.0, 0.5, 120.0, "s"), max_steps=steps, map=the_map,
        robot_speed=c.number(robot, "speed", f"{prefix}robot.", 0.7, 0.1, 3.0, "m/s"),
        battery=c.number(robot, "battery", f"{prefix}robot.", 1.0, 0.0, 1.0),
        idle_hours=c.number(robot, "idle_hours", f"{prefix}robot.", 6.0, 0.01, 100.0, "h"),
        drive_hours=c.number(robot, "drive_hours", f"{prefix}robot.", 1.5, 0.01, 100.0, "h"),
        charge_minutes=c.number(robot, "charge_minutes", f"{prefix}robot.", 10.0, 0.1, 600.0, "min"),
        detector_miss=c.number(detector, "miss", f"{prefix}detector.", 0.1, 0.0, 1.0),
        passers_per_minute=c.number(detector, "passers_per_minute", f"{prefix}detector.", 0.3, 0.0, 60.0),
        word_error_rate=c.number(speech, "word_error_rate", f"{prefix}speech.", 0.2, 0.0, 1.0),
        visitors=sorted(visitors, key=lambda v: v.arrive), source=source)


def load_reception_scenarios(path: Union[str, Path]) -> List[ReceptionScenario]:
    """Read a reception scenario file: one :class:`ReceptionScenario` per episode (one if no ``episodes:``).

    Raises:
        SpecError: a field is missing, unknown or out of range (file and field path named).
    """
    return load_episodes(path, "reception", _episode)
